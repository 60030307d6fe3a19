"""An order's handle on the robot (`OrderRobot`): what an executor may do with it, only
while its order runs and no stop is latched, and never once it has ended."""

from __future__ import annotations

import logging
from collections.abc import Callable

from voicectl.shared.errors import OrderFailed, UnsafeCommand
from voicectl.shared.messages import TargetPose
from voicectl.shared.robot.keys import RobotNames
from voicectl.shared.robot.velocity import unsafe_velocity
from voicectl.shared.ros2 import (
    CdrError,
    CmdVelType,
    CompressedImage,
    Image,
    Pose2D,
    Ros2Codec,
)

from .robot import RobotLink, RobotRevoked

_LOGGER = logging.getLogger(__name__)

UNSUPERVISED = "supervisor lost: the robot takes no command while no one could STOP it"
"""Why an order may not command the robot while the supervisor is lost."""
LATCHED = "the emergency stop is on: the robot takes no command until it is released"


class OrderRobot:
    """The robot as one order sees it. Calls go to the process's `RobotLink` until the
    order ends or is abandoned; then the handle is revoked, and every call raises
    `RobotRevoked` and sends nothing.

    The handle also notes whether the order has commanded the robot (anything but
    reading it or stopping it), and refuses commands while `unsupervised()` says no one
    could STOP the robot: they raise OrderFailed and send nothing.

    A command with a speed or a goal that is not a finite number is never sent: the robot
    is stopped, the handle revoked, `on_unsafe(reason)` told (the order fails, whatever
    the executor does with the UnsafeCommand raised)."""

    def __init__(
        self,
        link: RobotLink,
        order_id: str,
        unsupervised: Callable[[], bool] = lambda: False,
        on_unsafe: Callable[[str], None] = lambda _reason: None,
    ) -> None:
        self._link = link
        self._order_id = order_id
        self._revoked = False
        self._unsupervised = unsupervised
        self._on_unsafe = on_unsafe
        """Told why, when the order asked something unsafe (`UnsafeCommand`): it fails."""
        self.commanded = False
        """Whether the order has moved the robot, navigated, or sent it anything else."""
        self.problems: list[str] = []
        """What the robot did not confirm while this order ran (a refused cancel)."""

    def revoke(self) -> None:
        """End the handle; a plain flag, so any thread may do it (the emergency stop's)."""
        self._revoked = True

    @property
    def revoked(self) -> bool:
        return self._revoked

    def _live(self) -> RobotLink:
        if self._revoked:
            raise RobotRevoked(f"order '{self._order_id}' has ended: its robot handle is revoked")
        return self._link

    def _command(self) -> RobotLink:
        """The link, for a call that may move the robot."""
        link = self._live()
        if link.latched:
            raise RobotRevoked(LATCHED)
        if self._unsupervised():
            raise OrderFailed(UNSUPERVISED)
        self.commanded = True
        return link

    @property
    def pose(self) -> Pose2D | None:
        """The latest odometry pose, None until the first."""
        return self._link.pose

    @property
    def names(self) -> RobotNames:
        """The robot's ROS names; `names.topic("name")` is a name under its namespace."""
        return self._link.names

    @property
    def codec(self) -> Ros2Codec:
        return self._link.codec

    def _unsafe(self, refused: UnsafeCommand) -> UnsafeCommand:
        """The order asked something no robot may be sent: stopped, revoked, failed."""
        self._link.stop_moving()
        self.revoke()
        self._on_unsafe(str(refused))
        return refused

    def drive(self, linear_x: float, angular_z: float) -> None:
        """Publish one velocity command on the robot's cmd_vel (a zero one is a stop,
        always allowed, even once the handle is revoked)."""
        if linear_x == 0.0 and angular_z == 0.0:
            self._link.drive(0.0, 0.0)  # even revoked: an executor's clean-up may stop
            return
        link = self._command()
        try:
            link.drive(linear_x, angular_z)
        except UnsafeCommand as exc:
            raise self._unsafe(exc) from None
        self._stop_again_if_overtaken(link)

    def _stop_again_if_overtaken(self, link: RobotLink) -> None:
        """A stop that latched or revoked this handle while a command was on its way (on
        another thread: the emergency stop's, the watchdog's) may have sent its zero
        first, and the robot took the command after it. The stop sets its flag before it
        sends, so a command that finds the flag set here is followed by another zero; one
        that does not went out before the stop's own."""
        if link.latched or self._revoked:
            link.stop_moving()

    async def next_pose(self, timeout: float = 5.0) -> Pose2D:
        return await self._live().next_pose(timeout)

    async def next_image(self, timeout: float = 5.0) -> Image | CompressedImage:
        return await self._live().next_image(timeout)

    async def navigate(
        self, target: TargetPose, on_feedback: Callable[[Pose2D, float], None]
    ) -> None:
        link = self._command()
        try:
            await link.navigate(target, on_feedback, self.problems.append)
        except UnsafeCommand as exc:
            raise self._unsafe(exc) from None

    def publish(self, name: str, ros_type: str, payload: bytes) -> None:
        """Publish CDR bytes on any other topic of the robot (`names.topic("name")`, of
        ROS type `ros_type`): any topic may move it. A velocity on cmd_vel goes as `drive`
        sends it, held to the speed limits (OrderFailed if it cannot be read); a velocity
        on any topic with an axis that is not a finite number is refused."""
        link = self._command()
        try:
            self._publish(link, name, ros_type, payload)
        except UnsafeCommand as exc:
            raise self._unsafe(exc) from None
        self._stop_again_if_overtaken(link)

    def _publish(self, link: RobotLink, name: str, ros_type: str, payload: bytes) -> None:
        if name != link.names.cmd_vel:
            link.transport.publish(name, ros_type, payload)  # refuses what is not finite
            return
        unsafe = unsafe_velocity(ros_type, payload)
        if unsafe is not None:
            raise UnsafeCommand(f"refused {unsafe} on '{name}'; the robot was stopped")
        kind = CmdVelType.of(ros_type)
        try:
            if kind is None:
                raise CdrError(f"{ros_type} is not a Twist or a TwistStamped")
            linear_x, angular_z = link.codec.read_velocity(kind, payload)
        except CdrError as exc:
            raise OrderFailed(
                f"a velocity on '{name}' must be one the executor can read, to hold it to "
                f"the speed limits: {exc}"
            ) from exc
        link.drive(linear_x, angular_z)

    async def call(self, name: str, service_type: str, request: bytes, timeout: float) -> bytes:
        """Call any other service of the robot with CDR bytes; its reply's bytes."""
        return await self._command().transport.call(name, service_type, request, timeout)
