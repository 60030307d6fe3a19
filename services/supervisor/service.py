"""The supervisor on the bus: one process for every robot under ``voice/*``.

Per robot a `RobotSupervisor` (robot.py) answers requests, dispatches orders and
publishes state. Here: which robots are served (a robot appears the first time any
request, event or executor token names it, up to `MAX_ROBOTS`), the claim on each that
keeps a second supervisor off it, and the submits committed in batches.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable, Coroutine
from dataclasses import dataclass
from typing import Any

from voicectl.shared.bus import Bus, Pending, json_decoder
from voicectl.shared.errors import ServiceError
from voicectl.shared.keys import ANY, RobotKeys, last_chunk, robot_of
from voicectl.shared.keys import MAX_ROBOTS as MAX_ROBOTS  # (`--max-robots`)
from voicectl.shared.messages import (
    EmergencyStop,
    ExecutorEvent,
    ExecutorInfo,
    Failed,
    Message,
    Release,
    Submit,
    Submitted,
    SupervisorRequest,
)
from voicectl.shared.ownership import OWNER_CHECK, answering, owner_tokens, owners
from voicectl.shared.process import Service
from voicectl.shared.robot.stop import prepare
from voicectl.shared.throttle import Throttled

from .queue import MAX_QUEUE, RobotQueue
from .robot import STOP_NODE, RobotSupervisor
from .store import OrderStore

_LOGGER = logging.getLogger(__name__)

CLAIM_WINDOW = 2.0
"""Seconds after this supervisor claimed a robot during which another's claim counts as
made at the same time, and is settled by Zenoh id; any later one is a newcomer's, which
never displaces it."""
KNOWN_LISTED = 10
"""Robots named in the refusal of a request for an unknown one."""


Waiting = tuple[Pending[SupervisorRequest], RobotSupervisor, Submit, tuple[list[str], bool]]
"""A submit taken and queued, to be answered once its orders are committed."""


@dataclass
class Claim:
    """This supervisor's claim on one robot: its owner token on the bus, and since when."""

    at: float
    """Loop time of the claim."""
    ends: list[Callable[[], None]]
    """What it declared on the bus for the robot, to withdraw when it lets go."""
    kept: bool
    """Named with --robot or restored from the store: never let go to make room, and a
    rival that wins it means this process must stop. A robot taken on because its
    executor announced itself is let go instead."""


