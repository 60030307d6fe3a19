"""The messages' own invariants (shared/messages.py): an order's target pose and its number
parameters are finite numbers, whoever makes one, and JSON that says otherwise is refused
where it is decoded, in one line."""

from __future__ import annotations

import math

import msgspec
import pytest
from hypothesis import given
from hypothesis import strategies as st

from voicectl.shared.bus import json_decoder
from voicectl.shared.messages import Execute, Order, SupervisorRequest, TargetPose

FLOATS = st.floats(allow_nan=True, allow_infinity=True)


@given(FLOATS, FLOATS, FLOATS)
def test_a_target_pose_is_finite_numbers_or_nothing(x: float, y: float, yaw: float) -> None:
    if all(math.isfinite(value) for value in (x, y, yaw)):
        assert TargetPose(frame="map", x=x, y=y, yaw=yaw).x == x
        return
    with pytest.raises(ValueError, match="must be a finite number") as made:
        TargetPose(frame="map", x=x, y=y, yaw=yaw)
    assert "\n" not in str(made.value)
    raw = {"frame": "map", "x": x, "y": y, "yaw": yaw}
    with pytest.raises(msgspec.ValidationError, match="must be a finite number"):
        msgspec.convert(raw, TargetPose)


@given(FLOATS)
def test_an_order_s_number_parameters_are_finite(value: float) -> None:
    params = {"distance": value, "how": "nan"}  # a string that says nan is only a string
    if math.isfinite(value):
        assert Order(order="go", label="drive", description="go", params=params).params == params
        return
    with pytest.raises(ValueError, match="parameter 'distance' must be a finite number"):
        Order(order="go", label="drive", description="go", params=params)


ORDER = b'{"order":"go","label":"drive","description":"go","params":{"distance":%s}}'
POSED = b'{"order":"go","label":"mbgoal","description":"go","target_pose":{"frame":"map","x":%s}}'


@pytest.mark.parametrize("number", [b"NaN", b"Infinity", b"-Infinity", b"1e999", b"null"])
@pytest.mark.parametrize("order", [ORDER, POSED], ids=["param", "pose"])
def test_json_numbers_that_are_not_finite_are_refused_where_decoded(
    number: bytes, order: bytes
) -> None:
    """JSON has no NaN nor infinity: what writes them (`NaN`, `1e999`, or `null`, as
    msgspec and browsers write a NaN) gives an order the executor and the supervisor
    refuse at their edge, in one line, before any of it runs."""
    execute = b'{"type":"execute","order_id":"x","order":' + order % number + b"}"
    submit = b'{"type":"submit","request_id":"r","orders":[' + order % number + b"]}"
    for raw, kind in ((execute, Execute), (submit, SupervisorRequest)):
        with pytest.raises((msgspec.DecodeError, msgspec.ValidationError)) as refused:
            json_decoder(kind)(raw)
        assert "\n" not in str(refused.value)
