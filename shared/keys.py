"""Every key expression of the voice bus is built here and nowhere else; so are the ROS
names of a robot's topics and action (`RobotNames`), which the services, the commands and
the robot transports share.

voicectl's own traffic lives under ``voice/<robot>/...`` so that one router can carry
several robots and ``voice/**`` shows the whole order stream in any Zenoh tool. ROS 2
traffic follows the robot's middleware: zenoh-bridge-ros2dds' ``<namespace>/<topic>``
without the leading slash, or rmw_zenoh's ``<domain>/<namespace>/<topic>/<type>/<hash>``
(shared/robot/keys.py builds those keys and each layout's tokens; shared/robot/ chooses).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

ROOT = "voice"
_CHUNK = re.compile(r"^[A-Za-z0-9_-]+$")


ANY = "*"


MAX_CHUNK = 64
"""The longest robot name or other key chunk: a name is for people, and every one a
service meets costs it memory."""


def robot_of(key: str) -> str:
    """The robot name inside any ``voice/<robot>/...`` key."""
    return key.split("/")[1]


def last_chunk(key: str) -> str:
    """The last chunk of a key: the session of ``voice/<robot>/stt/audio/<session>``."""
    return key.rsplit("/", 1)[-1]


def check_chunk(name: str, what: str) -> str:
    """Return `name` if it is usable as one key chunk, else raise ValueError naming `what`."""
    if len(name) > MAX_CHUNK:
        raise ValueError(f"{what} '{name[:20]}...' is longer than {MAX_CHUNK} characters")
    if not _CHUNK.match(name):
        raise ValueError(f"{what} {name!r} must be letters, digits, '_' or '-'")
    return name


@dataclass(frozen=True)
class RobotKeys:
    """The keys of one robot's voice pipeline."""

    robot: str
    """A robot name, or `ANY` for key expressions that match every robot."""

    def __post_init__(self) -> None:
        if self.robot != ANY:
            check_chunk(self.robot, "robot name")

    @classmethod
    def any_robot(cls) -> RobotKeys:
        return cls(ANY)

    @property
    def prefix(self) -> str:
        return f"{ROOT}/{self.robot}"

    @property
    def transcript(self) -> str:
        """Final transcripts from the speech recogniser."""
        return f"{self.prefix}/stt/transcript"

    def stt_audio(self, session: str) -> str:
        """One recognition session's audio: start, chunks, stop."""
        return f"{self.prefix}/stt/audio/{check_chunk(session, 'session id')}"

    def stt_session(self, session: str) -> str:
        """What the recogniser says about one audio session (it ended, it was refused)."""
        return f"{self.prefix}/stt/session/{check_chunk(session, 'session id')}"

    @property
    def stt_audio_any(self) -> str:
        return f"{self.prefix}/stt/audio/*"

    @property
    def stt_check(self) -> str:
        """Whether some audio says a phrase (a listener's wake phrase), asked of the
        recogniser."""
        return f"{self.prefix}/stt/check"

    @property
    def partial(self) -> str:
        """Growing partial transcripts while someone speaks."""
        return f"{self.prefix}/stt/partial"

    @property
    def stt_status(self) -> str:
        """The recogniser's status: engine, grammar in use, what it cannot hear."""
        return f"{self.prefix}/stt/status"

    @property
    def proposal(self) -> str:
        """What the converter made of a transcript, for the panel to confirm."""
        return f"{self.prefix}/converter/proposal"

    @property
    def supervisor(self) -> str:
        """The supervisor's request/reply queryable (submit, cancel, state...)."""
        return f"{self.prefix}/supervisor/request"

    def supervisor_owner(self, tag: str) -> str:
        """Liveliness token of the supervisor serving this robot (`tag`: its Zenoh id), so
        that a second one on the bus knows to stand down."""
        return f"{self.prefix}/supervisor/owner/{tag}"

    @property
    def state(self) -> str:
        """The supervisor's state snapshot, published on every change."""
        return f"{self.prefix}/supervisor/state"

    @property
    def executor_execute(self) -> str:
        """The executor's queryable that accepts or rejects one order."""
        return f"{self.prefix}/executor/execute"

    @property
    def executor_control(self) -> str:
        """The executor's queryable for cancel and halt, outside any queue."""
        return f"{self.prefix}/executor/control"

    @property
    def executor_latch(self) -> str:
        """The emergency stop's latch, answered off the executor's event loop: whoever
        stops the robot may latch it."""
        return f"{self.prefix}/executor/latch"

    @property
    def executor_release(self) -> str:
        """Where the latch is let go: a key of its own, so that a secured bus lets the
        supervisor alone release it (a person releases through the supervisor)."""
        return f"{self.prefix}/executor/release"

    @property
    def executor_photo(self) -> str:
        """The photos the robot's orders took, served by its executor (`GetPhoto`)."""
        return f"{self.prefix}/executor/photo"

    @property
    def executor_info(self) -> str:
        """How the executor reaches the robot (namespace, distro), kept for late subscribers."""
        return f"{self.prefix}/executor/info"

    @property
    def executor_events(self) -> str:
        """Progress and results published by the executor."""
        return f"{self.prefix}/executor/events"

    @property
    def pose(self) -> str:
        """The robot's pose from odometry, published by its executor."""
        return f"{self.prefix}/robot/pose"

    @property
    def map(self) -> str:
        """The robot's own map, relayed by its executor while someone listens."""
        return f"{self.prefix}/robot/map"

    def label(self, label: str) -> str:
        """Liveliness token of one order label an executor of this robot serves."""
        return f"{self.prefix}/labels/{check_chunk(label, 'label') if label != ANY else ANY}"

    def alive(self, service: str) -> str:
        """Liveliness token of one service serving this robot."""
        return (
            f"{self.prefix}/alive/{check_chunk(service, 'service name') if service != ANY else ANY}"
        )

    @property
    def executor_says(self) -> tuple[str, ...]:
        """Every key this robot's executor publishes, serves or announces on: what a
        secured router grants that robot's executor, and no one else's."""
        return (
            f"{self.prefix}/executor/**",
            f"{self.prefix}/executor/**/@adv/**",  # its late-subscriber publishers
            f"{self.prefix}/robot/**",
            self.alive("executor"),
            self.label(ANY),
        )


