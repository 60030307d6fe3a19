"""Every key expression of the voice bus is built here and nowhere else.

voicectl's own traffic lives under ``voice/<robot>/...`` so that one router can carry
several robots and ``voice/**`` shows the whole order stream in any Zenoh tool. The robot's
ROS 2 traffic follows its middleware: its names (`RobotNames`), and the keys and tokens of
each Zenoh layout, are built in shared/robot/keys.py.
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
MAX_ROBOTS = 256
"""Robots a service follows at most besides those it was told to (`--max-robots` of the
supervisor and the panel): every name costs memory and bus declarations, and anyone on
the bus can make names up."""


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

    def grammar(self, language: str) -> str:
        """The recogniser grammar of one language's orders: published on change, kept for
        late subscribers."""
        return f"{ROOT}/converter/grammar/{check_chunk(language, 'language')}"

    @property
    def grammars(self) -> str:
        """Every language's grammar."""
        return f"{ROOT}/converter/grammar/*"

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
