# msgspec subclasses inherit frozen=True; mypy's dataclass_transform does not know that.
# mypy: disable-error-code="misc"
"""The messages voicectl services exchange, as msgspec Structs encoded as JSON.

Each key expression carries one tagged union; a receiver builds one typed decoder for it
once and dispatches on the decoded type with ``match``. New fields always get defaults so
that older and newer services can talk.
"""

from __future__ import annotations

import math
from enum import StrEnum
from typing import Annotated, Literal

import msgspec

from .kinds import CmdVelType, RosDistro, TransportKind

ParamValue = str | int | float | bool
LOGGED_TEXT = 120
"""Characters of a person's text that a log line shows."""


def excerpt(text: str) -> str:
    """A person's text as a log line quotes it: a 5 MB transcript must not become one line."""
    if len(text) <= LOGGED_TEXT:
        return repr(text)
    return f"{text[:LOGGED_TEXT]!r}... ({len(text)} characters)"


class Message(msgspec.Struct, tag_field="type", tag=str.lower, kw_only=True, frozen=True):
    """Base of every message on the bus; the tag names its type in the JSON."""


class Data(msgspec.Struct, kw_only=True, frozen=True):
    """Base of values nested inside messages (no tag)."""


# --- orders -----------------------------------------------------------------------------


class TargetPose(Data):
    """A planar goal pose; `frame` is a ROS frame id such as 'map' or 'base_link'."""

    frame: str
    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0
    """Heading in radians, counter-clockwise."""

    def __post_init__(self) -> None:
        for axis in ("x", "y", "yaw"):
            value = getattr(self, axis)
            if not math.isfinite(value):
                raise ValueError(f"a target pose's {axis} must be a finite number, not {value}")


class Order(Data, kw_only=True):
    """One thing for the robot to do, as the converter made it from words."""

    order: str
    """Name of the order in the orders file ('rotation')."""
    case: str | None = None
    """Name of the matched case ('left'), or None for an order without cases."""
    label: str
    """Which executor runs it ('mbgoal')."""
    description: str
    """Human wording of what will happen ('turn left')."""
    params: dict[str, ParamValue] = msgspec.field(default_factory=dict)
    """Every key of the order and its case that is not a known one."""
    target_pose: TargetPose | None = None
    confirm: bool = False
    """The orders file asks for a spoken yes before it runs, when no one presses Send
    (`voicectl listen`); the panel's Send is itself the confirmation."""

    def __post_init__(self) -> None:
        for name, value in self.params.items():
            if isinstance(value, float) and not math.isfinite(value):
                raise ValueError(f"parameter '{name}' must be a finite number, not {value}")


class ParseProblem(Data, omit_defaults=True):
    """A piece of text that did not become an order, and why."""

    text: str
    reason: str
    candidates: list[str] = msgspec.field(default_factory=list)
    """Orders the text could have meant, for the user to pick from; never dispatched alone."""


class ParseResult(Data):
    """What the converter made of a text: orders in spoken order, plus errors."""

    orders: list[Order] = msgspec.field(default_factory=list)
    errors: list[ParseProblem] = msgspec.field(default_factory=list)


# --- speech ---------------------------------------------------------------------------------

SAMPLE_RATE: Literal[16000] = 16000
"""Audio on the bus is 16 kHz mono signed 16-bit little-endian PCM..."""
FRAME_BYTES = 640
"""...in frames of 20 ms (320 samples); a chunk carries whole frames."""
MAX_CHUNK_FRAMES = 50
"""At most one second of audio per chunk."""


class AudioStart(Message):
    """Open a recognition session; its key names it (``voice/<robot>/stt/audio/<session>``).

    A session is one person speaking from one device: it may hold several utterances, each
    ended by a pause, and it ends with `AudioStop` (or when it goes quiet for too long).
    """

    sample_rate: Literal[16000] = SAMPLE_RATE
    channels: Literal[1] = 1
    language: Annotated[str, msgspec.Meta(pattern="^([a-z]{2,3})?$")] = ""
    """The language the person speaks (ISO 639-1, "es"); empty: the recogniser's own."""


