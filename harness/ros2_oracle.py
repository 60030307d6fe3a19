"""Real ROS 2's CDR, asked from a test: run in a venv of harness/ros2_env.py, it answers
JSON lines on stdin with `rclpy.serialization` (no node, no DDS participant).

    {"op": "decode", "type": "geometry_msgs/msg/Twist", "cdr": HEX, "probe": [offsets]}
        -> {"values": {...}, "ignored": [offsets]}: the message as plain values, and those
           of the probed bytes whose value changes nothing when flipped (alignment
           padding, which ROS leaves uninitialised; the encapsulation's options)
    {"op": "encode", "type": ..., "values": {...}} -> {"cdr": HEX}
    anything that fails                            -> {"error": "one line"}

Values: a message is a dict of its fields, a sequence or array a list, a byte array a list
of ints, a string a str; floats as Python floats. A service's or action's member type is
named as ROS does ('nav2_msgs/action/NavigateToPose_SendGoal_Request',
'action_msgs/srv/CancelGoal_Request').
"""

from __future__ import annotations

import importlib
import json
import sys
from typing import Any

from rclpy.serialization import deserialize_message, serialize_message
from rosidl_parser import definition


def message_class(ros_type: str) -> Any:
    """The Python class of a ROS type name, member types of services and actions included."""
    package, kind, name = ros_type.split("/")
    module = importlib.import_module(f"{package}.{kind}")
    for suffix, member in (
        ("_SendGoal_Request", ("Impl", "SendGoalService", "Request")),
        ("_SendGoal_Response", ("Impl", "SendGoalService", "Response")),
        ("_GetResult_Request", ("Impl", "GetResultService", "Request")),
        ("_GetResult_Response", ("Impl", "GetResultService", "Response")),
        ("_FeedbackMessage", ("Impl", "FeedbackMessage")),
        ("_Goal", ("Goal",)),
        ("_Result", ("Result",)),
        ("_Feedback", ("Feedback",)),
        ("_Request", ("Request",)),
        ("_Response", ("Response",)),
    ):
        if name.endswith(suffix) and hasattr(module, name.removesuffix(suffix)):
            found = getattr(module, name.removesuffix(suffix))
            for part in member:
                found = getattr(found, part)
            return found
    return getattr(module, name)


def to_values(message: Any) -> Any:
    if hasattr(message, "get_fields_and_field_types"):
        return {
            field: to_values(getattr(message, field))
            for field in message.get_fields_and_field_types()
        }
    if isinstance(message, (bytes, bytearray)):
        return list(message)
    if hasattr(message, "tolist"):  # numpy arrays
        return message.tolist()
    if isinstance(message, (list, tuple)) or type(message).__name__ == "array":
        return [to_values(item) for item in message]
    return message


def _class_of(slot: Any) -> Any:
    return message_class("/".join([*slot.namespaces, slot.name]))


def from_values(cls: Any, values: dict[str, Any]) -> Any:
    message = cls()
    slots = dict(zip(message.get_fields_and_field_types(), cls.SLOT_TYPES, strict=True))
    for field, value in values.items():
        slot = slots[field]
        if isinstance(slot, definition.NamespacedType):
            value = from_values(_class_of(slot), value)
        elif isinstance(slot, definition.AbstractNestedType) and isinstance(
            slot.value_type, definition.NamespacedType
        ):
            value = [from_values(_class_of(slot.value_type), item) for item in value]
        setattr(message, field, value)
    return message


def ignored(cls: Any, raw: bytes, probe: list[int]) -> list[int]:
    """Those of the `probe` offsets of `raw` whose bytes real ROS does not read: flipping
    one changes nothing it decodes."""
    original = to_values(deserialize_message(raw, cls))
    found = []
    flipped = bytearray(raw)
    for offset in probe:
        flipped[offset] ^= 0xFF
        try:
            same = to_values(deserialize_message(bytes(flipped), cls)) == original
        except Exception:  # a length that no longer fits: the byte is read
            same = False
        if same:
            found.append(offset)
        flipped[offset] ^= 0xFF
    return found


def answer(request: dict[str, Any]) -> dict[str, Any]:
    cls = message_class(request["type"])
    match request["op"]:
        case "decode":
            raw = bytes.fromhex(request["cdr"])
            return {
                "values": to_values(deserialize_message(raw, cls)),
                "ignored": ignored(cls, raw, request.get("probe", [])),
            }
        case "encode":
            return {"cdr": serialize_message(from_values(cls, request["values"])).hex()}
        case other:
            raise ValueError(f"unknown op {other!r}; known: decode, encode")


def main() -> None:
    for line in sys.stdin:
        try:
            reply = answer(json.loads(line))
        except Exception as exc:
            reply = {"error": f"{type(exc).__name__}: {exc}"}
        print(json.dumps(reply), flush=True)


if __name__ == "__main__":
    main()
