"""Every key expression voicectl uses is built here and nowhere else.

voicectl's own traffic lives under ``voice/<robot>/...`` so that one router can carry
several robots and ``voice/**`` shows the whole order stream in any Zenoh tool. ROS 2
traffic follows zenoh-bridge-ros2dds' layout: ``<namespace>/<topic>`` without the
leading slash.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

ROOT = "voice"
_CHUNK = re.compile(r"^[A-Za-z0-9_-]+$")


ANY = "*"


def robot_of(key: str) -> str:
    """The robot name inside any ``voice/<robot>/...`` key."""
    return key.split("/")[1]


def last_chunk(key: str) -> str:
    """The last chunk of a key: the session of ``voice/<robot>/stt/audio/<session>``."""
    return key.rsplit("/", 1)[-1]


def check_chunk(name: str, what: str) -> str:
    """Return `name` if it is usable as one key chunk, else raise ValueError naming `what`."""
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

    @property
    def stt_audio_any(self) -> str:
        return f"{self.prefix}/stt/audio/*"

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

    def label(self, label: str) -> str:
        """Liveliness token of one order label an executor of this robot serves."""
        return f"{self.prefix}/labels/{check_chunk(label, 'label')}"

    def alive(self, service: str) -> str:
        """Liveliness token of one service serving this robot."""
        return (
            f"{self.prefix}/alive/{check_chunk(service, 'service name') if service != ANY else ANY}"
        )


@dataclass(frozen=True)
class ConverterKeys:
    """The converter serves every robot with one set of orders."""

    @property
    def parse(self) -> str:
        """Request/reply: text in, orders and errors out."""
        return f"{ROOT}/converter/parse"

    @property
    def alive(self) -> str:
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
    def all_transcripts(self) -> str:
        return f"{ROOT}/*/stt/transcript"


@dataclass(frozen=True)
class BridgeKeys:
    """Keys of a ROS 2 graph as zenoh-bridge-ros2dds exposes it under `namespace`."""

    namespace: str = ""

    def __post_init__(self) -> None:
        parts = [p for p in self.namespace.strip("/").split("/") if p]
        for part in parts:
            check_chunk(part, "ROS namespace part")
        object.__setattr__(self, "namespace", "/".join(parts))

    def topic(self, name: str) -> str:
        """The key of a ROS topic, service or action member `name` ('/cmd_vel' or 'cmd_vel')."""
        name = name.strip("/")
        return f"{self.namespace}/{name}" if self.namespace else name

    @property
    def cmd_vel(self) -> str:
        return self.topic("cmd_vel")

    @property
    def odom(self) -> str:
        return self.topic("odom")

    @property
    def tf(self) -> str:
        return self.topic("tf")

    @property
    def camera_image(self) -> str:
        return self.topic("camera/image_raw")

    @property
    def simulator(self) -> str:
        """Liveliness token of `voicectl sim` once it serves this namespace (the real
        bridge announces itself under ``@/<zid>/@ros2_lv/...`` instead)."""
        return self.topic("voicectl_sim/alive")

    def action(self, action: str, member: str) -> str:
        """One of an action's five routes: send_goal, get_result, cancel_goal, feedback, status."""
        if member not in {"send_goal", "get_result", "cancel_goal", "feedback", "status"}:
            raise ValueError(f"unknown action member {member!r}")
        return self.topic(f"{action.strip('/')}/_action/{member}")