class AudioChunk(Message):
    """Whole 20 ms frames of PCM, in order; `seq` counts chunks from 0 to spot gaps."""

    seq: Annotated[int, msgspec.Meta(ge=0)]
    pcm: Annotated[bytes, msgspec.Meta(min_length=FRAME_BYTES)]

    def __post_init__(self) -> None:
        frames, rest = divmod(len(self.pcm), FRAME_BYTES)
        if rest or frames > MAX_CHUNK_FRAMES:
            raise ValueError(
                f"pcm must be whole {FRAME_BYTES}-byte frames (20 ms), at most "
                f"{MAX_CHUNK_FRAMES} of them; got {len(self.pcm)} bytes"
            )


class AudioStop(Message):
    """End the session: the utterance in progress, if any, is finished now."""


AudioMessage = AudioStart | AudioChunk | AudioStop


class PartialTranscript(Message):
    """What the recogniser hears so far in the current utterance; superseded by the next."""

    session: str
    utterance: int
    """Counts the session's utterances from 0."""
    text: str


class Doubt(Data):
    """A value in a transcript that the recogniser is not sure of: asked, never guessed."""

    position: int
    """Index of its first word in the transcript's words."""
    words: str
    """What the transcript says there ("ten")."""
    alternatives: list[str] = msgspec.field(default_factory=list)
    """What it may have been instead ("two"), most likely first."""
    confidence: float = 0.0


MAX_ALTERNATIVES = 16
"""At most this many other hypotheses travel with a transcription (the recogniser sends 8)."""


class Transcription(Data):
    """A free transcript of the utterance by a neural recogniser, bound to no grammar: the
    person's words as the model heard them, for the converter to parse and to weigh
    against the grammar's result (services/converter/decide.py)."""

    engine: str
    """Which model heard it ('moonshine', 'whisper')."""
    text: str
    """As the model writes it: capitals, punctuation, digits ("Go forward 10 metres.")."""
    confidence: float = 0.0
    """0 to 1: the geometric mean of its tokens' probabilities."""
    support: float | None = None
    """How likely this model finds the grammar's words beside its own: their mean
    log-probability per token minus that of its own words, in nats (0: as likely; -1: a
    token in e times less likely). None when the grammar heard no words."""
    asked: str = ""
    """Why this ear was asked, for an ear asked only when the others leave a doubt."""
    no_speech: float | None = None
    """The model's own probability that the audio held no speech (Whisper's)."""
    second: str | None = None
    """What a second decode of the same ear heard (Whisper, prompted with the orders'
    words), where it alone hears the language: its own evidence, never a second ear."""
    alternatives: Annotated[list[str], msgspec.Meta(max_length=MAX_ALTERNATIVES)] = msgspec.field(
        default_factory=list
    )
    """Both decodes' other hypotheses (beam searches), the first decode's then the second's,
    each most likely first: where neither's best makes orders, one of these may, and is
    only ever read back for a yes."""


