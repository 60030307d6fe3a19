"""What the panel shows, from the bus: every robot's events fanned out to its listeners.

One subscription per kind of message covers every robot (`voice/*/...`); each browser
listens to the robot it selected. New listeners get the last state, recogniser status,
pose, parts and the orders' places at once, so a reloaded page is whole without asking.
A robot's own map is subscribed to only while a browser listens to that robot: its
executor relays the map only while someone does.

Robot names come from anyone on the bus, so what is kept per robot is bounded as the
supervisor bounds the robots it serves (`--max-robots`): past the cap, the robot heard
from longest ago that no browser shows and no supervisor serves is forgotten to make
room, and otherwise the newcomer is not followed. The default robot is always followed.

The hub is a service (shared/process.py): `start()` subscribes, `run()` marks robots
offline whose pose went stale, `stop()` ends every subscription.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import logging
from collections.abc import Callable, Iterator

import msgspec

from voicectl.shared.bus import Bus, json_decoder
from voicectl.shared.keys import (
    ANY,
    MAX_ROBOTS,
    ConverterKeys,
    RobotKeys,
    last_chunk,
    robot_of,
)
from voicectl.shared.messages import (
    PartialTranscript,
    Places,
    Proposal,
    RobotMap,
    RobotPose,
    StateUpdate,
    SttStatus,
    Transcript,
)
from voicectl.shared.process import Service
from voicectl.shared.throttle import Throttled

_LOGGER = logging.getLogger(__name__)

PARTS = ("converter", "stt", "supervisor", "executor", "robot", "navigation")
"""What a panel shows as up or down; navigation from the token its executor holds while
the robot's navigation is there (services/executor/runner.py)."""
POSE_FRESH = 3.0
"""Seconds after its last pose that a robot still counts as online."""
QUEUE_LIMIT = 200
"""Frames a stalled browser may fall behind before it loses the oldest."""
END = b""
"""The last item of a listener's queue: the stream ends (the server is stopping)."""


class Parts(msgspec.Struct, tag="parts", tag_field="type"):
    """Which parts serving a robot are alive (from their liveliness tokens)."""

    robot: str
    parts: dict[str, bool]


class Robots(msgspec.Struct, tag="robots", tag_field="type"):
    """Every robot a service has announced itself for."""

    robots: list[str]


class Labels(msgspec.Struct, tag="labels", tag_field="type"):
    """The labels the robot's executors serve (from their tokens): an order with any
    other label would be refused, which a panel says before it is sent."""

    robot: str
    labels: list[str]


PanelEvent = (
    StateUpdate | Proposal | PartialTranscript | Transcript | SttStatus | RobotPose | RobotMap
)


