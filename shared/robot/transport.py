"""The robot-transport seam: how voicectl reaches a ROS 2 graph over Zenoh.

Two layouts exist: zenoh-bridge-ros2dds routing a DDS graph (`bridge.py`), and ROS 2's own
Zenoh middleware, rmw_zenoh, where every node is a Zenoh participant (`rmw_zenoh.py`). Both
carry the same CDR payloads; they differ in keys, in what travels beside a payload, and in
how the graph announces itself. Everything above this seam (the executor's robot, the
stop, the simulator, `voicectl health`) names topics and services by their ROS names and
types and never builds a key.

Names are full ROS names without the leading '/' ('bot1/cmd_vel',
'navigate_to_pose/_action/send_goal', from `RobotNames`); types are ROS type names
('geometry_msgs/msg/Twist'; a service's own type, 'action_msgs/srv/CancelGoal').

Besides what a transport does once open, its class says how it is opened (`open`), how a
robot's graph announces itself in its layout (`announcements`, from which
`detect_transport` knows the layout) and what a stop may build ahead of time
(`prepare`): what `open_transport`, `detect_transport` and the stop ask of every
transport of the registry, `TRANSPORTS` in `__init__.py`, without naming one.
"""

from __future__ import annotations

import abc
import enum
from collections.abc import Awaitable, Callable, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar, Self, TypeVar

from ..errors import UnsafeCommand
from ..kinds import RosDistro, TransportKind
from .keys import ACTION_MEMBERS, action_member
from .velocity import stilled, unsafe_velocity

if TYPE_CHECKING:  # the bus imports the messages, which import this package's kinds
    from ..bus import Bus

T = TypeVar("T")
Decode = Callable[[bytes], T]
"""One sample's bytes to a message; raises on bytes it cannot read (the sample is dropped)."""
Handle = Callable[[T], None]
Unsubscribe = Callable[[], None]


class Role(enum.StrEnum):
    """What a discovered interface does in the robot's graph."""

    PUBLISHER = "publisher"
    SUBSCRIBER = "subscriber"
    SERVICE_SERVER = "service server"
    SERVICE_CLIENT = "service client"
    ACTION_SERVER = "action server"
    ACTION_CLIENT = "action client"


@dataclass(frozen=True)
class Interface:
    """A topic, service or action of the robot's graph, with the type it uses."""

    role: Role
    name: str
    """Full ROS name without the leading '/' ('bot1/cmd_vel'; an action's own name)."""
    ros_type: str
    """'geometry_msgs/msg/TwistStamped', 'nav2_msgs/action/NavigateToPose'."""
    type_hash: str = ""
    """As announced ('RIHS01_...', 'TypeHashNotSupported'); '' when the layout has none."""


@dataclass(frozen=True)
class Announcements:
    """How a robot's graph announces its interfaces in one layout: by liveliness tokens."""

    tokens: str
    """The key expression of every liveliness token of the layout (in one ROS domain)."""
    name_of: Callable[[str], str | None]
    """The ROS name of the robot's interface a token's key announces; None for a key that
    announces none as far as the layout tells (rmw_zenoh: a node's, this process's own)."""


