"""Stopping a robot: the one implementation of "stop the robot", on any transport.

Zero velocity on cmd_vel, then a cancel of every navigation goal (through the action
client of `action.py`, which the executor's navigation uses too), and what navigation
answered (`RobotStop`). The executor stops its robot with it, the supervisor on STOP and
when the executor is lost, and `voicectl stop` and the panel when no supervisor answers:
whoever is left alive can stop the robot the same way, through the bridge or on rmw_zenoh.

The emergency stop is one procedure (`StopProcedure`), the same whether the supervisor
runs it on STOP or a client does because no supervisor answered: zero velocity first, at
once, before anything is asked of anyone; then the executor's latch (`ExecutorLatch`) and
the cancel of every goal, under way together; then what answered, in words
(`StopOutcome`). What only the supervisor has (its queue, its state, its history) it does
around the procedure, which knows nothing of it.

`zero_velocity` is a plain put: it may be called from any thread (a Zenoh callback, the
executor's watchdog), never waits for an event loop, and goes out at once.

On rmw_zenoh the robot hears only its own key: its type and type hash, as its liveliness
tokens announce them. A stop goes there, never to a key built from a guess: the executor
passes on what it learnt from the robot's tokens (`ExecutorInfo.cmd_vel_hash`), and the
stop's own transport follows the robot's tokens from the moment it is opened (when the
executor announces itself, or a supervisor starts), so that what it sees itself wins.
Zero velocity goes out at once on the best key known; it is sent in every type the robot
announced for cmd_vel as well as in the executor's (on rmw_zenoh each type is a key of its
own). Service calls (the cancel) are asked whatever the type hash, so reach the robot's
server whatever its hash.

A supervisor that never heard of an executor (one started after its executor died) has
no `ExecutorInfo`: it follows every transport of the registry on the default names (in
domain 0 where the layout has domains), and stops through the first on which a robot has
announced a cmd_vel subscriber, in the type and hash it announced (only rmw_zenoh's
subscribers announce a type: the bridge's topics share a key whatever the type), and
through `ExecutorInfo`'s default transport, the bridge, otherwise (`RobotStop.of(None,
...)`).
"""

from __future__ import annotations

import asyncio
import functools
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

from ..bus import Bus, Decode
from ..errors import BusError
from ..keys import RobotKeys
from ..messages import Done, ExecutorInfo, ExecutorReply, Failed, Latch
from ..ros2 import (
    CANCEL_ALL,
    CANCEL_GOAL,
    CmdVelType,
    Ros2Codec,
    RosDistro,
)
from . import TransportKind, open_transport, transports
from .action import CANCEL_TIMEOUT, ActionClient, Cancelled
from .keys import RobotNames
from .transport import Interface, RobotTransport, Role

_LOGGER = logging.getLogger(__name__)

T = TypeVar("T")

transports()  # every transport imported with the stop, not at a process's first STOP

STOP_REPEAT = 3
"""Zero velocity is sent this many times: one lost sample must not leave the robot moving."""
NODE = "voicectl_stop"
"""The ROS node a process that only stops a robot appears as, where nodes are seen."""


@functools.cache
def stop_codec(distro: RosDistro) -> Ros2Codec:
    """The codec that stops robots of `distro`, shared, with its stop messages encoded
    once: building a distribution's types and their encoders costs about 0.1 s, which
    the first STOP of a process paid before anything went out (bench/e2e.py)."""
    codec = Ros2Codec(distro)
    for kind in CmdVelType:
        codec.velocity(kind, 0.0, 0.0, 0.0)
    codec.cancel_goal_request(CANCEL_ALL)
    return codec


UNANNOUNCED = RosDistro.JAZZY
"""The codec that stops a robot no executor announced: a stop's messages (Twist,
TwistStamped, CancelGoal) are the same in every distribution voicectl speaks, so one
prepared codec serves, whatever the robot's tokens say."""