class SupervisorService(Service):
    """Every robot's supervisor in one process, sharing one bus and one store.

    A service (shared/process.py): `start()` restores the queues and serves them, `run()`
    ends only when another supervisor turns out to serve one of this one's robots
    (ServiceError), `stop()` stops each robot's dispatch.

    Robots come from the configuration (`robots`), from the store, and from executors
    that announce themselves (their liveliness token), at most `max_robots` of the last:
    past that, a robot whose executor has gone and that holds nothing (no order, no stop)
    makes room, and otherwise the newcomer is not served. Only executor tokens are heard
    for every robot name; events, announcements and owner tokens are subscribed to per
    robot served, so that made-up names cost nothing past the cap, and requests naming
    any other robot are refused.

    A robot has one supervisor. Before claiming one (its owner token), a supervisor looks
    for another's token, and counts it only if that supervisor answers for the robot
    (anyone on the bus can hold a token). A claim made later never displaces the one
    serving; two made at the same time (within `CLAIM_WINDOW`) are settled by Zenoh id,
    the lower keeping the robot. No wall clock takes part.
    """

    def __init__(
        self,
        bus: Bus,
        store: OrderStore,
        robots: list[str],
        *,
        continue_on_failure: bool = False,
        history_in_memory: int = 50,
        max_robots: int = MAX_ROBOTS,
        max_queue: int = MAX_QUEUE,
    ) -> None:
        self._bus = bus
        self._announced = robots
        self._store = store
        self._continue_on_failure = continue_on_failure
        self._history = history_in_memory
        self._max_robots = max_robots
        self._max_queue = max_queue
        self._robots: dict[str, RobotSupervisor] = {}
        self._zid = str(bus.session.zid())
        """Who this supervisor is on the bus: the last chunk of its owner tokens."""
        self._claims: dict[str, Claim] = {}
        self._serving = False
        """Requests are served: a robot added now is announced at once."""
        self._room_maybe = True
        """A robot may have gone idle since `_make_room` last found none."""
        self._admitting: dict[str, bool] = {}
        """Robots whose executor announced itself, being checked for another supervisor;
        with whether its token is still up."""
        self._decode_event = json_decoder(ExecutorEvent)
        self._decode_info = json_decoder(ExecutorInfo)
        self._noise = Throttled(_LOGGER)
        self._tasks: set[asyncio.Task[None]] = set()
        self.conflict: asyncio.Future[str] = asyncio.get_running_loop().create_future()
        """Set, saying why, when another supervisor serves one of this one's robots (one
        it keeps) and wins it: a robot has one supervisor, and this one must stop."""

    async def start(self) -> None:
        robots = self._announced
        saved = await self._store.call(self._store.load(self._history))
        kept = [*saved, *(name for name in robots if name not in saved)]
        for name, rival in zip(kept, await asyncio.gather(*map(self._rival, kept)), strict=True):
            if rival is not None:
                raise ServiceError(_taken(name, rival))
        # A latch file that cannot be read may have held any robot's STOP: all stopped.
        unsure = bool(self._store.latched.unreadable)
        for name, robot in saved.items():
            queue = self._new_queue(name)
            queue.restore(robot.open_orders, robot.history, robot.requests)
            queue.stopped = robot.stopped or unsure
            self._add(queue, kept=True)
            if robot.open_orders:
                _LOGGER.info("%s: restored %d open order(s)", name, len(robot.open_orders))
        for name in robots:
            if name not in self._robots:
                queue = self._new_queue(name)
                queue.stopped = unsure
                self._add(queue, kept=True)
        for name, served in self._robots.items():
            if served.stopped:  # said again: the latch file is written afresh
                self._store.set_stopped(name, True)
        # A robot whose executor this supervisor never hears is stopped on the keys its
        # graph announces (RobotStop.of): follow it from now on, and have the stop's codec
        # built before any STOP can arrive.
        await prepare(None, self._bus, STOP_NODE)
        # A burst of submits is taken in one go and committed once; STOP overtakes them.
        self._bus.serve_in_turn(
            RobotKeys.any_robot().supervisor,
            json_decoder(SupervisorRequest),
            self._on_request,
            batched=lambda request: isinstance(request, Submit),
            take=self._take_submits,
            overtakes=lambda request: isinstance(request, EmergencyStop),
        )
        self._bus.watch(RobotKeys.any_robot().alive("executor"), self._on_executor)
        # Served from now on: said for each robot (panels list the robots served).
        self._serving = True
        for name, claim in self._claims.items():
            claim.ends.append(self._bus.announce(RobotKeys(name).alive("supervisor")))
        _LOGGER.info("supervisor ready; history in %s", self._store.path)

    async def run(self) -> None:
        raise ServiceError(await self.conflict)

    async def stop(self) -> None:
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        await asyncio.gather(*(r.stop() for r in self._robots.values()))

    def _new_queue(self, name: str) -> RobotQueue:
        return RobotQueue(
            name,
            continue_on_failure=self._continue_on_failure,
            history_limit=self._history,
            max_queue=self._max_queue,
        )

    def _add(self, queue: RobotQueue, kept: bool) -> RobotSupervisor:
        """Serve `queue`'s robot: claim it (the owner token), hear its executor's events
        and announcement (the last one too, which the executor sends before its token),
        and other supervisors' claims."""
        robot = RobotSupervisor(self._bus, self._store, queue)
        keys = RobotKeys(queue.robot)
        self._robots[queue.robot] = robot
        robot.start()
        bus = self._bus
        ends = [
            bus.announce(keys.supervisor_owner(self._zid)),
            bus.watch(keys.supervisor_owner(ANY), self._on_owner),
            bus.subscribe(keys.executor_events, self._decode_event, lambda _, e: robot.on_event(e)),
            bus.subscribe(
                keys.executor_info, self._decode_info, lambda _, i: robot.on_info(i), history=True
            ),
        ]
        if self._serving:
            ends.append(bus.announce(keys.alive("supervisor")))
        self._claims[queue.robot] = Claim(asyncio.get_running_loop().time(), ends, kept)
        return robot

    def _retire(self, name: str) -> None:
        """Stop serving `name`: its owner token and subscriptions withdrawn, its dispatch
        stopped."""
        for end in self._claims.pop(name).ends:
            end()
        self._spawn(self._robots.pop(name).stop())

    def _spawn(self, work: Coroutine[Any, Any, None]) -> None:
        task = asyncio.get_running_loop().create_task(work)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    # --- which robots -------------------------------------------------------------------

    def _on_executor(self, key: str, alive: bool) -> None:
        name = robot_of(key)
        robot = self._robots.get(name)
        if robot is not None:
            robot.on_executor(alive)
            self._room_maybe |= not alive
        elif name in self._admitting:
            self._admitting[name] = alive
        elif alive:
            self._admit(name)

    def _admit(self, name: str) -> None:
        """Serve `name`, whose executor announced itself, if there is room (making some if
        a robot gone idle can give it) and no other supervisor serves it."""
        taken = sum(not claim.kept for claim in self._claims.values()) + len(self._admitting)
        if taken >= self._max_robots and not self._make_room():
            self._noise.warning(
                "admit",
                "robot '%s' is not served: %d robots besides those configured are served "
                "already (--max-robots), none idle; start the supervisor with --robot %s",
                name,
                taken,
                name,
            )
            return
        self._admitting[name] = True
        self._spawn(self._admit_unless_served(name))

    async def _admit_unless_served(self, name: str) -> None:
        try:
            rival = await self._rival(name)
        finally:
            alive = self._admitting.pop(name)
        if rival is not None:
            _LOGGER.info("%s: served by another supervisor (Zenoh id %s)", name, rival)
        elif name not in self._robots:
            self._add(self._new_queue(name), kept=False).on_executor(alive)

    def _make_room(self) -> bool:
        """Let go of the robot idle the longest that was taken on for its executor (gone
        since); False if there is none. Not looked for again until an executor goes: a
        flood of names past the cap must not cost a look at every robot each."""
        if not self._room_maybe:
            return False
        idle = [
            name
            for name, robot in self._robots.items()
            if robot.idle and not self._claims[name].kept
        ]
        if not idle:
            self._room_maybe = False
            return False
        oldest = min(idle, key=lambda name: self._robots[name].heard_at)
        _LOGGER.info("%s: no longer served: its executor has gone, and room is needed", oldest)
        self._retire(oldest)
        return True

    # --- who serves a robot ---------------------------------------------------------------

    async def _rival(self, robot: str) -> str | None:
        """The Zenoh id of another supervisor serving `robot` (shared/ownership.py: its
        owner token up, and it answers for the robot); None if there is none."""
        tokens = await asyncio.to_thread(owner_tokens, self._bus.session, robot, OWNER_CHECK)
        if all(tag == self._zid for tag in tokens):
            return None  # no one else claims it: nobody to ask (a made-up name, mostly)
        answers = await asyncio.to_thread(answering, self._bus, robot, OWNER_CHECK)
        supervising = owners(tokens, answers)
        for tag in tokens:
            if tag != self._zid and tag not in supervising:
                self._forged(robot, tag)
        return next((tag for tag in supervising if tag != self._zid), None)

    async def _answers(self, robot: str, zid: str) -> bool:
        """Whether the process with Zenoh id `zid` answers as `robot`'s supervisor: a
        token alone proves nothing."""
        return zid in await asyncio.to_thread(answering, self._bus, robot, OWNER_CHECK)

    def _forged(self, robot: str, tag: str) -> None:
        self._noise.warning(
            "owner",
            "robot '%s': an owner token names Zenoh id %s, which does not answer as its "
            "supervisor: ignored (anyone on the bus can hold a token)",
            robot,
            tag,
        )

    def _on_owner(self, key: str, alive: bool) -> None:
        robot, tag = robot_of(key), last_chunk(key)
        claim = self._claims.get(robot)
        if not alive or claim is None or tag == self._zid:
            return
        if asyncio.get_running_loop().time() - claim.at > CLAIM_WINDOW:
            # Whoever claims it now came later: it finds this one at its start, and stands
            # down if it is a supervisor. This one keeps the robot either way.
            self._noise.warning(
                "claim",
                "robot '%s': another claim to supervise it (Zenoh id %s), made while this "
                "supervisor serves it: this one keeps it",
                robot,
                tag,
            )
            return
        self._spawn(self._settle(robot, tag, claim))

    async def _settle(self, robot: str, tag: str, claim: Claim) -> None:
        """Two claims at the same time: the lower Zenoh id keeps the robot, if the other
        answers for it at all."""
        if not await self._answers(robot, tag):
            self._forged(robot, tag)
            return
        if not tag < self._zid or self._claims.get(robot) is not claim:
            return  # it stands down, or this one has already let go
        if claim.kept or self._robots[robot].holds_orders:
            if not self.conflict.done():
                self.conflict.set_result(_taken(robot, tag))
            return
        _LOGGER.info("%s: served by another supervisor (Zenoh id %s): let go", robot, tag)
        self._retire(robot)

    # --- requests and events ---------------------------------------------------------------

    async def _on_request(self, key: str, request: SupervisorRequest) -> Message:
        name = robot_of(key)
        if name not in self._robots:
            return self._unknown(name)
        self._room_maybe |= isinstance(request, Release)  # a released robot may be idle
        return await self._robots[name].handle(request)

    def _take_submits(self, batch: list[Pending[SupervisorRequest]]) -> None:
        """Submits in arrival order, each queued now; those accepted are answered together,
        from the store's thread, as soon as one commit holds them all: no order is
        acknowledged before it is on disk, and the loop is not woken once per submit."""
        waiting: list[Waiting] = []
        robots: dict[str, RobotSupervisor] = {}
        for pending in batch:
            submit = pending.request
            assert isinstance(submit, Submit)  # what `batched` lets through
            name = robot_of(pending.key)
            if name not in self._robots:
                pending.answer(self._unknown(name))
                continue
            robot = self._robots[name]
            accepted = robot.accept(submit)
            if isinstance(accepted, Failed):
                pending.answer(accepted)
                continue
            # A retry is answered after this commit too: its first one is stored by then.
            robots[name] = robot
            waiting.append((pending, robot, submit, accepted))
        if not waiting:
            return
        operations = [operation for robot in robots.values() for operation in robot.changes()]
        loop = asyncio.get_running_loop()

        def committed(error: BaseException | None) -> None:  # on the store's thread
            if error is None:
                for pending, _, _, (ids, _) in waiting:
                    pending.answer(Submitted(order_ids=ids))
            else:
                with contextlib.suppress(RuntimeError):  # the loop closed: nobody waits
                    loop.call_soon_threadsafe(self._not_stored, waiting, error)

        self._store.write_then(operations, committed)

    def _not_stored(self, waiting: list[Waiting], error: BaseException) -> None:
        for pending, robot, submit, (_, new) in waiting:
            pending.answer(robot.not_stored(submit, new, error))

    def _unknown(self, name: str) -> Failed:
        # A name nobody has configured or served: answer without creating a robot, so that
        # made-up names cannot grow the process without limit. Not even a STOP creates
        # one: with no executor ever heard of, there is no robot to know the keys of.
        # Asking its state is refused as well, naming the robots there are: a typo
        # answered with an empty state looks like an idle robot.
        names = sorted(self._robots)
        known = ", ".join(names[:KNOWN_LISTED]) or "none"
        if len(names) > KNOWN_LISTED:
            known += f" and {len(names) - KNOWN_LISTED} more"
        return Failed(
            reason=f"no executor has served robot '{name}' (known robots: {known}); start "
            "its executor, or the supervisor with --robot"
        )


def _taken(robot: str, zid: str) -> str:
    return (
        f"robot '{robot}' already has a supervisor (Zenoh id {zid}, which answers for it); "
        "a robot has one supervisor: stop the other one, or give this one a router of its own"
    )