class Hub(Service):
    """Bus subscriptions for every robot, and the browsers listening to each."""

    def __init__(self, bus: Bus, default_robot: str, max_robots: int = MAX_ROBOTS) -> None:
        self._bus = bus
        self._default = default_robot
        self._max_robots = max_robots
        self._followed: collections.OrderedDict[str, None] = collections.OrderedDict()
        """Robots besides the default one whose frames, parts and labels are kept, the one
        heard from longest ago first; at most `max_robots` of them, and those browsers
        show."""
        self._listeners: dict[str, set[asyncio.Queue[bytes]]] = {}
        self._last: dict[str, dict[str, bytes]] = {}
        """Per robot, the last frame of each kind a new listener needs."""
        self._alive: dict[str, set[str]] = {}
        """Per robot, the services whose token is up (robots with none are dropped)."""
        self._listed: set[str] = set()
        """Robots a supervisor's token says it serves."""
        self._noise = Throttled(_LOGGER)
        self._converter = False
        self._posed: dict[str, float] = {}
        self._labels: dict[str, set[str]] = {}
        """Per robot, the labels its executors announce."""
        self._places = b""
        """The last places of the orders, as a frame."""
        self._maps: dict[str, Callable[[], None]] = {}
        """Per robot listened to, the end of its map subscription."""
        self._encoder = msgspec.json.Encoder()
        self._ends: list[Callable[[], None]] = []
        """What `stop()` ends: the subscriptions and watches `start()` made."""
        self._ending = False

    async def start(self) -> None:
        every = RobotKeys(ANY)
        subscribe, watch = self._bus.subscribe, self._bus.watch
        for key, kind in (
            (every.state, StateUpdate),
            (every.proposal, Proposal),
            (every.partial, PartialTranscript),
            (every.transcript, Transcript),
            (every.stt_status, SttStatus),
            (every.pose, RobotPose),
        ):
            self._ends.append(
                subscribe(key, json_decoder(kind), self._on_event, history=kind is SttStatus)
            )
        self._ends += [
            subscribe(ConverterKeys().places, json_decoder(Places), self._on_places, history=True),
            watch(ConverterKeys().alive(), self._on_converter),
            watch(every.alive(ANY), self._on_alive),
            watch(every.label(ANY), self._on_label),
        ]

    async def stop(self) -> None:
        for end in [*self._ends, *self._maps.values()]:
            end()
        self._ends.clear()
        self._maps.clear()

    async def run(self) -> None:
        """Mark robots offline whose pose went stale; runs until cancelled."""
        while True:
            await asyncio.sleep(1.0)
            now = asyncio.get_running_loop().time()
            for robot, at in list(self._posed.items()):
                if now - at > POSE_FRESH:
                    del self._posed[robot]
                    self._send_parts(robot)

    def end_streams(self) -> None:
        """End every listener's stream, and any opened from now on: the server is stopping,
        and waits for its responses to finish, which an event stream never does."""
        self._ending = True
        for listeners in self._listeners.values():
            for queue in listeners:
                queue.put_nowait(END)

    @property
    def robots(self) -> list[str]:
        """The default robot and every robot a supervisor serves (its token says so): a
        robot only someone's token names is not listed, since anyone can make one up."""
        return sorted({self._default, *self._listed})

    def parts(self, robot: str) -> Parts:
        alive = self._alive.get(robot, set())
        states = {part: part in alive for part in PARTS}
        states["converter"] = self._converter
        states["robot"] = robot in self._posed
        return Parts(robot=robot, parts=states)

    def knows_state(self, robot: str) -> bool:
        return self.knows(robot, "StateUpdate")

    def knows(self, robot: str, kind: str) -> bool:
        """Whether a last frame of `kind` ('StateUpdate', 'SttStatus', 'pose', 'map') is
        kept for `robot`, to prime a page opened now."""
        return kind in self._last.get(robot, {})

    def remember(self, robot: str, state: StateUpdate) -> None:
        """A state asked for (a panel opened before any change was published)."""
        frame = self._frame(state)
        if self._follow(robot):
            self._last.setdefault(robot, {})["StateUpdate"] = frame
        self._send(robot, frame)

    @property
    def held(self) -> set[str]:
        """The robots something is kept for (frames, parts, labels, a fresh pose)."""
        return {*self._last, *self._labels, *self._alive, *self._posed, *self._listed}

    @contextlib.contextmanager
    def listen(self, robot: str) -> Iterator[asyncio.Queue[bytes]]:
        """A queue of server-sent-event frames for `robot`, primed with what is known."""
        queue: asyncio.Queue[bytes] = asyncio.Queue()
        if self._ending:
            queue.put_nowait(END)
        for frame in self._last.get(robot, {}).values():
            queue.put_nowait(frame)
        queue.put_nowait(self._frame(self.parts(robot)))
        queue.put_nowait(self._frame(Robots(robots=self.robots)))
        queue.put_nowait(self._frame(self.labels(robot)))
        if self._places:
            queue.put_nowait(self._places)
        listeners = self._listeners.setdefault(robot, set())
        listeners.add(queue)
        self._follow(robot)  # one a browser shows is followed, past the cap if need be
        if robot not in self._maps:
            self._maps[robot] = self._bus.subscribe(
                RobotKeys(robot).map, json_decoder(RobotMap), self._on_event, history=True
            )
        try:
            yield queue
        finally:
            listeners.discard(queue)
            if not listeners:
                del self._listeners[robot]
                if robot in self._maps:
                    self._maps.pop(robot)()

    def _frame(self, message: object) -> bytes:
        return b"data: " + self._encoder.encode(message) + b"\n\n"

    def _send(self, robot: str, frame: bytes) -> None:
        if self._ending:  # nothing may come after END, nor push it out of a full queue
            return
        for queue in self._listeners.get(robot, ()):
            if queue.qsize() >= QUEUE_LIMIT:  # a stalled browser loses old frames
                queue.get_nowait()
            queue.put_nowait(frame)

    def _on_event(self, key: str, message: PanelEvent) -> None:
        robot = robot_of(key)
        kept = isinstance(message, StateUpdate | SttStatus | RobotMap | RobotPose)
        if kept and not self._follow(robot):
            return  # nobody shows it: it has no listener to send to either
        frame = self._frame(message)
        match message:
            case StateUpdate() | SttStatus():
                self._last.setdefault(robot, {})[type(message).__name__] = frame
            case RobotMap():
                self._last.setdefault(robot, {})["map"] = frame
            case RobotPose():
                self._last.setdefault(robot, {})["pose"] = frame
                fresh = robot not in self._posed
                self._posed[robot] = asyncio.get_running_loop().time()
                if fresh:
                    self._send_parts(robot)
        self._send(robot, frame)

    def _on_places(self, _key: str, places: Places) -> None:
        self._places = self._frame(places)
        for listeners in self._listeners.values():
            for queue in listeners:
                queue.put_nowait(self._places)

    def labels(self, robot: str) -> Labels:
        return Labels(robot=robot, labels=sorted(self._labels.get(robot, ())))

    def _on_label(self, key: str, alive: bool) -> None:
        robot, label = robot_of(key), last_chunk(key)
        if alive and self._follow(robot):
            self._labels.setdefault(robot, set()).add(label)
        elif robot in self._labels:
            self._labels[robot].discard(label)
            if not self._labels[robot]:
                del self._labels[robot]
        else:
            return
        self._send(robot, self._frame(self.labels(robot)))

    def _on_converter(self, _key: str, alive: bool) -> None:
        self._converter = alive
        for robot in self._listeners:
            self._send_parts(robot)

    def _on_alive(self, key: str, alive: bool) -> None:
        robot, service = robot_of(key), last_chunk(key)
        services = self._alive.get(robot)
        if services is None:
            if not alive or not self._follow(robot, serving=service == "supervisor"):
                return
            services = self._alive[robot] = set()
        if alive:
            services.add(service)
        else:
            services.discard(service)
        if not services:
            del self._alive[robot]
        self._send_parts(robot)
        if ("supervisor" in services) != (robot in self._listed):
            self._listed ^= {robot}
            robots = self._frame(Robots(robots=self.robots))
            for listeners in self._listeners.values():  # every open panel learns of it
                for queue in listeners:
                    queue.put_nowait(robots)

    def _follow(self, robot: str, serving: bool = False) -> bool:
        """Whether to keep what is heard of `robot` (`serving`: its supervisor announces
        itself). The default robot always; one already followed, or one a browser shows;
        a newcomer while fewer than `max_robots` are followed, or once the one heard from
        longest ago that nobody shows and no supervisor serves is forgotten for it."""
        if robot == self._default:
            return True
        if robot in self._followed:
            self._followed.move_to_end(robot)
            return True
        full = len(self._followed) >= self._max_robots
        if full and not self._make_room() and robot not in self._listeners:
            self._noise.warning(
                "follow",
                "robot '%s'%s not followed: %d robots are (--max-robots), each shown or "
                "served; start the panel with --robot %s to show it whatever comes",
                robot,
                " (its supervisor announced itself)" if serving else "",
                len(self._followed),
                robot,
            )
            return False
        self._followed[robot] = None
        return True

    def _make_room(self) -> bool:
        """Forget the robot heard from longest ago that no browser shows and no supervisor
        serves; False if there is none."""
        for robot in self._followed:
            if robot not in self._listeners and robot not in self._listed:
                break
        else:
            return False
        del self._followed[robot]
        for table in (self._last, self._labels, self._alive, self._posed):
            table.pop(robot, None)
        return True

    def _send_parts(self, robot: str) -> None:
        self._send(robot, self._frame(self.parts(robot)))