_BUILDING: set[asyncio.Future[None]] = set()
"""Builds under way: the loop keeps only weak references to them."""


def prepare(
    info: ExecutorInfo | None, bus: Bus | None = None, node: str = NODE
) -> asyncio.Future[None]:
    """Build what will stop the robot `info` announces (its codec, and what its transport
    prepares: on rmw_zenoh the type hashes in its keys), off the event loop, as soon as
    its executor announces it: not when someone presses STOP. Given the `bus` (and the
    `node` the stop will use), the stop's transport is opened now too, and follows the
    robot's announcements from now on. `info` None: a robot no executor announced
    (`RobotStop.of`). Nobody has to keep or await the future."""
    if bus is not None:
        if info is None:
            for transport in _unannounced(bus, node):
                transport.follow()
        else:
            _transport(info, _names(info), bus, node).follow()

    def build() -> None:
        if info is None:  # its keys will be the robot's own: nothing to prepare for them
            stop_codec(UNANNOUNCED)
            return
        stop_codec(info.distro)
        transports()[_stop_kind(info)].prepare(
            info.distro, (info.cmd_vel_type.ros_type, CANCEL_GOAL)
        )

    building = asyncio.ensure_future(asyncio.to_thread(build))
    _BUILDING.add(building)
    building.add_done_callback(_BUILDING.discard)
    return building


@dataclass(frozen=True)
class RobotStop:
    """How to stop one robot: its transport and names, its distribution, what cmd_vel takes."""

    transport: RobotTransport
    names: RobotNames
    codec: Ros2Codec
    cmd_vel_type: CmdVelType

    @classmethod
    def of(cls, info: ExecutorInfo | None, bus: Bus, node: str = NODE) -> RobotStop:
        """From what the executor announced; names that make no sense fall back to the
        defaults (with a warning), since a stop on the usual names beats no stop. With no
        `info` at all (no executor was ever heard), the default keys of the first transport
        on which a robot announced its cmd_vel, else the bridge's (see the module's
        docstring)."""
        if info is None:
            names = RobotNames()
            for unannounced in _unannounced(bus, node):
                unannounced.follow()
                types = unannounced.subscriber_types(names.cmd_vel)
                announced = [CmdVelType.of(ros_type) for ros_type in types]
                kind = next((kind for kind in announced if kind is not None), None)
                if kind is not None:
                    return cls(unannounced, names, stop_codec(UNANNOUNCED), kind)
            info = ExecutorInfo()  # its defaults: the bridge, the default names
        names = _names(info)
        transport = _transport(info, names, bus, node)
        transport.follow()
        if info.cmd_vel_hash:
            transport.expect(
                Interface(
                    Role.SUBSCRIBER, names.cmd_vel, info.cmd_vel_type.ros_type, info.cmd_vel_hash
                )
            )
        return cls(transport, names, stop_codec(info.distro), info.cmd_vel_type)

    def zero_velocity(self) -> str:
        """Send zero velocity, first and at once; says where. In the type the robot's
        cmd_vel takes as far as anyone knows, and in every type the robot's subscribers
        announced to this transport (rmw_zenoh), each on its own key."""
        name = self.names.cmd_vel
        kinds = [self.cmd_vel_type]
        for ros_type in self.transport.subscriber_types(name):
            kind = CmdVelType.of(ros_type)
            if kind is not None and kind not in kinds:
                kinds.append(kind)
        stamp = time.time()
        for kind in kinds:
            payload = self.codec.velocity(kind, 0.0, 0.0, stamp)
            for _ in range(STOP_REPEAT):
                self.transport.publish(name, kind.ros_type, payload, urgent=True)
        return f"sent zero velocity on '{name}'"

    @property
    def navigation(self) -> ActionClient:
        """The robot's navigation action, as far as a stop needs it (its cancel): declares
        nothing until used, so a stop pays nothing for it."""
        return ActionClient(self.transport, self.names.topic(self.names.navigate_name), self.codec)

    async def cancel_goals(
        self, goal_id: bytes | None = None, timeout: float = CANCEL_TIMEOUT
    ) -> Cancelled:
        """Cancel one navigation goal, or every goal; what navigation answered."""
        return await self.navigation.cancel(goal_id, timeout)

    def cancel_goals_now(self) -> None:
        """Ask navigation to cancel every goal without waiting for its answer; from any
        thread (one whose event loop is stalled)."""
        self.navigation.cancel_now()

    async def halt(self) -> Cancelled:
        """Zero velocity now, then every goal cancelled; the cancel's outcome, its detail
        prefixed with where the zero velocity went."""
        sent = self.zero_velocity()
        cancelled = await self.cancel_goals()
        return Cancelled(cancelled.answered, cancelled.confirmed, f"{sent}; {cancelled.detail}")