class Transcript(Message):
    """A final transcript: one per spoken utterance, from the recogniser.

    `text` and the fields after it are the grammar's result and its own verdict;
    `transcription`, when the recogniser has a second ear, is what that one heard. The
    converter decides from both whether and which orders the speech becomes.
    """

    text: str
    confidence: float | None = None
    """0 to 1; the recogniser rejects an utterance below its threshold (0.5 by default)."""
    session: str = ""
    """The audio session it came from; empty for text that was not spoken."""
    utterance: int = 0
    rejected: bool = False
    """True when the grammar's result is not a command by the recogniser's own judgement."""
    reason: str = ""
    """Why it was rejected, in one line."""
    speech_start: float | None = None
    """Seconds from the start of the session's audio to where the speech began..."""
    speech_end: float | None = None
    """...and ended, as the recogniser found it."""
    heard: str = ""
    """An unconstrained transcript of the same speech: what the person seems to have said."""
    word_confidences: list[float] = msgspec.field(default_factory=list)
    """Per word of `text`, 0 to 1: how surely the recogniser heard it (for pocketsphinx,
    the word's posterior in the grammar's lattice, or the open decode's when higher)."""
    doubts: list[Doubt] = msgspec.field(default_factory=list)
    """Values to ask the person about; a transcript with doubts is never sent by itself."""
    transcription: Transcription | None = None
    """What the second ear (Moonshine) heard."""
    third: Transcription | None = None
    """What the third ear (Whisper) heard, when the first two left a doubt."""
    language: str = "en"
    """The language it was heard in: the converter reads it with that language's orders."""
    alone: bool = False
    """Heard by one ear only, the one that hears the language (Whisper, for a language
    that the grammar's ear and Moonshine do not hear): `text` is empty and `transcription`
    is that ear's. Its orders need evidence of their own (docs/speech.md)."""


class SttStatus(Message):
    """The speech recogniser's state, published on change and re-sent to late subscribers."""

    engine: str
    ready: bool = False
    """True once a grammar is in use: before that every utterance is rejected."""
    grammar_version: str = ""
    detail: str = ""
    """One line for a person: what it listens for, or what is missing."""
    sessions: int = 0
    unpronounceable: list[str] = msgspec.field(default_factory=list)
    """Grammar words without a pronunciation: commands that use them cannot be heard."""


class SessionEnded(Message):
    """The recogniser ended an audio session, or refused to start it (`refused`): told to
    whoever streams it, so that a person is never left talking to nobody."""

    reason: str
    refused: bool = False


MAX_CHECK_SECONDS = 4.0
CHECK_WAIT = 5.0
MAX_CHECK_WAIT = 30.0
MAX_PHRASE_WORDS = 8
MAX_PHRASE_CHARACTERS = 64
"""A wake phrase is a few words: the cost of checking one grows with its length (a check
of 8,000 characters took 7.9 CPU-seconds and 0.7 GB)."""


def check_phrase(phrase: str) -> str:
    """`phrase` if it is as short as a wake phrase is; ValueError saying the limits if not."""
    if not phrase.strip():
        raise ValueError("a phrase needs a word")
    if len(phrase) > MAX_PHRASE_CHARACTERS or len(phrase.split()) > MAX_PHRASE_WORDS:
        raise ValueError(
            f"a phrase is at most {MAX_PHRASE_WORDS} words and {MAX_PHRASE_CHARACTERS} "
            f"characters; got {len(phrase.split())} words, {len(phrase)} characters"
        )
    return phrase


class CheckPhrase(Message):
    """Does this audio say `phrase`? Asked by a listener whose spotter heard its wake
    phrase (`voicectl listen --wake`): the recogniser's neural ear checks, so that a false
    wake sends nothing."""

    pcm: bytes
    """16 kHz mono 16-bit PCM around the phrase, at most `MAX_CHECK_SECONDS`."""
    phrase: Annotated[str, msgspec.Meta(max_length=MAX_PHRASE_CHARACTERS)]
    """At most `MAX_PHRASE_WORDS` words (`check_phrase`)."""
    wait: Annotated[float, msgspec.Meta(gt=0.0, le=MAX_CHECK_WAIT)] = CHECK_WAIT
    """Seconds the asker waits for the answer: a check not begun in time is dropped."""

    def __post_init__(self) -> None:
        if len(self.pcm) > MAX_CHECK_SECONDS * SAMPLE_RATE * 2 or len(self.pcm) % 2:
            raise ValueError(f"pcm must be whole samples, at most {MAX_CHECK_SECONDS:g} s")
        check_phrase(self.phrase)


