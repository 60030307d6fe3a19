"""Whom the executor takes orders from: the supervisor that owns its robot, and no one else.

The executor's execute key is open to anyone on an open bus, and an order there moves the
robot. So before it takes one, the executor asks who supervises the robot by the rule the
supervisors keep among themselves (shared/ownership.py: an owner token up, and an answer
as the robot's supervisor from the session the token names), and takes the order only if
that one supervisor says it is the order it runs now. A made-up supervisor (a token and
nothing behind it, or an answer and no token), another robot's, or a second process
claiming this robot beside its supervisor gets the order refused, saying why.

`sender` is the decision, pure; `OwnerCheck` asks the bus for what it decides on.
"""

from __future__ import annotations

import asyncio
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from voicectl.shared.bus import Bus
from voicectl.shared.messages import Execute, State
from voicectl.shared.ownership import OWNER_CHECK, answering, owner_tokens, owners


@dataclass(frozen=True)
class Take:
    """Run it: `supervisor` (its Zenoh id) owns the robot and runs this very order."""

    supervisor: str


@dataclass(frozen=True)
class Refuse:
    """Refuse it, saying `reason`."""

    reason: str


def sender(
    robot: str, execute: Execute, tokens: Sequence[str], answers: Mapping[str, State]
) -> Take | Refuse:
    """Whether `execute` comes from the supervisor that owns `robot`, given the Zenoh ids
    of the owner tokens up for it and what each process answering as its supervisor says
    it runs (`answers`, by Zenoh id)."""
    supervising = owners(tokens, answers)
    why = f"orders for robot '{robot}' are taken from its supervisor only"
    match supervising:
        case []:
            claims = [tag for tag in tokens if tag not in answers]
            detail = (
                f"an owner token names Zenoh id {', '.join(claims)}, which does not answer as "
                "its supervisor"
                if claims
                else "no owner token is up"
            )
            return Refuse(f"no supervisor owns robot '{robot}' ({detail}): {why}")
        case [owner]:
            current = answers[owner].current
            if current is None or current.id != execute.order_id or current.order != execute.order:
                running = f"'{current.id}'" if current is not None else "no order"
                return Refuse(
                    f"order '{execute.order_id}' is not the one robot '{robot}''s supervisor "
                    f"(Zenoh id {owner}) runs, which is {running}: {why}"
                )
            return Take(owner)
        case _:
            return Refuse(
                f"{len(supervising)} processes claim robot '{robot}' and answer as its "
                f"supervisor (Zenoh ids {', '.join(supervising)}): {why}, and it is not told "
                "which one that is; one must stand down"
            )


class OwnerCheck:
    """Asks the bus who supervises `robot`, for each order offered (`sender`)."""

    def __init__(self, bus: Bus, robot: str, timeout: float = OWNER_CHECK) -> None:
        self._bus = bus
        self._robot = robot
        self._timeout = timeout

    async def check(self, execute: Execute) -> Take | Refuse:
        """Whether to take `execute`; both questions asked at once, off the loop."""
        tokens, answers = await asyncio.gather(
            asyncio.to_thread(owner_tokens, self._bus.session, self._robot, self._timeout),
            asyncio.to_thread(answering, self._bus, self._robot, self._timeout),
        )
        return sender(self._robot, execute, tokens, answers)