@dataclass(frozen=True)
class LatchAnswer:
    """What the executor said to a stop's latch."""

    detail: str
    """In a few words, for a person."""
    safe: bool
    """It commands the robot no more: it latched, or there is no executor to command it."""
    failed: bool = False
    """It refused, or did not answer although it was online: the order it runs may go on
    running there, and whoever keeps the order has to end it."""


class ExecutorLatch:
    """A robot's executor's stop latch, asked over the bus: while it is on, no order
    commands the robot. The executor answers it off its event loop, so a blocked loop
    does not hold the answer up."""

    def __init__(
        self,
        bus: Bus,
        keys: RobotKeys,
        decode: Decode[ExecutorReply],
        timeout: float,
        online: Callable[[], bool] | None = None,
    ) -> None:
        """`online`: whether the executor is online now, for whoever knows (the
        supervisor): one that is not is not asked, and one that is but does not answer has
        failed. Without it (a client, which cannot know), no answer means no executor,
        and a dead executor commands nothing."""
        self._bus = bus
        self._keys = keys
        self._decode = decode
        self._timeout = timeout
        self._online = online

    async def latch(self) -> LatchAnswer:
        """Latch the executor's stop; what it said."""
        try:
            reply = await self._ask(on=True)
        except BusError as exc:
            if self._online is None:
                return LatchAnswer(
                    "no executor answered (a dead executor commands nothing)", safe=True
                )
            reply = _unreachable(exc)
        match reply:
            case None:
                return LatchAnswer("no executor online", safe=True)
            case Done(detail=detail):
                return LatchAnswer(f"executor: {detail}", safe=True)
            case Failed(reason=reason):
                return LatchAnswer(f"EXECUTOR: {reason}", safe=False, failed=True)
        return LatchAnswer(f"executor answered {type(reply).__name__}", safe=False)

    async def release(self) -> str:
        """Let the executor's latch go (the supervisor's to do, on a key of its own): ''
        once it did, or when no executor is online; else why it did not."""
        try:
            reply = await self._ask(on=False)
        except BusError as exc:
            reply = _unreachable(exc)
        return reply.reason if isinstance(reply, Failed) else ""

    async def _ask(self, on: bool) -> ExecutorReply | None:
        """The executor's reply; None when it is known to be offline, and not asked."""
        if self._online is not None and not self._online():
            return None
        reply: ExecutorReply = await self._bus.request(
            self._keys.executor_latch if on else self._keys.executor_release,
            Latch(on=on),
            self._decode,
            self._timeout,
            urgent=True,
        )
        return reply


def _unreachable(exc: BusError) -> Failed:
    return Failed(reason=f"executor unreachable: {exc}")