class PhraseCheck(Message):
    """The answer to `CheckPhrase`."""

    checked: bool
    """False when this recogniser has no neural ear to check with: the spotter decides."""
    heard: bool = False
    text: str = ""
    """What the ear wrote for the audio."""
    support: float | None = None
    """How likely the ear finds the phrase beside its own words (see `Transcription`)."""


class Hearing(Data):
    """One ear's reading of an utterance, as the converter judged it."""

    ear: str
    """'grammar' (pocketsphinx bound to the orders) or a free ear's model ('moonshine',
    'whisper')."""
    text: str
    accepted: bool
    """Whether this ear's words alone make whole orders it vouches for."""
    verdict: str = ""
    """What they make, or why not, in plain words."""


class Proposal(Message):
    """The converter's reading of a transcript, for the panel to show and confirm."""

    transcript: str
    orders: list[Order] = msgspec.field(default_factory=list)
    errors: list[ParseProblem] = msgspec.field(default_factory=list)
    session: str = ""
    """The audio session of the transcript, so that a panel knows its own utterances."""
    utterance: int = 0
    rejected: bool = False
    """The recogniser rejected the speech: no orders, one error saying why."""
    doubts: list[Doubt] = msgspec.field(default_factory=list)
    """The transcript's doubtful values: the panel asks, and never sends these by itself."""
    hearings: list[Hearing] = msgspec.field(default_factory=list)
    """What each ear of the recogniser heard, for speech heard by more than one."""
    decision: str = ""
    """Why the speech became these orders, a doubt or nothing, in one line for a person."""
    confirm: bool = False
    """Heard by one ear without the evidence to send it alone: read back and sent only on
    a yes (a click on the panel, "sí" or "ja" hands-free). It then carries one doubt
    covering its whole transcript, with no alternatives, which is that question."""
    language: str = "en"
    """The language it was heard and read in."""


class ParseRequest(Message):
    text: str
    language: str = ""
    """The language of `text` (ISO 639-1); empty: the converter's default (English when
    it has English orders)."""


class GetGrammar(Message):
    """Ask for the current recogniser grammar (a recogniser that starts late does this)."""

    language: str = ""
    """Its language; empty: the converter's default."""


class Amend(Message):
    """Make `order` again as `change` (a correction, an order of label `queue` whose edit
    is `replace`) says: another number, or another case of the same order."""

    order: Order
    change: Order
    language: str = ""
    """The language the correction was said in; empty: the converter's default."""


ConverterRequest = ParseRequest | GetGrammar | Amend


class ParseReply(Message):
    result: ParseResult


class Amended(Message):
    order: Order


class Grammar(Message):
    """Everything a speech recogniser needs to listen only for valid commands.

    Published on every change of the orders and answered on request.
    """

    jsgf: str
    """A JSGF grammar whose public rule accepts every phrase the orders can produce."""
    phrases: list[str] = msgspec.field(default_factory=list)
    """Every single-order phrase, expanded (sequences join them with the separator)."""
    words: list[str] = msgspec.field(default_factory=list)
    """Every word that can occur in a command, sorted."""
    separator_phrases: list[str] = msgspec.field(default_factory=list)
    skip_words: list[str] = msgspec.field(default_factory=list)
    """Small words that may stand between and around the words of a command."""
    number_words: list[str] = msgspec.field(default_factory=list)
    """The words of spoken numbers in slots: values, which the recogniser checks apart."""
    leading: list[str] = msgspec.field(default_factory=list)
    """Phrases said before the orders they bring ("after that"): an utterance heard so far
    as one of them goes on, and the recogniser waits longer at its pause."""
    unexpandable: list[str] = msgspec.field(default_factory=list)
    """Orders whose alias cannot be expanded to a finite set, one line each saying why."""
    version: str = ""
    """Changes whenever the orders change (a digest of the phrases)."""
    language: str = "en"
    """The language of its orders (ISO 639-1): the recogniser hears it in that language."""


