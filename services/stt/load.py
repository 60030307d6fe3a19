"""Loading the configured engine, in this process or in worker processes (`--workers`)."""

from __future__ import annotations

from .engine import Engine, EngineOptions, load_here
from .workers import ProcessEngine


def load_engine(options: EngineOptions) -> Engine:
    """The engine `options` names, loaded now; EngineError with an install hint."""
    if options.workers > 0:
        return ProcessEngine(options, options.workers)
    return load_here(options)
