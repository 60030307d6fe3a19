"""Which velocity may reach a motor (services/executor/speed.py): `command` walked over every
kind of input, NaN and infinities included, against the rules docs/executors.md writes."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from voicectl.services.executor.config import limit_flags, limits_of, parse_args
from voicectl.services.executor.speed import (
    AS_ASKED,
    CONTROL_STEP,
    NOT_A_NUMBER,
    RULES,
    SAFE_LIMITS,
    SLOWING,
    SPEEDING_UP,
    STOP,
    TOP_SPEED,
    Refuse,
    SpeedLimits,
    Take,
    command,
)

WANTED = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 0.5, -0.5, 1.5, -1.5, math.nan, math.inf, -math.inf]),
)
"""What an order may ask: anything a float holds, the limits themselves, and what is not
a number."""
LAST = st.floats(-1.5, 1.5)
DT = st.floats(0.0, CONTROL_STEP)
LIMITS = st.builds(
    SpeedLimits,
    linear=st.floats(0.01, 5.0),
    angular=st.floats(0.01, 5.0),
    linear_accel=st.floats(0.01, 10.0),
    angular_accel=st.floats(0.01, 10.0),
)


@given(WANTED, WANTED, LAST, LAST, LIMITS, DT)
def test_only_finite_speeds_within_the_limits_ever_reach_a_motor(
    linear: float,
    angular: float,
    last_linear: float,
    last_angular: float,
    limits: SpeedLimits,
    dt: float,
) -> None:
    """The invariants, whatever is asked: a command with a speed that is not a finite
    number is refused whole, with a reason naming it; anything else goes out as finite
    numbers no faster than the top speeds, the same way as asked (or zero), and faster
    than the last command by at most the acceleration times the time since."""
    verdict = command(linear, angular, (last_linear, last_angular), limits, dt)
    asked = {"linear": linear, "angular": angular}
    if not all(math.isfinite(value) for value in asked.values()):
        assert isinstance(verdict, Refuse)
        assert verdict.rule == NOT_A_NUMBER
        for axis, value in asked.items():
            assert (f"{axis} speed {value}" in verdict.reason) is (not math.isfinite(value))
        assert "\n" not in verdict.reason
        return
    assert isinstance(verdict, Take)
    axes = (
        (verdict.linear, linear, last_linear, limits.linear, limits.linear_accel),
        (verdict.angular, angular, last_angular, limits.angular, limits.angular_accel),
    )
    for (sent, wanted, last, top, accel), rule in zip(axes, verdict.rules, strict=True):
        assert math.isfinite(sent)
        assert abs(sent) <= top
        assert rule in RULES
        if wanted == 0.0:
            assert (sent, rule) == (0.0, STOP)
            continue
        assert sent == 0.0 or (sent > 0.0) == (wanted > 0.0)  # never the other way
        assert abs(sent) <= abs(wanted)
        if abs(sent) > abs(last) or (sent != 0.0 and (sent > 0.0) != (last > 0.0)):
            base = last if (last > 0.0) == (sent > 0.0) else 0.0
            assert abs(sent - base) <= accel * dt + 1e-12, rule
        if rule == AS_ASKED:
            assert sent == wanted
        if rule == SLOWING:
            assert sent == wanted
            assert abs(sent) <= abs(last)
        if rule == TOP_SPEED:
            assert abs(wanted) > top
        if rule == SPEEDING_UP:
            assert abs(sent) < abs(wanted)


@pytest.mark.parametrize(
    ("linear", "angular", "last", "expected"),
    [
        (0.3, 0.0, (0.3, 0.0), Take(0.3, 0.0, (SLOWING, STOP))),
        (0.2, 0.0, (0.3, 0.0), Take(0.2, 0.0, (SLOWING, STOP))),
        (9.0, 0.0, (0.5, 0.0), Take(0.5, 0.0, (TOP_SPEED, STOP))),
        (0.3, 0.0, (0.0, 0.0), Take(0.1, 0.0, (SPEEDING_UP, STOP))),
        (0.3, 0.0, (0.25, 0.0), Take(0.3, 0.0, (AS_ASKED, STOP))),
        (-0.3, 0.0, (0.3, 0.0), Take(-0.1, 0.0, (SPEEDING_UP, STOP))),
        (
            math.nan,
            0.0,
            (0.3, 0.0),
            Refuse("an order asked for linear speed nan: not a finite number"),
        ),
        (
            math.inf,
            -math.inf,
            (0.3, 0.0),
            Refuse(
                "an order asked for linear speed inf and angular speed -inf: not a finite number"
            ),
        ),
    ],
)
def test_each_rule_of_the_table(
    linear: float, angular: float, last: tuple[float, float], expected: Take | Refuse
) -> None:
    verdict = command(linear, angular, last, SAFE_LIMITS, CONTROL_STEP)
    if isinstance(expected, Take):
        assert isinstance(verdict, Take)
        assert verdict.rules == expected.rules
        assert (verdict.linear, verdict.angular) == pytest.approx((expected.linear, 0.0))
    else:
        assert verdict == expected


@pytest.mark.parametrize("value", [0.0, -1.0, math.nan, math.inf])
def test_limits_are_positive_finite_numbers(value: float) -> None:
    with pytest.raises(ValueError, match="must be a number above 0"):
        SpeedLimits(linear=value)


def test_limits_come_from_the_flags_else_the_environment_else_the_safe_ones() -> None:
    """The executor's limits (and `voicectl up`'s, which passes them on as flags)."""
    args = parse_args(["--max-speed", "0.3"])
    environ = {"VOICECTL_MAX_SPEED": "0.9", "VOICECTL_MAX_ANGULAR_SPEED": "0.7"}
    assert limits_of(args, environ) == SpeedLimits(linear=0.3, angular=0.7)
    assert limits_of(parse_args([]), {}) == SAFE_LIMITS
    assert limits_of(parse_args([]), {"VOICECTL_MAX_ACCEL": " "}) == SAFE_LIMITS
    with pytest.raises(ValueError, match=r"^VOICECTL_MAX_SPEED: 'fast' is not a number above 0$"):
        limits_of(parse_args([]), {"VOICECTL_MAX_SPEED": "fast"})
    flags = limit_flags(SpeedLimits(linear=0.3, angular=0.7))
    assert limits_of(parse_args(flags), {"VOICECTL_MAX_SPEED": "0.9"}) == SpeedLimits(
        linear=0.3, angular=0.7
    )
