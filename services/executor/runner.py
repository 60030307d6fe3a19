"""The executor on the bus: takes one order at a time, reports progress and results.

The supervisor holds the operator's STOP. When its liveliness token goes (it died, or the
link to it is down past the Zenoh lease), an order that commands the robot is cancelled
and the robot halted; an order that has not commanded it (a wait, a photo) goes on, but
may not command the robot until a supervisor is back.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import logging
from collections.abc import Callable, Coroutine

from voicectl.shared.bus import Bus, Latest, json_decoder
from voicectl.shared.errors import OrderFailed
from voicectl.shared.hints import voicectl_command
from voicectl.shared.keys import RobotKeys
from voicectl.shared.messages import (
    Accepted,
    CancelOrder,
    ControlRequest,
    Done,
    Execute,
    ExecutorInfo,
    ExecutorRequest,
    Failed,
    GetResult,
    GetRunning,
    Halt,
    Latch,
    Message,
    Order,
    OrderFinished,
    OrderProgress,
    OrderStatus,
    Progress,
    Rejected,
    Running,
)
from voicectl.shared.process import Service, forever
from voicectl.shared.throttle import Throttled

from .fence import OrderRobot
from .framework import Bindings, ExecutionContext, Executor, ParamsMismatch, order_params
from .owner import OwnerCheck, Refuse
from .robot import RobotLink
from .watchdog import LoopWatchdog

_LOGGER = logging.getLogger(__name__)
RECENT_RESULTS = 32
CMD_VEL_TYPE_WAIT = 2.0
"""Seconds the start-up stop waits for the robot to say what cmd_vel takes."""
STALL_LIMIT = 0.5
"""Seconds the event loop may stall before an order commanding the robot is halted."""
SUPERVISOR_LOST = "supervisor lost: robot stopped (no one could STOP it)"
"""How an order that commanded the robot ends when the supervisor goes."""


class _Offered:
    """An order offered and being checked against who supervises the robot (`OwnerCheck`,
    a moment on the bus): not started yet. A cancel or a halt that comes meanwhile, which
    would have found it running had it started at once, withdraws it: it never starts."""

    def __init__(self) -> None:
        self.withdrawn = ""
        """Why it will not start, once something has withdrawn it."""


class _Execution:
    """The order being executed, the task that runs it and its robot handle."""

    def __init__(self, order_id: str, task: asyncio.Task[None], robot: OrderRobot) -> None:
        self.order_id = order_id
        self.task = task
        self.robot = robot
        self.reported = False
        """True once its result has been published, so it is published once."""
        self.cancel_reason = "cancelled"
        self.cancel_status = OrderStatus.CANCELLED
        self.ended_by: tuple[OrderStatus, str] | None = None
        """Set when something outside the order ended it (an emergency stop, a stalled
        loop): how it ended, whatever `execute` returns afterwards."""


class ExecutorService(Service):
    """Serves execute/cancel/halt for one robot.

    A service (shared/process.py): `start()` serves its keys and starts the robot's link
    and the loop's watchdog, `run()` ends stray motion and then says the executor is
    online, `stop()` takes it offline and interrupts the order that runs.
    """

    def __init__(
        self,
        bus: Bus,
        keys: RobotKeys,
        robot: RobotLink,
        bindings: Bindings,
        cancel_deadline: float = 2.0,
        stall_limit: float = STALL_LIMIT,
    ) -> None:
        self._bus = bus
        self._keys = keys
        self._robot = robot
        self._bindings = bindings
        self.labels = bindings.labels
        """The labels this executor serves."""
        self._cancel_deadline = cancel_deadline
        self._running: _Execution | None = None
        self._withdraw: Callable[[], None] = lambda: None
        self._recent: collections.OrderedDict[str, OrderFinished] = collections.OrderedDict()
        """The last results, to answer a cancel that crossed its order's end."""
        self.abandoned: dict[asyncio.Task[None], str] = {}
        """Tasks of executors that ignored a cancel, with their order ids: while one runs,
        no other order starts, so that no two `execute` ever run at once."""
        self._info: Latest | None = None
        self._supervisor_seen = False
        self.supervisor_lost = False
        """The supervisor was seen, and its token has gone since: no one could STOP."""
        self._tasks: set[asyncio.Task[str | None]] = set()
        """Halts in progress (the loop keeps only weak references to tasks)."""
        self._stall_limit = stall_limit
        self._watchdog: LoopWatchdog | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stalled: _Execution | None = None
        """The order halted because the loop stalled under it, until the loop runs again."""
        self._navigation: Callable[[], None] | None = None
        """Withdraws the navigation token, while it is held."""
        self._offered: dict[str, _Offered] = {}
        """Orders offered and being checked, by id."""
        self._owner = OwnerCheck(bus, keys.robot)
        """Orders are taken from the robot's own supervisor only."""
        self._noise = Throttled(_LOGGER)

    async def start(self) -> None:
        self._robot.start()
        self._bus.serve(self._keys.executor_execute, json_decoder(Execute), self.handle)
        self._bus.serve(self._keys.executor_control, json_decoder(ControlRequest), self.handle)
        latches = json_decoder(Latch)
        self._bus.serve_now(self._keys.executor_latch, latches, self._on_latch)
        self._bus.serve_now(self._keys.executor_release, latches, self._on_release)
        self._loop = loop = asyncio.get_running_loop()
        self._watchdog = LoopWatchdog(loop, self._stall_limit, self._on_stall, self._on_recover)
        self._watchdog.start()
        for label in self._bindings.labels:
            try:
                self._bus.announce(self._keys.label(label))
            except ValueError as exc:  # still served; only not announced
                _LOGGER.warning("label not announced: %s", exc)
        self._bus.watch(self._keys.alive("supervisor"), self._on_supervisor)
        self._info = self._bus.latest(self._keys.executor_info)
        self.publish_info()
        labels = ", ".join(self.labels)
        _LOGGER.info("executor ready for %s; labels: %s", self._keys.robot, labels)

    async def run(self) -> None:
        await self.end_stray_motion()
        await forever()

    def publish_info(self) -> None:
        """What a supervisor needs to stop the robot itself if this process dies; sent
        again when something about the robot is learnt (the type its cmd_vel takes, and
        on rmw_zenoh the type hash of the only key the robot hears it on)."""
        robot = self._robot
        info = ExecutorInfo(
            transport=robot.transport.kind,
            domain_id=robot.options.domain_id,
            namespace=robot.names.namespace,
            distro=robot.codec.distro,
            cmd_vel=robot.names.cmd_vel_name,
            cmd_vel_type=robot.cmd_vel_type,
            cmd_vel_hash=robot.cmd_vel_hash,
            navigate=robot.names.navigate_name,
            navigation=robot.navigation_problem or "",
        )
        if self._info is not None:  # started
            self._info.publish(info)
            self._say_navigation(robot.navigation_problem is None)

    def _say_navigation(self, available: bool) -> None:
        """Hold the robot's navigation token (`alive/navigation`, a part the panel shows)
        while navigation is there, and say when that changes."""
        if available == (self._navigation is not None):
            return
        if available:
            self._navigation = self._bus.announce(self._keys.alive("navigation"))
            _LOGGER.info("the robot's navigation is available")
        else:
            assert self._navigation is not None
            self._navigation()
            self._navigation = None
            _LOGGER.warning("%s", self._robot.navigation_problem)

    async def end_stray_motion(self) -> None:
        """At start nothing of this executor runs: whatever moves the robot (a goal an
        earlier executor left, a last velocity command) is stray, and is stopped. Only
        then does the executor say it is online, so that no order's goal meets this
        halt's cancel."""
        if not await self._robot.cmd_vel_type_known(CMD_VEL_TYPE_WAIT):
            _LOGGER.warning(
                "after %g s the robot has still not said what '%s' takes; stopping with Twist",
                CMD_VEL_TYPE_WAIT,
                self._robot.names.cmd_vel,
            )
        problem = await self._robot.halt()
        if problem is None:
            _LOGGER.info("robot halted at start: zero velocity, every navigation goal cancelled")
        else:
            _LOGGER.warning("robot halted at start: zero velocity sent, but %s", problem)
        self._withdraw = self._bus.announce(self._keys.alive("executor"))

    async def handle(self, request: ExecutorRequest) -> Message:
        match request:
            case Execute(order_id=order_id, order=order):
                offered = self._offered[order_id] = _Offered()
                try:
                    verdict = await self._owner.check(request)
                finally:
                    if self._offered.get(order_id) is offered:
                        del self._offered[order_id]
                if offered.withdrawn:
                    return Rejected(order_id=order_id, reason=offered.withdrawn)
                match verdict:
                    case Refuse(reason=reason):
                        self._noise.warning("sender", "refused order %s: %s", order_id, reason)
                        return Rejected(order_id=order_id, reason=reason)
                return self._start(order_id, order)
            case CancelOrder(order_id=order_id):
                running = self._running
                if running is None or running.order_id != order_id:
                    checked = self._offered.get(order_id)
                    if checked is not None:  # offered, still being checked: it never starts
                        checked.withdrawn = "cancelled before it started"
                        return self._finished(order_id, OrderStatus.CANCELLED, "cancelled")
                    # Finished as the cancel arrived? Then say how, so it is recorded right.
                    finished = self._recent.get(order_id)
                    if finished is not None:
                        return finished
                    return Failed(reason=f"order '{order_id}' is not running here")
                await self._cancel(running, "cancelled")
                return Done(detail=f"cancelled {order_id}")
            case Halt():
                problem = await self._halt("emergency stop")
                if problem is not None:
                    return Failed(reason=f"robot did not confirm the stop: {problem}")
                return Done(detail="halted")
            case GetRunning():
                running = self._running
                return Running(order_id=running.order_id if running is not None else None)
            case GetResult(order_id=order_id):
                finished = self._recent.get(order_id)
                if finished is None:
                    return Failed(reason=f"no result for order '{order_id}' here")
                return finished

    def _halt(self, why: str) -> Coroutine[None, None, str | None]:
        """Stop the robot and end the running order, if any, as cancelled for `why`. Zero
        velocity and the order's cancellation happen now, before the loop lets the order
        run again; the coroutine returned cancels the robot's goals, waits for the order to
        end, and says what the robot did not confirm (None if it did)."""
        self._robot.stop_moving()
        for offered in self._offered.values():
            offered.withdrawn = f"{why} before it started"
        running = self._running
        if running is not None:
            # Revoked at once, without the cancel deadline: whatever the executor does
            # now, it cannot move the robot. Cancelled before the robot's goals, so that
            # the order ends as cancelled, not as a navigation the robot dropped.
            running.robot.revoke()
            running.cancel_reason = why
            running.ended_by = running.ended_by or (running.cancel_status, why)
            running.task.cancel()
        return self._end_halt(running, why)

    async def _end_halt(self, running: _Execution | None, why: str) -> str | None:
        problem = await self._robot.halt()
        if running is not None:
            await self._cancel(running, why)
        return problem

    # --- the emergency stop and the stalled loop: on other threads than the loop --------------

    def _on_release(self, latch: Latch) -> Message:
        """On Zenoh's thread: the supervisor lets the latch go (or latches it, as anyone
        may)."""
        if latch.on:
            return self._on_latch(latch)
        self._robot.latched = False
        _LOGGER.info("emergency stop released: orders may command the robot again")
        return Done(detail="released")

    def _on_latch(self, latch: Latch) -> Message:
        """On Zenoh's thread, whatever the loop is doing: from now on the robot takes no
        command from any order, the running order's handle is revoked (no cancel deadline),
        zero velocity goes out; the loop then ends the order and cancels the robot's goals.
        Releasing is not done here but on its own key (`_on_release`)."""
        if not latch.on:
            return Failed(
                reason="the latch is released through the supervisor "
                f"({voicectl_command('release')}, or Release in the panel), which lifts its "
                "own STOP too"
            )
        self._robot.latched = True
        running = self._running
        if running is not None:
            running.robot.revoke()
            running.ended_by = (OrderStatus.CANCELLED, "emergency stop")
        sent = self._robot.stop_moving()
        _LOGGER.warning("emergency stop: %s", sent)
        if self._loop is not None:
            with contextlib.suppress(RuntimeError):  # the loop is closing: nothing to end
                self._loop.call_soon_threadsafe(self._halt_soon, "emergency stop")
        revoked = f"; order {running.order_id} may no longer command it" if running else ""
        return Done(detail=f"latched{revoked}")

    def _halt_soon(self, why: str) -> None:
        task = asyncio.get_running_loop().create_task(self._halt(why))
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    def _on_stall(self, seconds: float) -> None:
        """On the watchdog's thread: the loop has not run for `seconds`. An order that
        commands the robot is stopped from here, since its own loop cannot."""
        running = self._running
        if running is None or not running.robot.commanded or running.reported:
            _LOGGER.warning("the event loop has not run for %.1f s", seconds)
            return
        running.robot.revoke()
        stopper = self._robot.stopper
        stopper.zero_velocity()
        stopper.cancel_goals_now()
        running.cancel_status = OrderStatus.FAILED
        running.cancel_reason = (
            f"the executor's event loop stalled (blocking code in execute?): robot halted "
            f"after {seconds:.1f} s"
        )
        running.ended_by = (running.cancel_status, running.cancel_reason)
        self._stalled = running
        _LOGGER.error(
            "the event loop has not run for %.1f s while order %s commanded the robot: "
            "robot halted, its handle revoked; execute() must never block (use "
            "asyncio.to_thread)",
            seconds,
            running.order_id,
        )
        note = OrderProgress(
            order_id=running.order_id, progress=Progress(text=running.cancel_reason)
        )
        self._bus.publish(self._keys.executor_events, note, superseded=True)

    def _on_recover(self, seconds: float) -> None:
        stalled, self._stalled = self._stalled, None
        _LOGGER.warning("the event loop runs again after a %.1f s stall", seconds)
        if stalled is not None and stalled is self._running and not stalled.task.done():
            stalled.task.cancel()

    def _on_supervisor(self, _key: str, alive: bool) -> None:
        if alive:
            if self.supervisor_lost:
                _LOGGER.info("supervisor back: orders may command the robot again")
            elif not self._supervisor_seen:
                _LOGGER.info("supervisor online")
            self._supervisor_seen, self.supervisor_lost = True, False
            return
        if not self._supervisor_seen or self.supervisor_lost:
            return  # never there (an executor run alone), or already lost
        self.supervisor_lost = True
        running = self._running
        if running is None:
            _LOGGER.warning("supervisor lost; no order runs")
        elif not running.robot.commanded:
            _LOGGER.warning(
                "supervisor lost; order %s goes on, but may not command the robot until a "
                "supervisor is back",
                running.order_id,
            )
        else:
            _LOGGER.warning(
                "supervisor lost while order %s commanded the robot: cancelling it, halting "
                "the robot",
                running.order_id,
            )
            task = asyncio.get_running_loop().create_task(self._halt(SUPERVISOR_LOST))
            self._tasks.add(task)
            task.add_done_callback(self._tasks.discard)

    async def stop(self) -> None:
        # Offline first, so the supervisor holds its queue instead of sending the next order.
        self._withdraw()
        if self._watchdog is not None:
            self._watchdog.stop()
        if self._running is not None:
            # Interrupted, not cancelled: the rest of its command is dropped, as after a
            # failure, so that the next start does not carry on with it unasked.
            await self._cancel(
                self._running, "executor shutting down", status=OrderStatus.INTERRUPTED
            )

    def _start(self, order_id: str, order: Order) -> Message:
        executor = self._bindings.get(order.label)
        if executor is None:
            bound = ", ".join(self._bindings.labels) or "none"
            return Rejected(
                order_id=order_id,
                reason=f"unknown label '{order.label}'; bound labels: {bound}",
            )
        if self._robot.latched:
            return Rejected(
                order_id=order_id,
                reason="the emergency stop is latched on this executor",
                latched=True,
            )
        if self._running is not None:
            return Rejected(order_id=order_id, reason=f"busy with order '{self._running.order_id}'")
        if self.abandoned:
            stuck = ", ".join(f"'{stuck}'" for stuck in self.abandoned.values())
            return Rejected(
                order_id=order_id,
                reason=f"the executor of order {stuck} ignored its cancel and still runs; "
                "no new order until it ends (restarting the executor ends it)",
            )
        try:
            params = order_params(executor, order)
        except ParamsMismatch as exc:
            return Rejected(order_id=order_id, reason=str(exc))
        robot = OrderRobot(
            self._robot,
            order_id,
            lambda: self.supervisor_lost,
            on_unsafe=lambda reason: self._fail_unsafe(order_id, reason),
        )
        task = asyncio.create_task(self._run(order_id, executor, order, robot, params))
        self._running = _Execution(order_id, task, robot)
        return Accepted(order_id=order_id)

    async def _run(
        self,
        order_id: str,
        executor: Executor,
        order: Order,
        robot: OrderRobot,
        params: object,
    ) -> None:
        def report(progress: Progress) -> None:
            if robot.revoked:  # an executor that outlived its order has nothing to say
                return
            progressed = OrderProgress(order_id=order_id, progress=progress)
            # The next report replaces this one: under congestion it is dropped, not waited for.
            self._bus.publish(self._keys.executor_events, progressed, superseded=True)

        ctx = ExecutionContext(order_id, robot, report, params)
        _LOGGER.info("executing %s: %s (%s)", order_id, order.description, order.label)
        status, message = OrderStatus.SUCCEEDED, ""
        try:
            message = await executor.execute(order, ctx) or "done"
        except asyncio.CancelledError:
            running = self._running
            if running is not None:
                status, message = running.cancel_status, running.cancel_reason
            else:
                status, message = OrderStatus.CANCELLED, "cancelled"
        except OrderFailed as exc:
            status, message = OrderStatus.FAILED, str(exc)
        except Exception as exc:
            _LOGGER.exception("executor for '%s' raised", order.label)
            status, message = OrderStatus.FAILED, f"{type(exc).__name__}: {exc}"
        self._report(order_id, status, message)

    def _fail_unsafe(self, order_id: str, reason: str) -> None:
        """Order `order_id` asked to move the robot by a value that is not a finite number:
        the robot is stopped already and the handle revoked; the order fails with `reason`,
        whatever its executor does with the error (it is cancelled if it goes on)."""
        running = self._running
        if running is None or running.order_id != order_id or running.reported:
            return
        running.cancel_status, running.cancel_reason = OrderStatus.FAILED, reason
        running.ended_by = running.ended_by or (OrderStatus.FAILED, reason)
        if self._loop is not None:  # an executor may drive from a thread of its own
            self._loop.call_soon_threadsafe(self._end_if_running, running)

    @staticmethod
    def _end_if_running(running: _Execution) -> None:
        if not running.task.done() and not running.task.cancelling():
            running.task.cancel()

    def _report(self, order_id: str, status: OrderStatus, message: str) -> None:
        running = self._running
        if running is None or running.order_id != order_id or running.reported:
            return
        running.reported = True
        running.robot.revoke()
        self._running = None
        if running.ended_by is not None:
            # It may have run on past its end (a blocked loop): what it says is not how it ended.
            status, why = running.ended_by
            message = why if message == why else f"{why}; it then said: {message}"
        if running.robot.problems:
            message = "; ".join([message, *running.robot.problems])
        if status is OrderStatus.FAILED and running.robot.commanded:
            # Whatever failed (a goal it could not even make, an exception), the robot is
            # not left moving on the order's last command.
            self._robot.stop_moving()
        self._finished(order_id, status, message)

    def _finished(self, order_id: str, status: OrderStatus, message: str) -> OrderFinished:
        """Say how order `order_id` ended (kept for a cancel that crosses its end)."""
        _LOGGER.info("order %s %s: %s", order_id, status, message)
        finished = OrderFinished(order_id=order_id, status=status, message=message)
        self._recent[order_id] = finished
        while len(self._recent) > RECENT_RESULTS:
            self._recent.popitem(last=False)
        self._bus.publish(self._keys.executor_events, finished)
        return finished

    def _forget_abandoned(self, task: asyncio.Task[None]) -> None:
        order_id = self.abandoned.pop(task, None)
        _LOGGER.info("the abandoned executor of order %s has ended", order_id)

    async def _cancel(
        self, running: _Execution, why: str, status: OrderStatus = OrderStatus.CANCELLED
    ) -> None:
        """Cancel cooperatively; an executor that ignores it past the deadline is abandoned
        and the robot is halted, so a stuck executor can never keep it moving."""
        running.cancel_reason = why
        running.cancel_status = status
        if not running.task.cancelling():
            # Once is enough: a second cancel would cut short the executor's own clean-up
            # (cancelling its navigation goal and hearing whether the robot agreed).
            running.task.cancel()
        done, _ = await asyncio.wait({running.task}, timeout=self._cancel_deadline)
        if not done:
            _LOGGER.warning(
                "order %s ignored cancel for %.1f s; halting",
                running.order_id,
                self._cancel_deadline,
            )
            running.robot.revoke()
            self.abandoned[running.task] = running.order_id
            running.task.add_done_callback(self._forget_abandoned)
            problem = await self._robot.halt()
            halted = "robot halted" if problem is None else f"zero velocity sent, but {problem}"
            self._report(
                running.order_id, status, f"{why}; executor did not stop in time, {halted}"
            )
        else:
            self._report(running.order_id, status, why)
