"""What a user writes to add a behaviour: an `Executor` subclass with one async method.

The smallest one is `builtin/mul.py`: a msgspec Struct for its parameters, the labels
it serves, and `execute`, which reads `ctx.params`, reports with `ctx.progress(...)` and
returns what it did.

Returning ends the order as succeeded (the returned text is its message); raising
`OrderFailed` ends it as failed; any other exception is a failed order too, with the
exception's text. Cancellation arrives as `asyncio.CancelledError` at the next `await`.
An order whose parameters do not fit `params_type` is rejected before `execute` runs.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import msgspec

from voicectl.shared.errors import VoicectlError
from voicectl.shared.messages import Order, Progress

if TYPE_CHECKING:
    from .fence import OrderRobot


class ExecutionContext:
    """What an executor can use while it runs one order."""

    def __init__(
        self,
        order_id: str,
        robot: OrderRobot,
        report: Callable[[Progress], None],
        params: Any = None,
    ) -> None:
        self.order_id = order_id
        self.robot = robot
        """The robot, through zenoh-bridge-ros2dds' keys (topics, services, actions), for
        as long as this order runs."""
        self.params = params
        """The order's parameters as the executor's `params_type`, or the plain dict."""
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
    params_type: ClassVar[type[msgspec.Struct] | None] = None
    """The parameters it needs, as a msgspec Struct: orders are checked against it once,
    and `ctx.params` is an instance of it. None: `ctx.params` is the order's dict."""

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        """Carry out `order`; return a short result message, or raise `OrderFailed`."""
        raise NotImplementedError


class BindingError(VoicectlError):
    """An executor binding that cannot be loaded."""


class ParamsMismatch(VoicectlError):
    """An order whose parameters do not fit its executor's `params_type`."""


def order_params(executor: Executor, order: Order) -> Any:
    """`order.params` as `executor` wants them; ParamsMismatch says which one is wrong."""
    params_type = executor.params_type
    if params_type is None:
        return order.params
    try:
        return msgspec.convert(order.params, params_type)
    except msgspec.ValidationError as exc:
        what, _, path = str(exc).partition(" - at `$.")
        what = what.replace("Object missing required field `", "missing parameter `")
        where = f"parameter '{path.rstrip('`')}': " if path else ""
        raise ParamsMismatch(f"'{order.description}' ({order.label}): {where}{what}") from None


def load_executor(
    target: str, labels: tuple[str, ...] = (), kwargs: dict[str, Any] | None = None
) -> tuple[Executor, tuple[str, ...]]:
    """Import ``package.module:Class``, make one with `kwargs`; its labels, or the class's."""
    module_name, _, class_name = target.partition(":")
    if not module_name or not class_name:
        raise BindingError(f"executor {target!r}: expected module:Class")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise BindingError(f"executor {target!r}: cannot import {module_name}: {exc}") from exc
    cls = getattr(module, class_name, None)
    if not isinstance(cls, type) or not issubclass(cls, Executor):
        raise BindingError(f"executor {target!r}: {class_name} is not an Executor class")
    labels = labels or cls.labels
    if not labels:
        raise BindingError(f"executor {target!r}: no labels given and {class_name}.labels is empty")
    try:
        executor = cls(**(kwargs or {}))
    except Exception as exc:
        raise BindingError(f"executor {target!r}: {class_name}() failed: {exc}") from exc
    return executor, labels


def load_binding(spec: str) -> tuple[Executor, tuple[str, ...]]:
    """Load ``package.module:Class[=label,label]`` (the --executor flag)."""
    target, _, labels_text = spec.partition("=")
    labels = tuple(x.strip() for x in labels_text.split(",") if x.strip())
    return load_executor(target, labels)


class _FileBinding(msgspec.Struct, forbid_unknown_fields=True):
    target: str = msgspec.field(name="class")
    labels: list[str] = []
    args: dict[str, Any] = {}


class _BindingsFile(msgspec.Struct, forbid_unknown_fields=True):
    executors: list[_FileBinding]


def load_bindings_file(path: Path) -> list[tuple[Executor, tuple[str, ...]]]:
    """The bindings of an executors file (--executors): module:Class, labels, and
    keyword arguments for the constructor, so that one class serves several setups."""
    try:
        text = path.read_bytes()
    except OSError as exc:
        raise BindingError(f"{path}: {exc.strerror or exc}") from exc
    try:
        bindings = msgspec.yaml.decode(text, type=_BindingsFile)
    except (msgspec.ValidationError, msgspec.DecodeError) as exc:
        raise BindingError(f"{path}: {str(exc).splitlines()[0]}") from None
    loaded = []
    for number, binding in enumerate(bindings.executors, start=1):
        try:
            loaded.append(load_executor(binding.target, tuple(binding.labels), binding.args))
        except BindingError as exc:
            raise BindingError(f"{path}: executors entry {number}: {exc}") from None
    return loaded


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