class OrdersStatus(Message):
    """Whether the last (re)load of the orders files worked; errors keep the previous orders."""

    ok: bool
    sources: list[str] = msgspec.field(default_factory=list)
    errors: list[str] = msgspec.field(default_factory=list)
    orders: int = 0
    """How many orders are loaded (the previous set when the reload failed)."""
    languages: list[str] = msgspec.field(default_factory=list)
    """The languages the loaded orders are in."""


class Place(Data):
    """A named place of the orders ('kitchen'): where one of them takes the robot on the map."""

    name: str
    """The case's name ('kitchen'), or the order's when it has no cases."""
    phrase: str
    """Words that make the order ('reach kitchen'): what a click on the place stages."""
    description: str
    """The order's description ('reach kitchen')."""
    pose: TargetPose
    """Where it is, in the 'map' frame."""
    language: str = "en"
    """The language of `phrase` and `description`: each language's orders give their own."""
    title: str = ""
    """The place as the map labels it in that language ("la cocina"); empty: `name`."""


class Places(Message):
    """Every named place of the loaded orders, published on every (re)load."""

    places: list[Place] = msgspec.field(default_factory=list)


# --- robot ------------------------------------------------------------------------------------


class ExecutorInfo(Message):
    """How the executor reaches its robot: what the supervisor and the clients need to
    stop the robot themselves when the executor is gone."""

    transport: TransportKind = TransportKind.BRIDGE
    domain_id: int = 0
    """The ROS domain, on rmw_zenoh."""
    namespace: str = ""
    """The robot's namespace ('' or 'bot1')."""
    distro: RosDistro = RosDistro.JAZZY
    cmd_vel: str = "cmd_vel"
    """The velocity topic's name."""
    cmd_vel_type: CmdVelType = CmdVelType.TWIST
    cmd_vel_hash: str = ""
    """On rmw_zenoh, the type hash the robot's cmd_vel subscribers announced for
    `cmd_vel_type` ('RIHS01_...', 'TypeHashNotSupported' on Humble): the last chunk of the
    only key they hear. '' until the executor has seen their tokens."""
    navigate: str = "navigate_to_pose"
    """The NavigateToPose action's name."""
    navigation: str = ""
    """Why navigation orders would fail at once ('navigation unavailable: ...': Nav2's
    interfaces missing where the executor runs, no navigation announced by the robot);
    '' when the robot's navigation is there."""


class RobotMap(Message):
    """The robot's own map (a Nav2 robot's occupancy grid), relayed by its executor while a
    panel shows it, at most every few seconds."""

    width: int
    """Cells; the image is `width` x `height` pixels."""
    height: int
    resolution: float
    """Metres per cell."""
    origin: TargetPose
    """Where the cell (0, 0) corner is, in the map's frame."""
    png: str
    """The grid as a base64 8-bit grey PNG, row 0 at the origin: 0 occupied, 254 free,
    205 unknown (map_server's colours)."""


class RobotPose(Message):
    """Where the robot is, from its odometry, as its executor sees it (at most twice a second)."""

    x: float
    y: float
    yaw: float
    frame: str = "odom"
    run: str = ""
    """Which run of the executor sent it: a new one after a restart, whose odometry may
    start anywhere (the panel's trail breaks there instead of joining the two)."""


# --- supervisor ---------------------------------------------------------------------------


class OrderStatus(StrEnum):
    QUEUED = "queued"
    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"
    CANCELLED = "cancelled"
    REJECTED = "rejected"
    INTERRUPTED = "interrupted"
    """It was running when the supervisor stopped, and the executor no longer runs it."""


class Progress(Data):
    """How far the current order has come, as much as the executor knows."""

    text: str = ""
    distance_linear: float | None = None
    """Metres still to go."""
    distance_angular: float | None = None
    """Radians still to turn."""
    percent: float | None = None


