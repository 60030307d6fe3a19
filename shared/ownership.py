"""Who supervises a robot, by the one rule the supervisors and the executors share.

A supervisor claims a robot with a liveliness token, `voice/<robot>/supervisor/owner/<zid>`
(`<zid>`: its Zenoh session's id). Anyone on the bus can hold such a token, so a token
alone proves nothing: the supervisor is the process whose token is up and which answers,
from the very session the token names, as that robot's supervisor on the robot's request
key (its `GetState`). A second supervisor stands down when it finds one at its start
(services/supervisor/service.py); the executor takes orders from that one supervisor only
(services/executor/owner.py). On a secured bus only the supervisor may hold the token or
answer on the key at all (voicectl/secure-router.json5); on an open one this is the rule.

Both checks wait on the bus: run them in a thread.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterable, Mapping

import msgspec
import zenoh

from .bus import Bus, json_decoder
from .keys import RobotKeys, last_chunk
from .messages import GetState, State, StateReply, SupervisorReply

OWNER_CHECK = 2.0
"""Seconds to find who holds a robot's owner token, and who answers for it."""


def owner_tokens(session: zenoh.Session, robot: str, timeout: float = OWNER_CHECK) -> list[str]:
    """The Zenoh ids named by the owner tokens up for `robot` (blocks)."""
    replies = session.liveliness().get(RobotKeys(robot).supervisor_owner("*"), timeout=timeout)
    return [last_chunk(str(reply.ok.key_expr)) for reply in replies if reply.ok is not None]


def answering(bus: Bus, robot: str, timeout: float = OWNER_CHECK) -> dict[str, State]:
    """What each other process that answers as `robot`'s supervisor says of the robot's
    orders, by its Zenoh id (blocks): the replies to `GetState` on the robot's request
    key, from every process but this one, that are a state of that robot."""
    replies = bus.session.get(
        RobotKeys(robot).supervisor,
        payload=bus.encode(GetState()),
        target=zenoh.QueryTarget.ALL,
        # Every reply, each from its own process: Zenoh's default keeps only the latest of
        # the replies on one key, and a made-up supervisor's could hide the real one's.
        consolidation=zenoh.ConsolidationMode.NONE,
        allowed_destination=zenoh.Locality.REMOTE,
        timeout=timeout,
    )
    decode = json_decoder(SupervisorReply)
    found: dict[str, State] = {}
    for reply in replies:
        replier = reply.replier_id
        if reply.ok is None or replier is None:
            continue
        with contextlib.suppress(msgspec.DecodeError, msgspec.ValidationError):
            answer = decode(reply.ok.payload.to_bytes())
            if isinstance(answer, StateReply) and answer.state.robot == robot:
                found[str(replier.zid)] = answer.state
    return found


def owners(tokens: Iterable[str], answers: Mapping[str, State]) -> list[str]:
    """The Zenoh ids that supervise the robot by the rule: a token up, and an answer as
    its supervisor from the same session; in the tokens' order, each once."""
    return list(dict.fromkeys(tag for tag in tokens if tag in answers))
