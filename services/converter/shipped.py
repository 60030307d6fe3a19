"""Where the orders files that voicectl ships are, checked out or installed."""

from __future__ import annotations

from pathlib import Path

_HERE = Path(__file__).resolve().parent


def shipped_orders() -> Path:
    """`orders/` of the checkout this code runs from (an editable install too); in an
    installed wheel, their copy packaged as ``services/converter/shipped_orders``."""
    installed = _HERE / "shipped_orders"
    return installed if installed.is_dir() else _HERE.parents[1] / "orders"
