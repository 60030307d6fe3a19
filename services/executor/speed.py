"""Which velocity an order may send to the robot's motors: one pure decision, `command`.

Every velocity the executor sends goes through it (`RobotLink.drive`), whether an executor
drove with `ctx.robot.drive` or published its own Twist bytes on cmd_vel. The rules, in
the order they apply to each axis (docs/executors.md has them as a table):

- **not a number**: a wanted speed that is NaN or infinite is refused, the whole command
  with it: nothing of it reaches the robot, which is stopped instead, and the order fails;
- **stop**: zero goes out at once;
- **slowing down**: a speed the same way as the last one sent, and no faster, at once;
- **top speed**: anything faster than the limit is held to it;
- **speeding up**: from the last speed sent (from rest when it reverses) by at most the
  acceleration limit times the time since;
- **as asked**: anything else goes out as the order asked it.

Nav2's goals carry no speed: what reaches Nav2 is its `speed_limit` topic
(services/executor/robot.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import msgspec

CONTROL_STEP = 0.1
"""Seconds of speeding up one velocity command may use at most: the first after a pause
starts from rest, however long the pause."""


class SpeedLimits(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """How fast the executor lets any order move the robot, whatever the order asks: every
    velocity command is held to these (`--max-speed` ...). Slowing down is never held back."""

    linear: float = 0.5
    """m/s, forwards or backwards."""
    angular: float = 1.5
    """rad/s, either way."""
    linear_accel: float = 1.0
    """m/s², speeding up."""
    angular_accel: float = 3.0
    """rad/s², speeding up."""

    def __post_init__(self) -> None:
        for name in self.__struct_fields__:
            value = getattr(self, name)
            if not 0.0 < value < math.inf:
                raise ValueError(f"speed limit {name} must be a number above 0, not {value}")


SAFE_LIMITS = SpeedLimits()
"""The limits of a robot configured with none: a walking pace, a gentle start."""

NOT_A_NUMBER = "not a number"
STOP = "stop"
SLOWING = "slowing down"
TOP_SPEED = "top speed"
SPEEDING_UP = "speeding up"
AS_ASKED = "as asked"
RULES = (NOT_A_NUMBER, STOP, SLOWING, TOP_SPEED, SPEEDING_UP, AS_ASKED)
"""Every rule of `command`, in the order they are tried."""


@dataclass(frozen=True)
class Take:
    """Send this velocity."""

    linear: float
    angular: float
    rules: tuple[str, str]
    """The rule that set each axis (linear, angular)."""


@dataclass(frozen=True)
class Refuse:
    """Send nothing of it: stop the robot, and fail the order with `reason`."""

    reason: str
    rule: str = NOT_A_NUMBER


def command(
    linear: float,
    angular: float,
    last: tuple[float, float],
    limits: SpeedLimits,
    dt: float,
) -> Take | Refuse:
    """What goes to the motors when an order asks `linear` m/s and `angular` rad/s, the
    last command sent having been `last` (linear, angular) `dt` seconds ago (at most
    `CONTROL_STEP`, and `last` zero when it is stale)."""
    wrong = [
        f"{axis} speed {value}"
        for axis, value in (("linear", linear), ("angular", angular))
        if not math.isfinite(value)
    ]
    if wrong:
        return Refuse(f"an order asked for {' and '.join(wrong)}: not a finite number")
    dt = dt if 0.0 <= dt <= CONTROL_STEP else CONTROL_STEP
    last_linear, last_angular = (value if math.isfinite(value) else 0.0 for value in last)
    held_linear, linear_rule = _axis(linear, last_linear, limits.linear, limits.linear_accel, dt)
    held_angular, angular_rule = _axis(
        angular, last_angular, limits.angular, limits.angular_accel, dt
    )
    return Take(held_linear, held_angular, (linear_rule, angular_rule))


def limited(wanted: float, last: float, top: float, accel: float, dt: float) -> float:
    """`wanted` held to `top`, and to speeding up by at most `accel * dt` from `last`;
    slower than `last` (or zero) at once, and through zero at once when it reverses.
    `wanted` must be a finite number (`command` refuses any other)."""
    return _axis(wanted, last, top, accel, dt)[0]


def _axis(wanted: float, last: float, top: float, accel: float, dt: float) -> tuple[float, str]:
    """One axis of `command`: the speed sent, and the rule that set it."""
    if wanted == 0.0:
        return 0.0, STOP
    capped = max(-top, min(top, wanted))
    same_way = last != 0.0 and (capped > 0.0) == (last > 0.0)
    if same_way and abs(capped) <= abs(last):
        return capped, TOP_SPEED if capped != wanted else SLOWING
    base = last if same_way else 0.0
    step = accel * dt
    held = base + max(-step, min(step, capped - base))
    if held != capped:
        return held, SPEEDING_UP
    return held, TOP_SPEED if capped != wanted else AS_ASKED