class Via(StrEnum):
    """How a request reached the supervisor."""

    VOICE = "voice"
    """The robot's own ear (`voicectl listen`)."""
    PANEL = "panel"
    CLI = "cli"
    """A `voicectl` command."""
    API = "api"
    """Anything else that asks the bus or the HTTP API directly."""


class Asked(Data):
    """Who asked for an order or an edit, and how: kept with it in the history."""

    via: Via = Via.API
    spoken: bool = False
    """Said (a microphone, the robot's ear) rather than typed or clicked."""
    by: str = ""
    """Who, as the client knows it: a user and host, a panel's address."""


class OrderRecord(Data):
    """An order as the supervisor tracks it, from acceptance to its result."""

    id: str
    order: Order
    status: OrderStatus
    transcript: str = ""
    request_id: str = ""
    message: str = ""
    """The executor's last word on it (why it failed, what it did)."""
    progress: Progress | None = None
    submitted_at: float = 0.0
    started_at: float | None = None
    ended_at: float | None = None
    asked: Asked | None = None
    """Who asked for it and how; None for records from before it was kept."""


class State(Data):
    """Everything a panel needs to show a robot's orders at a glance."""

    robot: str
    executor_online: bool = False
    current: OrderRecord | None = None
    queue: list[OrderRecord] = msgspec.field(default_factory=list)
    """The head of the queue, in dispatch order (at most a page; see `queue_length`)."""
    queue_length: int = 0
    history: list[OrderRecord] = msgspec.field(default_factory=list)
    """Recent history, most recent first; GetHistory pages through all of it."""
    stopped: bool = False
    """The emergency stop is latched: nothing runs and nothing is accepted until Release."""
    paused: str = ""
    """Why the queue waits instead of dispatching (orders restored after a restart wait
    for Resume); empty when it runs."""
    stop_detail: str = ""
    """What the robot, navigation and the executor answered to the last emergency stop:
    they answer after the stop is acknowledged, and their answers land here."""
    undo: str = ""
    """The edit an "undo" would revert now, in words ("cancel kitchen"); empty when none."""


class Submit(Message):
    """Queue a batch of orders (one utterance); `request_id` makes retries harmless."""

    request_id: str
    orders: list[Order]
    transcript: str = ""
    asked: Asked | None = None


class Edit(Message):
    """Change the queue or ask about it: `edit` is an order of the reserved label `queue`
    (shared/edits.py reads its parameters), as the converter made it from words."""

    request_id: str
    edit: Order
    orders: list[Order] = msgspec.field(default_factory=list)
    """The orders it brings: those an `after` edit puts after the last one added."""
    transcript: str = ""
    asked: Asked | None = None


class Cancel(Message):
    order_id: str


class CancelAll(Message):
    pass


class EmergencyStop(Message):
    pass


class GetState(Message):
    pass


class Release(Message):
    """Release a latched emergency stop: orders are accepted again."""


class Resume(Message):
    """Let a paused queue (orders restored after a restart) run."""


class Reorder(Message):
    """Move a queued order to `position` (0 is next)."""

    order_id: str
    position: Annotated[int, msgspec.Meta(ge=0)]


HISTORY_OFFSET_MAX = 2**53
"""The furthest a history page may start (JSON's largest exact integer)."""
HISTORY_LIMIT_MAX = 500
"""The most records one history page holds."""


class GetHistory(Message):
    """A page of finished orders, most recent first."""

    offset: Annotated[int, msgspec.Meta(ge=0, le=HISTORY_OFFSET_MAX)] = 0
    limit: Annotated[int, msgspec.Meta(ge=1, le=HISTORY_LIMIT_MAX)] = 50


SupervisorRequest = (
    Submit
    | Cancel
    | CancelAll
    | EmergencyStop
    | Release
    | Resume
    | GetState
    | Reorder
    | GetHistory
    | Edit
)