@dataclass(frozen=True)
class ConverterKeys:
    """The converter serves every robot with one set of orders."""

    @property
    def parse(self) -> str:
        """Request/reply: text in, orders and errors out."""
        return f"{ROOT}/converter/parse"

    def alive(self) -> str:
        """Liveliness token of the converter (a method, as `RobotKeys.alive(service)`)."""
        return f"{ROOT}/converter/alive"

    @property
    def grammar(self) -> str:
        """The recogniser grammar: published on change, and a queryable for late starters."""
        return f"{ROOT}/converter/grammar"

    @property
    def status(self) -> str:
        """Whether the orders files loaded; published on every (re)load."""
        return f"{ROOT}/converter/status"

    @property
    def places(self) -> str:
        """The named places of the orders; published on every (re)load."""
        return f"{ROOT}/converter/places"

    @property
    def all_transcripts(self) -> str:
        return f"{ROOT}/*/stt/transcript"


ACTION_MEMBERS = ("send_goal", "cancel_goal", "get_result", "feedback", "status")
"""The services and topics ROS 2 makes of every action, under ``<action>/_action/``."""


def action_member(action: str, member: str) -> str:
    """The name of one of an action's services or topics ('navigate_to_pose/_action/status')."""
    if member not in ACTION_MEMBERS:
        raise ValueError(f"unknown action member {member!r}")
    return f"{action.strip('/')}/_action/{member}"


_ROS_TOKEN = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def check_ros_name(name: str, what: str) -> str:
    """`name` without its leading '/', if ROS 2 accepts it as a topic, action or namespace
    ('bot1', 'diff_drive_controller/cmd_vel'); else ValueError naming `what`."""
    parts = name.strip("/").split("/") if name.strip("/") else []
    for part in parts:
        if not _ROS_TOKEN.match(part) or "__" in part:
            raise ValueError(
                f"{what} {name!r}: {part!r} is not a ROS 2 name; use letters, digits and "
                "single '_', not starting with a digit ('-' and '.' are not allowed)"
            )
    return "/".join(parts)


@dataclass(frozen=True)
class RobotNames:
    """The ROS names of one robot's topics and action, under its `namespace`, fully
    qualified without the leading '/' ('bot1/cmd_vel'): what zenoh-bridge-ros2dds uses as
    keys as they are, and rmw_zenoh inside its keys.

    The names can be remapped ('diff_drive_controller/cmd_vel'): ROS name ``/a/b`` under
    namespace ``/ns`` is ``ns/a/b``.
    """

    namespace: str = ""
    cmd_vel_name: str = "cmd_vel"
    odom_name: str = "odom"
    camera_name: str = "camera/image_raw"
    navigate_name: str = "navigate_to_pose"
    """Nav2's NavigateToPose action."""
    map_name: str = "map"
    """The occupancy grid a Nav2 robot's map server publishes."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "namespace", check_ros_name(self.namespace, "ROS namespace"))
        for field in ("cmd_vel_name", "odom_name", "camera_name", "navigate_name", "map_name"):
            name = check_ros_name(getattr(self, field), field.removesuffix("_name") + " name")
            if not name:
                raise ValueError(f"{field.removesuffix('_name')} name must not be empty")
            object.__setattr__(self, field, name)

    def topic(self, name: str) -> str:
        """The full name of a topic, service or action member `name` ('/cmd_vel' or 'cmd_vel')."""
        name = name.strip("/")
        return f"{self.namespace}/{name}" if self.namespace else name

    @property
    def cmd_vel(self) -> str:
        return self.topic(self.cmd_vel_name)

    @property
    def odom(self) -> str:
        return self.topic(self.odom_name)

    @property
    def tf(self) -> str:
        return self.topic("tf")

    @property
    def camera_image(self) -> str:
        return self.topic(self.camera_name)

    @property
    def map(self) -> str:
        return self.topic(self.map_name)

    @property
    def simulator(self) -> str:
        """Liveliness token of `voicectl sim` once it serves this namespace (the real
        bridge announces itself under ``@/<zid>/@ros2_lv/...`` instead)."""
        return self.topic("voicectl_sim/alive")

    def action(self, action: str, member: str) -> str:
        """One of an action's five routes: send_goal, get_result, cancel_goal, feedback, status."""
        return self.topic(action_member(action, member))

    def navigate(self, member: str) -> str:
        """A route of the robot's NavigateToPose action."""
        return self.action(self.navigate_name, member)

    @property
    def everything(self) -> str:
        """Every key under the namespace (every key at all for a robot without one)."""
        return self.topic("**")

    @property
    def any_cmd_vel(self) -> str:
        """Any velocity topic under the namespace, remapped or not."""
        return self.topic("**/cmd_vel")

    @property
    def any_action(self) -> str:
        """Any action's send_goal, get_result or cancel_goal under the namespace."""
        return self.topic("**/_action/*")
