"""What a user writes to add a behaviour: an `Executor` subclass with one async method.

A minimal executor::

    from services.executor import Executor

    class Multiply(Executor):
        labels = ("mul",)

        async def execute(self, order, ctx):
            a, b = order.params["a"], order.params["b"]
            ctx.progress(f"multiplying {a} by {b}")
            return f"{a} x {b} = {a * b}"

Returning ends the order as succeeded (the returned text is its message); raising
`OrderFailed` ends it as failed; any other exception is a failed order too, with the
exception's text. Cancellation arrives as `asyncio.CancelledError` at the next `await`.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import TYPE_CHECKING, ClassVar

from shared.errors import VoicectlError
from shared.messages import Order, Progress

if TYPE_CHECKING:
    from .robot import RobotLink


class ExecutionContext:
    """What an executor can use while it runs one order."""

    def __init__(self, order_id: str, robot: RobotLink, report: Callable[[Progress], None]) -> None:
        self.order_id = order_id
        self.robot = robot
        """The robot, through zenoh-bridge-ros2dds' keys (topics, services, actions)."""
        self._report = report

    def progress(
        self,
        text: str = "",
        *,
        distance_linear: float | None = None,
        distance_angular: float | None = None,
        percent: float | None = None,
    ) -> None:
        """Tell the supervisor (and so the panel) how far the order has come."""
        self._report(
            Progress(
                text=text,
                distance_linear=distance_linear,
                distance_angular=distance_angular,
                percent=percent,
            )
        )


class Executor:
    """Base of every executor: set `labels` and implement `execute`."""

    labels: ClassVar[tuple[str, ...]] = ()
    """The order labels this executor serves unless bound otherwise."""

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        """Carry out `order`; return a short result message, or raise `OrderFailed`."""
        raise NotImplementedError


class BindingError(VoicectlError):
    """An executor binding that cannot be loaded."""


def load_binding(spec: str) -> tuple[Executor, tuple[str, ...]]:
    """Load ``package.module:Class[=label,label]`` into an executor and its labels."""
    target, _, labels_text = spec.partition("=")
    module_name, _, class_name = target.partition(":")
    if not module_name or not class_name:
        raise BindingError(f"executor binding {spec!r}: expected module:Class[=label,...]")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise BindingError(
            f"executor binding {spec!r}: cannot import {module_name}: {exc}"
        ) from exc
    cls = getattr(module, class_name, None)
    if not isinstance(cls, type) or not issubclass(cls, Executor):
        raise BindingError(f"executor binding {spec!r}: {class_name} is not an Executor class")
    labels = tuple(x.strip() for x in labels_text.split(",") if x.strip()) or cls.labels
    if not labels:
        raise BindingError(
            f"executor binding {spec!r}: no labels given and {class_name}.labels is empty"
        )
    try:
        executor = cls()
    except Exception as exc:
        raise BindingError(f"executor binding {spec!r}: {class_name}() failed: {exc}") from exc
    return executor, labels


class Bindings:
    """Which executor serves which label."""

    def __init__(self) -> None:
        self._by_label: dict[str, Executor] = {}

    def bind(self, executor: Executor, labels: tuple[str, ...]) -> None:
        for label in labels:
            self._by_label[label] = executor

    def get(self, label: str) -> Executor | None:
        return self._by_label.get(label)

    @property
    def labels(self) -> list[str]:
        return sorted(self._by_label)