class Submitted(Message):
    order_ids: list[str]


class Done(Message):
    """A request that needs no answer beyond 'it happened'."""

    detail: str = ""


class Failed(Message):
    """A request that could not be carried out; `reason` says why in one line."""

    reason: str


class Stopped(Message):
    """The answer to an emergency stop: zero velocity has gone out and the stop is latched;
    `confirmed` when what could still move the robot (navigation, the executor) said
    within moments that it stopped. An unconfirmed stop says what is in doubt."""

    confirmed: bool
    detail: str


class Answered(Message):
    """The answer to an `Edit`: what it did or why not, in one short sentence, or the
    answer to a question."""

    answer: str
    changed: bool = False
    """The queue changed (a refused edit and a question change nothing)."""
    edit_id: str = ""
    """The edit's record in the history; empty for a question."""
    order_ids: list[str] = msgspec.field(default_factory=list)
    """The orders it queued (an `after` edit's, a correction's new order)."""


class StateReply(Message):
    state: State


class HistoryPage(Message):
    records: list[OrderRecord]
    total: int
    """How many finished orders the robot has in all."""
    offset: int = 0


class StateUpdate(Message):
    """Published on the state key whenever anything changes."""

    state: State


SupervisorReply = Submitted | Done | Stopped | Failed | StateReply | HistoryPage | Answered

ConverterReply = ParseReply | Grammar | Amended | Failed

SttReply = PhraseCheck | Failed


# --- executor ------------------------------------------------------------------------------


class Execute(Message):
    """Run one order; the reply only says whether the executor took it."""

    order_id: str
    order: Order


class CancelOrder(Message):
    order_id: str


class Halt(Message):
    """Stop all motion now, outside any order."""


class Latch(Message):
    """The emergency stop, told to the executor on a key of its own: answered on the
    thread that receives it, never on the executor's event loop, so that an executor
    whose loop is blocked still stops commanding the robot. `on` refuses every command
    and ends the running order at once; off lets orders command again, and is taken only
    on the executor's release key (the supervisor's)."""

    on: bool = True


class GetRunning(Message):
    """Which order is the executor running? Asked by a supervisor that restarted."""


class GetResult(Message):
    """How did this order end? Asked by a supervisor that restarted while it ran; the
    executor keeps its last results, and answers with OrderFinished or Failed."""

    order_id: str


class GetPhoto(Message):
    """The photo an order took (the `pic` executor's), asked on the executor's photo key."""

    order_id: str


class Photo(Message):
    order_id: str
    media_type: str
    """'image/png', 'image/jpeg': as the camera gave it."""
    data: bytes


PhotoReply = Photo | Failed


ControlRequest = CancelOrder | Halt | GetRunning | GetResult
"""What the executor's control key takes; its execute key takes `Execute` alone, so a
message sent to the wrong key is a decode error, not a surprise."""
ExecutorRequest = Execute | ControlRequest


class Accepted(Message):
    order_id: str


class Rejected(Message):
    order_id: str
    reason: str
    latched: bool = False
    """The executor is under an emergency stop: the order was refused for the stop."""


class Running(Message):
    order_id: str | None = None
    """None when idle."""


class OrderProgress(Message):
    order_id: str
    progress: Progress


class OrderFinished(Message):
    order_id: str
    status: OrderStatus
    """An end: succeeded, failed, cancelled, rejected or interrupted, never queued or
    running (a message saying otherwise does not decode)."""
    message: str = ""

    def __post_init__(self) -> None:
        if self.status in (OrderStatus.QUEUED, OrderStatus.RUNNING):
            raise ValueError(f"an order does not finish as {self.status}")


ExecutorEvent = OrderProgress | OrderFinished


ExecutorReply = Accepted | Rejected | Done | Failed | Running | OrderFinished
"""A cancel for an order that has just finished is answered with its OrderFinished, so
the supervisor records what really happened."""
