"""Orders files: YAML in, a validated `OrderSet` out, or one clear error.

The shape (the ``orders_list`` wrapper is optional)::

    orders_list:
      separator: "then"            # regex between the orders of one utterance
      orders:
        rotation:                  # order name
          voice_alias: "turn"      # regex, mandatory
          label: "mbgoal"          # executor label, mandatory
          frame: "base_link"       # frame/x/y/yaw make the target pose
          cases:
            left: {voice_alias: "left", yaw: 1.57}

Any other key of an order or case is a parameter of the order: unknown keys are
meaningful here, so they are kept rather than refused.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from shared.errors import OrdersFileError
from shared.messages import ParamValue, TargetPose

RESERVED_KEYS = frozenset({"voice_alias", "label", "description", "cases"})
POSE_KEYS = ("x", "y", "yaw")
DEFAULT_SEPARATOR = "then"


@dataclass(frozen=True)
class CaseSpec:
    """One variant of an order ('left' of 'rotation') and what it changes."""

    name: str
    alias: str
    description: str
    values: dict[str, ParamValue]


@dataclass(frozen=True)
class OrderSpec:
    """One order as written in an orders file."""

    name: str
    alias: str
    label: str
    description: str
    values: dict[str, ParamValue]
    cases: tuple[CaseSpec, ...] = ()
    source: str = ""
    """The file it came from, for error messages."""

    def target_pose(self, case: CaseSpec | None) -> TargetPose | None:
        merged = self.merged_values(case)
        frame = merged.get("frame")
        if not isinstance(frame, str):
            return None
        pose = {k: float(merged.get(k, 0.0)) for k in POSE_KEYS}
        return TargetPose(frame=frame, **pose)

    def params(self, case: CaseSpec | None) -> dict[str, ParamValue]:
        merged = self.merged_values(case)
        if "frame" in merged:
            return {k: v for k, v in merged.items() if k != "frame" and k not in POSE_KEYS}
        return merged

    def merged_values(self, case: CaseSpec | None) -> dict[str, ParamValue]:
        return {**self.values, **(case.values if case else {})}

    def full_description(self, case: CaseSpec | None) -> str:
        return f"{self.description} {case.description}" if case else self.description


@dataclass(frozen=True)
class OrderSet:
    """Every order the converter knows, and how utterances are split."""

    orders: tuple[OrderSpec, ...]
    separator: str = DEFAULT_SEPARATOR
    sources: tuple[str, ...] = field(default=())

    @staticmethod
    def load(path: Path) -> OrderSet:
        """Load one YAML file, or every ``*.yaml``/``*.yml`` in a directory."""
        if path.is_dir():
            files = sorted([*path.glob("*.yaml"), *path.glob("*.yml")])
            if not files:
                raise OrdersFileError(f"{path}: no *.yaml orders files in this directory")
            return OrderSet.merge([OrderSet.load(f) for f in files])
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise OrdersFileError(f"{path}: cannot read orders file: {exc}") from exc
        return OrderSet.from_yaml(text, str(path))

    @staticmethod
    def from_yaml(text: str, source: str = "<text>") -> OrderSet:
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            where = f"{source}:{mark.line + 1}" if mark is not None else source
            problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
            raise OrdersFileError(f"{where}: invalid YAML: {problem}") from exc
        return OrderSet.from_dict(data, source)

    @staticmethod
    def from_dict(data: Any, source: str = "<dict>") -> OrderSet:
        if isinstance(data, dict) and "orders_list" in data:
            data = data["orders_list"]
        if not isinstance(data, dict) or not isinstance(data.get("orders"), dict):
            raise OrdersFileError(f"{source}: expected a mapping with an 'orders' mapping")
        unknown = set(data) - {"orders", "separator"}
        if unknown:
            raise OrdersFileError(
                f"{source}: unknown top-level key(s) {', '.join(sorted(map(str, unknown)))}; "
                "allowed: orders, separator"
            )
        separator = data.get("separator", DEFAULT_SEPARATOR)
        if not isinstance(separator, str) or not separator.strip():
            raise OrdersFileError(f"{source}: 'separator' must be a non-empty string (regex)")
        _check_regex(separator, f"{source}: separator")
        orders = tuple(
            _order_from_dict(str(name), spec, source) for name, spec in data["orders"].items()
        )
        if not orders:
            raise OrdersFileError(f"{source}: 'orders' is empty")
        return OrderSet(orders=orders, separator=separator, sources=(source,))

    @staticmethod
    def merge(sets: list[OrderSet]) -> OrderSet:
        """Join several files; the same order name twice is an error naming both files."""
        seen: dict[str, str] = {}
        for order_set in sets:
            for order in order_set.orders:
                if order.name in seen:
                    raise OrdersFileError(
                        f"{order.source}: order '{order.name}' is already defined in "
                        f"{seen[order.name]}"
                    )
                seen[order.name] = order.source
        separators = {s.separator for s in sets}
        if len(separators) > 1:
            raise OrdersFileError(
                "orders files disagree on the separator: " + ", ".join(sorted(separators))
            )
        return OrderSet(
            orders=tuple(o for s in sets for o in s.orders),
            separator=separators.pop(),
            sources=tuple(src for s in sets for src in s.sources),
        )


def _order_from_dict(name: str, spec: Any, source: str) -> OrderSpec:
    where = f"{source}: order '{name}'"
    if not isinstance(spec, dict):
        raise OrdersFileError(f"{where}: expected a mapping, got {type(spec).__name__}")
    alias = _required_str(spec, "voice_alias", where)
    label = _required_str(spec, "label", where)
    description = spec.get("description", alias)
    if not isinstance(description, str):
        raise OrdersFileError(f"{where}: 'description' must be a string")
    values = _values(spec, where)
    raw_cases = spec.get("cases", {})
    if raw_cases is None:
        raw_cases = {}
    if not isinstance(raw_cases, dict):
        raise OrdersFileError(f"{where}: 'cases' must be a mapping of case name to case")
    cases = tuple(_case_from_dict(str(n), c, f"{where} case '{n}'") for n, c in raw_cases.items())
    order = OrderSpec(
        name=name,
        alias=alias,
        label=label,
        description=description,
        values=values,
        cases=cases,
        source=source,
    )
    for case in cases or (None,):
        merged = order.merged_values(case)
        if "frame" in merged:
            for key in POSE_KEYS:
                value = merged.get(key, 0.0)
                if isinstance(value, bool) or not isinstance(value, int | float):
                    at = f" case '{case.name}'" if case else ""
                    raise OrdersFileError(f"{where}{at}: '{key}' must be a number, got {value!r}")
    return order


def _case_from_dict(name: str, spec: Any, where: str) -> CaseSpec:
    if not isinstance(spec, dict):
        raise OrdersFileError(f"{where}: expected a mapping, got {type(spec).__name__}")
    if "cases" in spec:
        raise OrdersFileError(f"{where}: cases cannot have cases of their own")
    if "label" in spec:
        raise OrdersFileError(f"{where}: 'label' belongs to the order, not to a case")
    alias = _required_str(spec, "voice_alias", where)
    description = spec.get("description", alias)
    if not isinstance(description, str):
        raise OrdersFileError(f"{where}: 'description' must be a string")
    return CaseSpec(name=name, alias=alias, description=description, values=_values(spec, where))


def _required_str(spec: dict[str, Any], key: str, where: str) -> str:
    if key not in spec:
        raise OrdersFileError(f"{where}: missing mandatory key '{key}'")
    value = spec[key]
    if not isinstance(value, str) or not value.strip():
        raise OrdersFileError(f"{where}: '{key}' must be a non-empty string, got {value!r}")
    if key == "voice_alias":
        _check_regex(value, f"{where}: 'voice_alias'")
    return value.strip()


def _values(spec: dict[str, Any], where: str) -> dict[str, ParamValue]:
    values: dict[str, ParamValue] = {}
    for key, value in spec.items():
        if key in RESERVED_KEYS:
            continue
        if not isinstance(key, str):
            raise OrdersFileError(f"{where}: parameter names must be strings, got {key!r}")
        if not isinstance(value, str | int | float | bool):
            raise OrdersFileError(
                f"{where}: parameter '{key}' must be a string, number or boolean, "
                f"got {type(value).__name__}"
            )
        values[key] = value
    return values


def _check_regex(pattern: str, where: str) -> None:
    try:
        compiled = re.compile(pattern)
    except re.error as exc:
        raise OrdersFileError(f"{where}: invalid regex {pattern!r}: {exc}") from exc
    if compiled.match(""):
        raise OrdersFileError(f"{where}: regex {pattern!r} matches empty text")
