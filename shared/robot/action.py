"""A ROS 2 action client on the robot-transport seam: written once, for every transport.

An action is three services and two topics under ``<action>/_action/`` (rcl_action):
send_goal, get_result and cancel_goal; feedback and status. `ActionClient` speaks them
through a `RobotTransport`, with the CDR types of `shared.ros2`, so that the bridge and
rmw_zenoh reach Nav2 the same way. The executor's robot sends its goals with it; the stop
cancels with it.

The client is Nav2's NavigateToPose, the one action voicectl sends goals to: the codec
reads its goal, feedback and result. Cancel and status are action_msgs' and the same for
every action.

Sending never waits for anything but the call itself: a cancel asks at once, urgently,
and `cancel_now` does not even wait for the answer (a stop from a thread whose loop has
stalled). Constructing a client declares nothing; only `follow` subscribes.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from ..errors import BusError
from ..ros2 import (
    CANCEL_ALL,
    CANCEL_GOAL,
    NAVIGATE_FEEDBACK,
    NAVIGATE_GET_RESULT,
    NAVIGATE_SEND_GOAL,
    CancelCode,
    CdrError,
    GoalStatus,
    NavigateFeedback,
    NavigateResult,
    Pose2D,
    Ros2Codec,
)
from .keys import action_member
from .transport import RobotTransport

_LOGGER = logging.getLogger(__name__)

CANCEL_TIMEOUT = 2.0
"""How long navigation has to answer a cancel."""
GOAL_STATUS_ARRAY = "action_msgs/msg/GoalStatusArray"

OnFeedback = Callable[[NavigateFeedback], None]


@dataclass
class _Followed:
    """A goal this client sent and still follows."""

    on_feedback: OnFeedback
    status: GoalStatus | None = None
    """The latest status the action server published for it; None before any."""


class ActionClient:
    """The robot's NavigateToPose action `action` ('bot1/navigate_to_pose'), as a ROS 2
    action client sees it, through `transport`."""

    def __init__(self, transport: RobotTransport, action: str, codec: Ros2Codec) -> None:
        self.transport = transport
        self.action = action
        self.codec = codec
        """The robot's distribution's codec: goals and results differ between Humble and
        Jazzy (cancel, status and feedback do not). Its owner replaces it once the
        distribution is known."""
        self._goals: dict[bytes, _Followed] = {}
        self._unsubscribe: list[Callable[[], None]] = []

    def member(self, member: str) -> str:
        """The name of one of the action's services or topics ('send_goal', 'status')."""
        return action_member(self.action, member)

    # --- following: feedback and status ---------------------------------------------------

    def follow(self) -> None:
        """Subscribe to the action's feedback and status, once, for the goals this client
        follows (`following`)."""
        if self._unsubscribe:
            return
        codec = self.codec  # status is the same in every distribution
        self._unsubscribe = [
            self.transport.subscribe(  # the feedback in the codec of the day (Rolling's differs)
                self.member("feedback"),
                NAVIGATE_FEEDBACK,
                lambda raw: self.codec.read_feedback(raw),
                self._on_feedback,
            ),
            self.transport.subscribe(  # transient local: the last status, also to a late client
                self.member("status"),
                GOAL_STATUS_ARRAY,
                codec.read_goal_status_array,
                self._on_status,
                latched=True,
            ),
        ]

    def close(self) -> None:
        """End the subscriptions of `follow`."""
        for unsubscribe in self._unsubscribe:
            unsubscribe()
        self._unsubscribe = []

    @contextlib.contextmanager
    def following(self, goal_id: bytes, on_feedback: OnFeedback) -> Iterator[None]:
        """Follow goal `goal_id` (its feedback to `on_feedback`, its status to `status`)
        while in the block: entered before the goal is sent, so that nothing it says
        early is lost."""
        self._goals[goal_id] = _Followed(on_feedback)
        try:
            yield
        finally:
            self._goals.pop(goal_id, None)

    def status(self, goal_id: bytes) -> GoalStatus | None:
        """The latest status published for a followed goal; None before any, or for a goal
        not followed."""
        followed = self._goals.get(goal_id)
        return followed.status if followed is not None else None

    def _on_feedback(self, feedback: NavigateFeedback) -> None:
        followed = self._goals.get(feedback.goal_id)
        if followed is not None:
            followed.on_feedback(feedback)

    def _on_status(self, statuses: list[tuple[bytes, GoalStatus]]) -> None:
        for goal_id, status in statuses:
            followed = self._goals.get(goal_id)
            if followed is not None and followed.status is not status:
                followed.status = status
                _LOGGER.debug("goal %s %s", goal_id.hex()[:8], status.name)

    # --- the services ---------------------------------------------------------------------

    async def send_goal(self, goal_id: bytes, frame: str, pose: Pose2D, timeout: float) -> bool:
        """Send a goal: whether the server accepted it. BusError when nothing answers,
        CdrError for an answer that does not decode."""
        reply = await self.transport.call(
            self.member("send_goal"),
            NAVIGATE_SEND_GOAL,
            self.codec.send_goal_request(goal_id, frame, pose),
            timeout,
        )
        return self.codec.read_send_goal_response(reply)

    async def result_reply(self, goal_id: bytes, timeout: float) -> bytes:
        """get_result's reply as it came, in the server's distribution's layout; the
        server answers once the goal has ended (at once for a goal it does not know).
        BusError when nothing answers."""
        return await self.transport.call(
            self.member("get_result"),
            NAVIGATE_GET_RESULT,
            self.codec.get_result_request(goal_id),
            timeout,
        )

    async def get_result(self, goal_id: bytes, timeout: float) -> NavigateResult:
        """How goal `goal_id` ended, once it has. BusError when nothing answers, CdrError
        for an answer that does not decode. Safe to ask again."""
        return self.codec.read_get_result_response(await self.result_reply(goal_id, timeout))

    async def cancel(
        self, goal_id: bytes | None = None, timeout: float = CANCEL_TIMEOUT
    ) -> Cancelled:
        """Cancel one goal, or every goal; what navigation answered. Asked at once and
        urgently: a cancel is part of a stop."""
        what = f"goal {goal_id.hex()[:8]}" if goal_id is not None else "every goal"
        request = self.codec.cancel_goal_request(goal_id or CANCEL_ALL)
        try:
            raw = await self.transport.call(
                self.member("cancel_goal"), CANCEL_GOAL, request, timeout, urgent=True
            )
        except BusError as exc:
            return Cancelled(
                False, False, f"navigation did not answer the cancel of {what} ({exc})"
            )
        try:
            code = self.codec.read_cancel_goal_response(raw).return_code
        except CdrError as exc:
            return Cancelled(
                True, False, f"navigation's answer to the cancel does not decode: {exc}"
            )
        match code:
            case CancelCode.REJECTED:
                return Cancelled(True, False, f"navigation refused to cancel {what}")
            case CancelCode.UNKNOWN_GOAL_ID:
                return Cancelled(True, True, "navigation had no goal to cancel")
            case CancelCode.GOAL_TERMINATED:
                return Cancelled(True, True, "navigation's goals had already ended")
            case _:
                return Cancelled(True, True, f"navigation cancelled {what}")

    def cancel_now(self) -> None:
        """Ask the server to cancel every goal without waiting for its answer; from any
        thread (one whose event loop is stalled)."""
        self.transport.call_and_forget(
            self.member("cancel_goal"),
            CANCEL_GOAL,
            self.codec.cancel_goal_request(),
            CANCEL_TIMEOUT,
        )


@dataclass(frozen=True)
class Cancelled:
    """What navigation said to a cancel."""

    answered: bool
    """Navigation answered at all (a robot without Nav2 never does)."""
    confirmed: bool
    """Nothing it was asked to cancel goes on: cancelled, unknown or already ended."""
    detail: str
    """In one line, for a person."""