@dataclass(frozen=True)
class StopOutcome:
    """What an emergency stop did, and what had answered it when it was looked at."""

    sent: str
    """Where zero velocity went."""
    navigation: Cancelled | None
    """What navigation said to the cancel of every goal; None while it has not answered."""
    executor: LatchAnswer | None
    """What the executor said to the latch; None while it has not answered."""

    @property
    def settled(self) -> bool:
        """Everything asked has answered."""
        return self.navigation is not None and self.executor is not None

    @property
    def confirmed(self) -> bool:
        """Nothing moves the robot any more: navigation has no goal left (or there is no
        navigation at all, a robot driven by cmd_vel alone, and zero velocity is all),
        and the executor latched (or there is none)."""
        navigation, executor = self.navigation, self.executor
        if navigation is None or executor is None:
            return False
        return (navigation.confirmed or not navigation.answered) and executor.safe

    @property
    def detail(self) -> str:
        """In one line: zero velocity, navigation, the executor."""
        navigation = "navigation has not answered the cancel yet"
        if self.navigation is not None:
            navigation = self.navigation.detail
        executor = "the executor has not answered yet"
        if self.executor is not None:
            executor = self.executor.detail
        return f"{self.sent}; {navigation}; {executor}"


@dataclass(frozen=True)
class StopProcedure:
    """One emergency stop of one robot, under way from `begin` on: zero velocity sent,
    the executor's latch and the cancel of every navigation goal asked together, and their
    answers gathered (`outcome`)."""

    sent: str
    """Where zero velocity went."""
    latching: asyncio.Future[LatchAnswer]
    cancelling: asyncio.Future[Cancelled]

    @classmethod
    def begin(cls, robot: RobotStop, executor: ExecutorLatch) -> StopProcedure:
        """Stop `robot` now: zero velocity goes out at once, before anything is asked of
        anyone, whatever the executor is doing; the latch and the cancel go out as soon as
        the caller yields to the loop. Whoever begins it keeps it (or a task awaiting its
        `outcome`) until it has settled: the loop keeps only weak references to them."""
        sent = robot.zero_velocity()
        latching = asyncio.ensure_future(executor.latch())
        return cls(sent, latching, asyncio.ensure_future(robot.cancel_goals()))

    async def outcome(self, wait: float | None = None) -> StopOutcome:
        """What had answered after at most `wait` seconds; with no `wait`, once all has."""
        asked: list[asyncio.Future[Any]] = [self.latching, self.cancelling]
        await asyncio.wait(asked, timeout=wait)
        return StopOutcome(self.sent, _answer(self.cancelling), _answer(self.latching))


def _answer(asked: asyncio.Future[T]) -> T | None:
    return asked.result() if asked.done() else None


def _names(info: ExecutorInfo) -> RobotNames:
    try:
        return RobotNames(info.namespace, cmd_vel_name=info.cmd_vel, navigate_name=info.navigate)
    except ValueError as exc:
        _LOGGER.warning("unusable executor info (%s); stopping on default names", exc)
        return RobotNames()


def _transport(info: ExecutorInfo, names: RobotNames, bus: Bus, node: str) -> RobotTransport:
    """The transport a stop of the robot `info` announces uses (one per process and robot:
    `open_transport` keeps it): its own, or, for a graph this process cannot reach (DDS),
    the one its STOP relay serves."""
    kind = _stop_kind(info)
    return open_transport(bus, kind, node, names.namespace, info.domain_id, info.distro)


def _stop_kind(info: ExecutorInfo) -> TransportKind:
    return transports()[info.transport].stop_through or info.transport


def _unannounced(bus: Bus, node: str) -> list[RobotTransport]:
    """Every transport on Zenoh in the registry's order, in domain 0 without a namespace,
    its distribution learnt from the robot's announcements: where a supervisor that never
    heard of an executor looks for its robot (a transport that learns nothing from them,
    the bridge, opens without declaring anything and finds no cmd_vel type; a robot on
    DDS is reached through its STOP relay, on the bridge's layout)."""
    kinds = [kind for kind, cls in transports().items() if cls.stop_through is None]
    return [open_transport(bus, kind, node) for kind in kinds]