class RobotTransport(abc.ABC):
    """One process's way onto the robot's graph. Calls that send may come from any thread
    (a stop from Zenoh's thread or a watchdog): they never wait for the event loop."""

    kind: ClassVar[TransportKind]
    stop_through: ClassVar[TransportKind | None] = None
    """The transport through which a process that has Zenoh alone (the supervisor, the
    panel, `voicectl stop`) stops a robot of this kind, where it cannot reach the robot's
    graph itself (DDS: through the STOP relay's layout); None: through this one."""

    @classmethod
    @abc.abstractmethod
    def open(
        cls, bus: Bus, node: str, namespace: str, domain_id: int, distro: RosDistro | None
    ) -> Self:
        """This transport on `bus`, this process appearing as ROS node `node` in the
        robot's `namespace` and ROS domain where the layout has nodes and domains, speaking
        `distro` (None: learn it) where the layout depends on it (`open_transport`)."""

    @classmethod
    @abc.abstractmethod
    def announcements(cls, domain_id: int, own: str) -> Announcements | None:
        """How a robot's graph in ROS domain `domain_id` announces itself in this layout,
        to a process whose Zenoh session is `own` (its id) (`detect_transport`); None for
        a graph that announces nothing on Zenoh (DDS)."""

    @classmethod
    def unavailable(cls) -> str | None:
        """Why this process cannot open this transport (rclpy cannot be imported), in one
        line; None when it can. Told before the bus opens; and `detect_transport` picks a
        graph that announces nothing on Zenoh only where it is available."""
        return None

    @classmethod
    @abc.abstractmethod
    def prepare(cls, distro: RosDistro, ros_types: Iterable[str]) -> None:
        """Build what sending in `ros_types` to a robot of `distro` will first need, so
        that a STOP does not pay for it (rmw_zenoh: their type hashes, which its keys
        carry); blocks, so runs off the event loop. Nothing where a key needs nothing
        built (the bridge)."""

    def publish(self, name: str, ros_type: str, payload: bytes, urgent: bool = False) -> None:
        """Publish one CDR message on a topic. An `urgent` one (zero velocity) waits for
        room instead of being dropped, and goes first. A velocity command with an axis
        that is not a finite number is never sent, whoever asks: the same command with
        every axis zero goes instead, at once, and UnsafeCommand says why."""
        unsafe = unsafe_velocity(ros_type, payload)
        if unsafe is None:
            self.send(name, ros_type, payload, urgent)
            return
        self.send(name, ros_type, stilled(ros_type, payload), urgent=True)
        raise UnsafeCommand(f"refused {unsafe} on '{name}'; sent zero velocity instead")

    @abc.abstractmethod
    def send(self, name: str, ros_type: str, payload: bytes, urgent: bool = False) -> None:
        """Put one CDR message on a topic as it is (`publish` checks it first)."""

    @abc.abstractmethod
    def subscribe(
        self, name: str, ros_type: str, decode: Decode[T], handler: Handle[T], latched: bool = False
    ) -> Unsubscribe:
        """Call `handler(message)` on the loop for every sample on a topic that decodes;
        returns the function that ends the subscription. A `latched` topic (ROS's
        transient local: a map) also gives what its publishers keep for late subscribers."""

    @abc.abstractmethod
    async def call(
        self, name: str, service_type: str, request: bytes, timeout: float, urgent: bool = False
    ) -> bytes:
        """Call a service with a CDR request; its CDR reply. BusError when nothing answers."""

    @abc.abstractmethod
    def call_and_forget(self, name: str, service_type: str, request: bytes, timeout: float) -> None:
        """Call a service urgently, from any thread, without waiting for its answer."""

    @abc.abstractmethod
    def serve(
        self, name: str, service_type: str, handler: Callable[[bytes], Awaitable[bytes | None]]
    ) -> None:
        """Answer a service's CDR requests (a simulated robot's); a handler returning None
        leaves the request unanswered."""

    @abc.abstractmethod
    def offer(self, interface: Interface) -> None:
        """Announce that this process offers `interface` as the robot's graph would show
        it, so that what discovers the robot finds it (a simulated robot's)."""

    @abc.abstractmethod
    def discover(self, handler: Callable[[Interface, bool], None]) -> None:
        """Call `handler(interface, present)` on the loop as the robot's interfaces appear
        and go, those that were there before included; this process's own excepted."""

    @abc.abstractmethod
    def follow(self) -> None:
        """Learn from the robot's announcements from now on, in the background, so that
        what this process sends goes where the robot listens (`discover` does it too;
        once is enough). Nothing to learn where a key does not depend on them (the
        bridge). A simulated robot does not follow: a robot's keys are its own."""

    @abc.abstractmethod
    def expect(self, interface: Interface) -> None:
        """Take `interface` as the robot's, as another process saw it announced (the
        executor, whose `ExecutorInfo` passes it on): what this process sends to it goes
        where the robot listens even before this transport has seen the robot's own
        announcement, which wins once seen. Nothing to do where a key does not depend on
        what the robot announces (the bridge)."""

    def announced_distro(self) -> RosDistro | None:
        """The robot's distribution as its announcements tell it (rmw_zenoh's type hashes:
        Nav2's feedback tells Rolling from Jazzy, where a get_result reply cannot), whatever
        was configured; None where they tell nothing (the bridge, DDS)."""
        return None

    def lacks(self, ros_type: str) -> str | None:
        """Why this process cannot send or read messages of `ros_type` on this transport
        at all, in one line (DDS: its interface package is not installed here); None when
        it can (the layouts on Zenoh carry CDR that voicectl writes itself)."""
        return None

    @abc.abstractmethod
    def subscriber_types(self, name: str) -> list[str]:
        """The ROS types the robot's subscribers of topic `name` have announced, as far as
        this transport has seen, where a layout keeps a topic's types apart on the wire
        (rmw_zenoh: the type is in the key), so that a message in each reaches only those
        who take it; [] elsewhere (the bridge), and before anything was seen."""


@dataclass(frozen=True)
class ActionMember:
    """One of the services and topics ROS 2 makes of an action."""

    name: str
    """'navigate_to_pose/_action/send_goal'."""
    ros_type: str
    service: bool


def action_members(action: str, action_type: str) -> list[ActionMember]:
    """The three services and two topics of action `action` of type `action_type`
    ('nav2_msgs/action/NavigateToPose'), with their types, as rcl_action makes them."""
    types = {
        "send_goal": f"{action_type}_SendGoal",
        "cancel_goal": "action_msgs/srv/CancelGoal",
        "get_result": f"{action_type}_GetResult",
        "feedback": f"{action_type}_FeedbackMessage",
        "status": "action_msgs/msg/GoalStatusArray",
    }
    return [
        ActionMember(action_member(action, member), types[member], member in SERVICE_MEMBERS)
        for member in ACTION_MEMBERS
    ]


SERVICE_MEMBERS = frozenset({"send_goal", "cancel_goal", "get_result"})


def action_of(name: str, ros_type: str) -> tuple[str, str] | None:
    """The action whose send_goal service `name` of type `ros_type` is, as (name, type);
    None for any other service."""
    suffix = action_member("", "send_goal")
    if name.endswith(suffix) and ros_type.endswith("_SendGoal"):
        return name.removesuffix(suffix), ros_type.removesuffix("_SendGoal")
    return None
