"""The robot as executors see it: ROS 2 through the robot's transport, CDR payloads.

`RobotLink` is the one connection of the process: it follows odometry, learns what the
robot's topics take from what the robot's graph announces, learns the ROS distribution
from a get_result reply, and does the navigation and stop work, through zenoh-bridge-ros2dds
or rmw_zenoh alike (shared/robot/: Nav2 through the seam's action client, the stop through
its stop). Each order gets an `OrderRobot` (fence.py), a handle onto the link that is
revoked when the order ends, so that an executor that outlives its order can never move the
robot again; relays.py publishes the pose and the map for voicectl's own panels.

Every velocity the executor publishes goes through `RobotLink.drive`, which sends it as
the robot's `SpeedLimits` let it go (speed.py: top speeds, how fast it may speed up, and
never a speed that is not a finite number), whatever an order asks. A goal whose pose is
not finite is never sent either. Nav2's goals carry no speed: before each goal, Nav2's
controller is told the top linear speed on its `speed_limit` topic.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import Callable

from voicectl.shared.errors import BusError, OrderFailed, UnsafeCommand
from voicectl.shared.geometry import compose, map_cell
from voicectl.shared.messages import TargetPose
from voicectl.shared.robot import Interface, RobotTransport, Role
from voicectl.shared.robot.action import ActionClient
from voicectl.shared.robot.stop import RobotStop
from voicectl.shared.robot_options import RobotOptions
from voicectl.shared.ros2 import (
    NAVIGATE_FEEDBACK,
    NAVIGATION_ERRORS,
    SAME_RESULT,
    SPEED_LIMIT,
    CameraType,
    CdrError,
    CmdVelType,
    CompressedImage,
    GoalStatus,
    Image,
    NavigateFeedback,
    NavigateResult,
    OccupancyGrid,
    Odometry,
    Pose2D,
    Ros2Codec,
    RosDistro,
    distro_of_result,
    new_goal_id,
)
from voicectl.shared.throttle import Throttled

from .speed import CONTROL_STEP, SAFE_LIMITS, Refuse, SpeedLimits, Take, command

_LOGGER = logging.getLogger(__name__)

OCCUPANCY_GRID = "nav_msgs/msg/OccupancyGrid"
MAP_WAIT = 2.5
"""Seconds a refused goal waits for the robot's map to say why: a latched map comes at
once, and a map published periodically (the simulator's) every second."""
OCCUPIED = 65
"""A cell this occupied or more is an obstacle (map_server's default threshold, 0.65)."""
SEND_GOAL_TIMEOUT = 10.0
RESULT_TIMEOUT = 24 * 3600.0
"""get_result answers when navigation ends, which can take as long as the robot needs."""
RESULT_GRACE = 10.0
"""Seconds get_result may keep failing (a link down) before the goal is cancelled."""
RESULT_RETRY = 0.5
PROBE_TIMEOUT = 3.0
ROBOT_FRAME = "base_link"
ODOM_FRAME = "odom"
ODOMETRY = "nav_msgs/msg/Odometry"
STALE_COMMAND = 0.5
"""Seconds after which the last command no longer says how fast the robot goes (a base's
cmd_vel watchdog has stopped it, or a stop from elsewhere has): it counts as at rest."""


class RobotRevoked(OrderFailed):
    """A call through the robot handle of an order that has ended."""


class RobotLink:
    """Topics and actions of one robot, shared by every order of the process."""

    def __init__(
        self,
        transport: RobotTransport,
        options: RobotOptions,
        on_change: Callable[[], None] = lambda: None,
        result_grace: float = RESULT_GRACE,
        limits: SpeedLimits = SAFE_LIMITS,
    ) -> None:
        self.transport = transport
        self._result_grace = result_grace
        self.limits = limits
        self._commanded = (0.0, 0.0, -math.inf)
        """The last velocity sent (linear, angular) and when (monotonic seconds)."""
        self._noise = Throttled(_LOGGER)
        self.options = options
        self.names = options.names
        self._on_change = on_change
        """Called when what is known about the robot changes (a detected type)."""
        self._pose_listeners: list[Callable[[Pose2D], None]] = []
        self.pose: Pose2D | None = None
        """Latest pose from odometry, None until the first message."""
        self._odometry = asyncio.Event()
        self.distro: RosDistro | None = options.distro
        """The robot's distribution: as configured, or once detected; None until then."""
        self.navigation = ActionClient(
            transport, self.names.topic(self.names.navigate_name), self.codec
        )
        """Nav2's NavigateToPose, its codec the robot's distribution's once known."""
        self.distro_problem: str | None = None
        """Why navigation cannot be used (the configured distribution is not the robot's)."""
        self._distro_checked = False
        self._probing: asyncio.Task[None] | None = None
        self._probe_again = False
        self._navigation_seen = False
        self.navigation_missing = transport.lacks(NAVIGATE_FEEDBACK)
        """Why this process cannot speak Nav2's NavigateToPose at all (on DDS, nav2_msgs
        is not installed here); None when it can."""
        self.announced_cmd_vel: CmdVelType | None = None
        """What the robot's graph says its cmd_vel subscribers take."""
        self._cmd_vel_hashes: dict[CmdVelType, str] = {}
        """The type hashes the robot's cmd_vel subscribers announced, by type (rmw_zenoh)."""
        self._cmd_vel_learnt = asyncio.Event()
        self.announced_camera: CameraType | None = None
        self._warned_cmd_vel = False
        self.latched = False
        """The emergency stop is on: no order may command the robot. Set from whatever
        thread hears the stop; read wherever a command is about to go out."""

    # --- what the robot takes -------------------------------------------------------------

    @property
    def codec(self) -> Ros2Codec:
        """A codec for the robot's messages (topics are the same in every distribution)."""
        return Ros2Codec(self.distro or RosDistro.JAZZY)

    @property
    def cmd_vel_type(self) -> CmdVelType:
        """As configured, else as the robot announced it, else plain Twist."""
        return self.options.cmd_vel_type or self.announced_cmd_vel or CmdVelType.TWIST

    @property
    def cmd_vel_hash(self) -> str:
        """The type hash the robot's cmd_vel subscribers announced for `cmd_vel_type`; ''
        if none did (or the layout has none): for whoever stops the robot without us."""
        return self._cmd_vel_hashes.get(self.cmd_vel_type, "")

    @property
    def camera_type(self) -> CameraType:
        if self.options.camera_type is not None:
            return self.options.camera_type
        if self.announced_camera is not None:
            return self.announced_camera
        compressed = self.names.camera_name.endswith("/compressed")
        return CameraType.COMPRESSED if compressed else CameraType.RAW

    async def cmd_vel_type_known(self, timeout: float) -> bool:
        """Wait, at most `timeout` seconds, until the type cmd_vel takes is configured or
        announced by the robot: a stop in the wrong type is one the robot cannot read."""
        if self.options.cmd_vel_type is None:
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(timeout):
                    await self._cmd_vel_learnt.wait()
        return self.options.cmd_vel_type is not None or self.announced_cmd_vel is not None

    def on_pose(self, listener: Callable[[Pose2D], None]) -> None:
        """Call `listener(pose)` on the loop for every odometry pose."""
        self._pose_listeners.append(listener)

    @property
    def navigation_seen(self) -> bool:
        """Whether the robot's NavigateToPose server is there: announced (and not gone
        since), or it answered."""
        return self._navigation_seen

    @navigation_seen.setter
    def navigation_seen(self, seen: bool) -> None:
        if seen != self._navigation_seen:
            self._navigation_seen = seen
            self._on_change()

    @property
    def navigation_problem(self) -> str | None:
        """Why a navigation order would fail before anything is sent, in one line: Nav2's
        interfaces missing here, no navigation announced by the robot, or a distribution
        other than the configured one; None while nothing says so."""
        if self.navigation_missing is not None:
            return (
                "navigation unavailable: Nav2's interfaces are missing where the executor "
                f"runs (no nav2_msgs); {self.navigation_missing}"
            )
        if not self.navigation_seen:
            return (
                f"navigation unavailable: the robot announces no "
                f"'{self.names.topic(self.names.navigate_name)}' action on the "
                f"{self.transport.kind} transport (is Nav2 running, under that name? "
                "--navigate names it)"
            )
        return self.distro_problem

    def start(self) -> None:
        codec = self.codec
        names = self.names
        self.transport.subscribe(names.odom, ODOMETRY, codec.read_odometry, self._on_odom)
        if self.navigation_missing is None:
            self.navigation.follow()
        else:  # velocity orders run all the same; navigation orders fail at once
            _LOGGER.warning("%s", self.navigation_problem)
        self.transport.discover(self._on_interface)
        self._probe_soon()

    def _on_interface(self, interface: Interface, present: bool) -> None:
        names = self.names
        if not present:
            if interface.role is Role.ACTION_SERVER and interface.name == names.topic(
                names.navigate_name
            ):
                self.navigation_seen = False  # Nav2 has gone (or its bridge)
            return
        self._adopt_announced_distro()
        match interface.role:
            case Role.SUBSCRIBER if interface.name == names.cmd_vel:
                self._learn_cmd_vel(interface.ros_type, interface.type_hash)
            case Role.PUBLISHER if interface.name == names.camera_image:
                self.announced_camera = CameraType.of(interface.ros_type)
            case Role.ACTION_SERVER if interface.name == names.topic(names.navigate_name):
                self.navigation_seen = True
                self._probe_soon()
            case Role.SERVICE_SERVER if interface.name == names.navigate("get_result"):
                self._probe_soon()  # its key now known (rmw_zenoh: the hash in it)

    def _learn_cmd_vel(self, ros_type: str, type_hash: str = "") -> None:
        found = CmdVelType.of(ros_type)
        if found is None:
            _LOGGER.error("'%s' takes %s, which voicectl cannot send", self.names.cmd_vel, ros_type)
            return
        configured = self.options.cmd_vel_type
        if configured is not None and configured is not found:
            _LOGGER.error(
                "'%s' takes %s, says the robot, but --cmd-vel-type is %s: the robot will "
                "not understand its velocity commands",
                self.names.cmd_vel,
                ros_type,
                configured,
            )
        self._cmd_vel_learnt.set()
        changed = False
        if type_hash and self._cmd_vel_hashes.get(found) != type_hash:
            # The supervisor and the clients stop on that key (ExecutorInfo).
            self._cmd_vel_hashes[found] = type_hash
            changed = True
        if found is not self.announced_cmd_vel:
            self.announced_cmd_vel = found
            _LOGGER.info("'%s' takes %s (announced by the robot)", self.names.cmd_vel, ros_type)
            changed = True
        if changed:
            self._on_change()

    # --- the distribution -----------------------------------------------------------------

    def _adopt_announced_distro(self) -> None:
        """Take the distribution the robot's announcements name (rmw_zenoh's hashes) where
        a get_result reply cannot tell it (`SAME_RESULT`: Rolling's result is Jazzy's, its
        feedback is not), unless one was configured."""
        announced = self.transport.announced_distro()
        if announced is None or announced is self.distro or self.options.distro is not None:
            return
        if self.distro is not None and SAME_RESULT.get(announced) is not self.distro:
            return  # the probe's answer stands: the announcements name another layout
        self.distro = announced
        self.navigation.codec = Ros2Codec(announced)
        _LOGGER.info(
            "the robot's navigation speaks ROS 2 %s (from its type hashes)", announced.title()
        )
        self._on_change()

    def _probe_soon(self) -> None:
        """Probe the distribution now, or again once the probe under way has failed (a
        server announced meanwhile may answer where the first probe found none)."""
        if self._distro_checked or self.navigation_missing is not None:
            return
        if self._probing is not None and not self._probing.done():
            self._probe_again = True
            return
        self._probe_again = False
        self._probing = asyncio.get_running_loop().create_task(self._probe_distro())
        self._probing.add_done_callback(self._probed)

    def _probed(self, _probe: asyncio.Task[None]) -> None:
        if self._probe_again:
            self._probe_soon()

    async def _probe_distro(self) -> None:
        """Ask get_result about a goal that does not exist: an action server answers at
        once, in its distribution's layout, and nothing moves."""
        try:
            reply = await self.navigation.result_reply(new_goal_id(), PROBE_TIMEOUT)
        except BusError as exc:
            _LOGGER.debug("no answer to the distribution probe: %s", exc)
            return
        self.navigation_seen = True
        try:
            found = distro_of_result(reply)
        except CdrError as exc:
            self.distro_problem = f"navigation's get_result reply is in no known layout: {exc}"
            _LOGGER.error("%s", self.distro_problem)
            self._on_change()
            return
        self._distro_checked = True
        configured = self.options.distro
        # Rolling's result is Jazzy's: what tells it is its hashes, or the configuration.
        for told in (configured, self.transport.announced_distro()):
            if told is not None and SAME_RESULT.get(told) is found:
                found = told
                break
        if configured is not None and configured is not found:
            self.distro_problem = (
                f"the robot's navigation speaks ROS 2 {found.title()}, not {configured.title()} "
                f"as --distro says; restart the executor with --distro {found} (or auto)"
            )
            _LOGGER.error("%s", self.distro_problem)
            self._on_change()
            return
        if self.distro is not found:
            self.distro = found
            self.navigation.codec = Ros2Codec(found)
            _LOGGER.info("the robot's navigation speaks ROS 2 %s", found.title())
            self._on_change()

    async def _known_distro(self) -> RosDistro:
        """The distribution, probing now if it is not known yet; OrderFailed if it cannot
        be told or does not match the configuration. Found before any goal is sent."""
        if not self._distro_checked:
            if self._probing is not None and not self._probing.done():
                await asyncio.shield(self._probing)
            else:
                await self._probe_distro()
        if self.distro_problem is not None:
            raise OrderFailed(self.distro_problem)
        if self.distro is None:
            raise OrderFailed(
                f"cannot tell the robot's ROS distribution: nothing answered on "
                f"'{self.names.navigate('get_result')}' (is Nav2 up, and reachable on the "
                f"{self.transport.kind} transport?); or start the executor with --distro"
            )
        return self.distro

    # --- topics ---------------------------------------------------------------------------

    def _on_odom(self, odometry: Odometry) -> None:
        self.pose = odometry.pose
        self._odometry.set()
        for listener in self._pose_listeners:
            listener(odometry.pose)

    async def next_pose(self, timeout: float = 5.0) -> Pose2D:
        """The next odometry pose (fresher than any seen so far)."""
        self._odometry.clear()
        try:
            # Not asyncio.wait_for: on Python 3.11 it can swallow a cancellation that comes
            # as the pose does, and the order would run on past its cancel.
            async with asyncio.timeout(timeout):
                await self._odometry.wait()
        except TimeoutError:
            raise OrderFailed(f"no odometry on '{self.names.odom}' for {timeout:g} s") from None
        assert self.pose is not None
        return self.pose

    async def next_image(self, timeout: float = 5.0) -> Image | CompressedImage:
        """The next camera frame. The camera is subscribed only for this call: the bridge
        streams a topic across the network whenever someone subscribes to it."""
        frame: asyncio.Future[Image | CompressedImage] = asyncio.get_running_loop().create_future()

        def on_frame(image: Image | CompressedImage) -> None:
            if not frame.done():
                frame.set_result(image)

        codec = self.codec
        decode: Callable[[bytes], Image | CompressedImage] = (
            codec.read_compressed_image
            if self.camera_type is CameraType.COMPRESSED
            else codec.read_image
        )
        kind = self.camera_type.ros_type
        name = self.names.camera_image
        unsubscribe = self.transport.subscribe(name, kind, decode, on_frame)
        try:
            async with asyncio.timeout(timeout):
                return await frame
        except TimeoutError:
            raise OrderFailed(f"no {kind} on '{name}' for {timeout:g} s") from None
        finally:
            unsubscribe()

    def drive(self, linear_x: float, angular_z: float) -> None:
        """Publish one velocity command on cmd_vel, in the type the robot takes, as the
        speed limits let it go (`speed.command`). Each waits for room rather than being
        dropped, and goes first. One the limits refuse (a speed that is not a finite
        number) is not sent: the robot is stopped, and UnsafeCommand says why."""
        linear_x, angular_z = self._limit(linear_x, angular_z)
        kind = self.cmd_vel_type
        if kind is CmdVelType.TWIST and self.announced_cmd_vel is None and not self._warned_cmd_vel:
            self._warned_cmd_vel = self.options.cmd_vel_type is None
            if self._warned_cmd_vel:
                _LOGGER.warning(
                    "the robot has not announced '%s'; sending Twist (see --cmd-vel-type)",
                    self.names.cmd_vel,
                )
        payload = self.codec.velocity(kind, linear_x, angular_z, time.time())
        # Every velocity at a stop's priority: Zenoh keeps order only within a priority,
        # and a stop that overtook the command sent just before it left the robot moving
        # (heard: 0.2 m/s after the zero that ended an order).
        self.transport.publish(self.names.cmd_vel, kind.ros_type, payload, urgent=True)

    def _limit(self, linear_x: float, angular_z: float) -> tuple[float, float]:
        """The command as the limits let it go, from the last one sent; remembered as
        sent. A refused one stops the robot and raises UnsafeCommand."""
        now = time.monotonic()
        last_linear, last_angular, at = self._commanded
        if now - at > STALE_COMMAND:
            last_linear = last_angular = 0.0
        dt = min(now - at, CONTROL_STEP)
        top = self.limits
        match command(linear_x, angular_z, (last_linear, last_angular), top, dt):
            case Refuse(reason=reason):
                sent = self.stop_moving()
                _LOGGER.error("%s: nothing of it sent; %s", reason, sent)
                raise UnsafeCommand(f"{reason}; the robot was stopped")
            case Take(linear=linear, angular=angular):
                if abs(linear_x) > top.linear or abs(angular_z) > top.angular:
                    self._noise.warning(
                        "speed",
                        "an order asked %g m/s, %g rad/s: held to %g m/s, %g rad/s "
                        "(--max-speed, --max-angular-speed)",
                        linear_x,
                        angular_z,
                        top.linear,
                        top.angular,
                    )
        self._commanded = (linear, angular, now)
        return linear, angular

    @property
    def stopper(self) -> RobotStop:
        """How to stop this robot, as far as it is known now."""
        return RobotStop(self.transport, self.names, self.codec, self.cmd_vel_type)

    def stop_moving(self) -> str:
        """Zero velocity, at once; callable from any thread."""
        self._commanded = (0.0, 0.0, time.monotonic())
        return self.stopper.zero_velocity()

    # --- stopping -------------------------------------------------------------------------

    async def halt(self) -> str | None:
        """Zero velocity now, then cancel every navigation goal. Returns None when the
        robot confirmed, else what is in doubt."""
        self.stop_moving()
        return await self.cancel_goals()

    async def cancel_goals(self, goal_id: bytes | None = None) -> str | None:
        """Cancel one navigation goal (or all); None when navigation confirmed it or had
        nothing to cancel, else what went wrong, logged, with zero velocity sent again."""
        cancelled = await self.stopper.cancel_goals(goal_id)
        self.navigation_seen |= cancelled.answered
        if cancelled.confirmed:
            return None
        if not cancelled.answered and not self.navigation_seen and goal_id is None:
            return None  # a robot without navigation: nothing to cancel
        _LOGGER.warning("%s; the robot may still be moving", cancelled.detail)
        self.stop_moving()
        return cancelled.detail

    # --- navigation -----------------------------------------------------------------------

    async def navigate(
        self,
        target: TargetPose,
        on_feedback: Callable[[Pose2D, float], None],
        on_problem: Callable[[str], None],
    ) -> None:
        """Run Nav2's NavigateToPose to `target`; return on success, raise otherwise.

        On Jazzy a 'base_link' goal is sent as it is: the navigator transforms it once,
        on receipt, that is when this order starts. Humble's navigator would transform it
        again at every replan, so that it moves with the robot: there it is turned into an
        'odom' goal from the current odometry first.
        """
        frame, pose = target.frame, Pose2D(x=target.x, y=target.y, yaw=target.yaw)
        self._refuse_unless_finite(frame, pose)
        unavailable = self.navigation_problem
        if unavailable is not None:
            raise OrderFailed(unavailable)
        distro = await self._known_distro()
        navigation = self.navigation
        if navigation.codec.distro is not distro:  # set with the distribution; kept honest here
            navigation.codec = Ros2Codec(distro)
        if distro is RosDistro.HUMBLE and frame == ROBOT_FRAME:
            pose, frame = compose(await self.next_pose(), pose), ODOM_FRAME
            self._refuse_unless_finite(frame, pose)  # odometry's own numbers may not be
        await self._limit_navigation()
        goal_id = new_goal_id()

        def feedback(message: NavigateFeedback) -> None:
            on_feedback(message.pose, message.distance_remaining)

        with navigation.following(goal_id, feedback):
            try:
                try:
                    accepted = await navigation.send_goal(goal_id, frame, pose, SEND_GOAL_TIMEOUT)
                except BusError as exc:
                    raise OrderFailed(f"navigation unavailable: {exc}") from exc
                if not accepted:
                    _LOGGER.info(
                        "navigation rejected the goal (%s %g, %g)", target.frame, target.x, target.y
                    )
                    raise OrderFailed(
                        f"navigation refused the goal{await self._why_refused(target)}"
                    )
                result = await self._result(goal_id)
            except asyncio.CancelledError:
                # While send_goal is still under way too: navigation may have the goal
                # already (its answer not back yet), and a goal nobody follows must not
                # drive on.
                problem = await asyncio.shield(self.cancel_goals(goal_id))
                if problem is not None:
                    on_problem(problem)
                raise
        _raise_unless_succeeded(result, distro)

    async def _limit_navigation(self) -> None:
        """Hold Nav2's controller to the top linear speed of `limits` for the goal about
        to be sent: its speed_limit topic (m/s), which Nav2 keeps until told otherwise. Nav2
        takes no angular limit there. Where it cannot be sent, the goal goes all the same,
        at the speeds Nav2 is configured with, and the log says so. Off the loop: a DDS
        publisher's first message waits for DDS to match it."""
        name = self.names.speed_limit
        missing = self.transport.lacks(SPEED_LIMIT)
        try:
            if missing is not None:
                raise BusError(missing)
            payload = self.codec.speed_limit(self.limits.linear, time.time())
            await asyncio.to_thread(self.transport.publish, name, SPEED_LIMIT, payload)
        except BusError as exc:
            self._noise.warning("speed_limit", "Nav2's speed limit not sent on '%s': %s", name, exc)

    def _refuse_unless_finite(self, frame: str, pose: Pose2D) -> None:
        """UnsafeCommand, the robot stopped, for a goal pose that is not finite numbers."""
        if all(math.isfinite(value) for value in (pose.x, pose.y, pose.yaw)):
            return
        sent = self.stop_moving()
        goal = f"x {pose.x}, y {pose.y}, yaw {pose.yaw} in '{frame}'"
        _LOGGER.error("refused a goal at %s: not a finite pose; %s", goal, sent)
        raise UnsafeCommand(f"a goal at {goal}: not a finite pose; not sent, the robot stopped")

    async def _why_refused(self, target: TargetPose) -> str:
        """What the robot's own map says of a goal navigation refused (Nav2 says nothing):
        ': it is outside the robot's map', or '' when the map cannot tell. A goal relative
        to the robot is placed by odometry, and said to be, unless the map is odometry's."""
        grid = await self.map_once(MAP_WAIT)
        if grid is None:
            return ""
        if target.frame == grid.frame:
            point, basis = Pose2D(x=target.x, y=target.y, yaw=0.0), ""
        elif target.frame == ROBOT_FRAME and self.pose is not None:
            point = compose(self.pose, Pose2D(x=target.x, y=target.y, yaw=0.0))
            basis = "" if grid.frame == ODOM_FRAME else " (by odometry)"
        else:
            return ""
        match map_cell(grid, point.x, point.y):
            case None:
                where = "outside the robot's map"
            case cell if cell < 0:
                where = "in a part of the robot's map it has not seen"
            case cell if cell >= OCCUPIED:
                where = "on an obstacle of the robot's map"
            case _:
                return ""
        return f": it is {where}{basis}"

    async def map_once(self, timeout: float) -> OccupancyGrid | None:
        """The robot's map, if one comes within `timeout` seconds (a latched map: at once);
        subscribed only for this call, as a map is large."""
        grids: asyncio.Queue[OccupancyGrid] = asyncio.Queue()
        unsubscribe = self.transport.subscribe(
            self.names.map,
            OCCUPANCY_GRID,
            self.codec.read_occupancy_grid,
            grids.put_nowait,
            latched=True,
        )
        try:
            async with asyncio.timeout(timeout):
                return await grids.get()
        except TimeoutError:
            return None
        finally:
            unsubscribe()

    async def _result(self, goal_id: bytes) -> NavigateResult:
        """get_result, asked again while it fails (it is safe to repeat). If it cannot be
        had within the result grace, the goal is cancelled before the order fails, so that
        the robot does not drive on while the order is reported over."""
        loop = asyncio.get_running_loop()
        failing_since: float | None = None
        while True:
            try:
                return await self.navigation.get_result(goal_id, RESULT_TIMEOUT)
            except (BusError, CdrError) as exc:
                now = loop.time()
                failing_since = now if failing_since is None else failing_since
                if now - failing_since >= self._result_grace:
                    problem = await self.cancel_goals(goal_id)
                    outcome = problem or "the goal was cancelled"
                    raise OrderFailed(f"navigation result lost ({exc}); {outcome}") from exc
                _LOGGER.warning("navigation result not received (%s); asking again", exc)
            await asyncio.sleep(RESULT_RETRY)


def _raise_unless_succeeded(result: NavigateResult, distro: RosDistro) -> None:
    status = result.status
    if status == GoalStatus.SUCCEEDED:
        return
    if status == GoalStatus.CANCELED:
        raise OrderFailed("navigation was cancelled on the robot")
    if distro is RosDistro.HUMBLE:
        raise OrderFailed(f"navigation ended {status.name} (Humble's Nav2 gives no reason)")
    detail = ""
    if result.error_code:
        meaning = NAVIGATION_ERRORS.get(result.error_code, "unknown code")
        detail = f": error {result.error_code} ({meaning})"
    if result.error_msg:
        detail += f"{': ' if not detail else ', '}{result.error_msg}"
    raise OrderFailed(f"navigation ended {status.name}{detail}")
