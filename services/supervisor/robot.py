"""The supervisor's work for one robot: its requests answered, its orders dispatched one
at a time to its executor, its progress folded in, its state published after every change
(coalesced to at most one every `PUBLISH_INTERVAL`), and its emergency stop."""

from __future__ import annotations

import asyncio
import functools
import logging
from collections.abc import Callable

from voicectl.shared.bus import Bus, json_decoder
from voicectl.shared.errors import BusError
from voicectl.shared.hints import voicectl_command
from voicectl.shared.keys import RobotKeys
from voicectl.shared.messages import (
    Accepted,
    Cancel,
    CancelAll,
    CancelOrder,
    Done,
    EmergencyStop,
    Execute,
    ExecutorEvent,
    ExecutorInfo,
    ExecutorReply,
    Failed,
    GetHistory,
    GetResult,
    GetRunning,
    GetState,
    Halt,
    HistoryPage,
    Message,
    OrderFinished,
    OrderProgress,
    OrderRecord,
    OrderStatus,
    Rejected,
    Release,
    Reorder,
    Resume,
    Running,
    StateReply,
    StateUpdate,
    Stopped,
    Submit,
    Submitted,
    SupervisorRequest,
)
from voicectl.shared.robot.stop import (
    ExecutorLatch,
    RobotStop,
    StopOutcome,
    StopProcedure,
    prepare,
)
from voicectl.shared.ros2 import NAVIGATE_FEEDBACK

from .queue import QueueFull, RequestConflict, RobotQueue
from .store import Operation, OrderStore

_LOGGER = logging.getLogger(__name__)

EXECUTOR_TIMEOUT = 5.0
"""How long the executor may take to accept an order or answer a cancel."""
RESUME_GRACE = 3.0
"""After a restart, how long to wait for the executor before calling a restored running
order interrupted."""
RESTORED_STOP = "emergency stop (latched when the supervisor restarted)"
"""How an order restored as running ends when the stop was latched at the restart."""
LOST_GRACE = 0.5
"""After the executor's token goes, how long its running order may still report a result."""
SETTLE = 0.5
"""After an executor that was lost is heard again, how long it must stay so before it is
handed an order: a link that has just come back can drop again at once, and an order sent
then reaches nobody and fails."""
PUBLISH_INTERVAL = 0.02
SAVE_WAIT = 2.0
"""How long a change that is answered only once on disk (a reorder) waits for the store;
past it, the answer says the change is not on disk yet (it is kept, and lands later)."""
CONFIRM_WAIT = 0.3
"""How long an emergency stop waits for navigation and the executor to confirm before it
is acknowledged: the zero velocity is out before, so this delays only the answer."""
HOLD_EVERY = 0.1
"""While the stop is latched, zero velocity goes out this often."""
STOP_NODE = "voicectl_supervisor"
"""The ROS node the supervisor appears as where nodes are seen (rmw_zenoh), for its stops."""


class RobotSupervisor:
    """Everything the supervisor does for one robot."""

    def __init__(self, bus: Bus, store: OrderStore, queue: RobotQueue) -> None:
        self._bus = bus
        self._store = store
        self._queue = queue
        self._keys = RobotKeys(queue.robot)
        self._reply_decode = json_decoder(ExecutorReply)
        self._executor_latch = ExecutorLatch(
            bus,
            self._keys,
            self._reply_decode,
            EXECUTOR_TIMEOUT,
            online=lambda: self._queue.executor_online,
        )
        self._wake = asyncio.Event()
        self._publish_handle: asyncio.TimerHandle | None = None
        self._last_publish = 0.0
        self._tasks: list[asyncio.Future[None]] = []
        self._holding: asyncio.Future[None] | None = None
        self._lost_pending = False
        """The executor's token went while an order ran, and the grace has not run out."""
        self._settled_at: float | None = None
        """When an executor back after a loss may be handed an order (loop time); None
        before the executor was first heard, when it may be at once."""
        self._token = False
        """The executor's liveliness token is alive."""
        self._served: dict[str, bool] = {}
        """Which of its services (execute, control) are reachable: a request sent to one
        now would arrive."""
        self._ends: list[Callable[[], None]] = []
        """What `stop()` withdraws from the bus."""
        self.heard_at = 0.0
        """Loop time the executor's token last came or went."""
        self.executor_info: ExecutorInfo | None = None
        """How to reach the robot without its executor: the executor's last word on it;
        None while no executor was heard (`RobotStop.of` then looks for the robot)."""

    @property
    def robot(self) -> str:
        return self._queue.robot

    def on_info(self, info: ExecutorInfo) -> None:
        """The executor's word on its robot: its stop is prepared now, not at STOP."""
        self.executor_info = info
        prepare(info, self._bus, STOP_NODE)

    def start(self) -> None:
        loop = asyncio.get_running_loop()
        for key in (self._keys.executor_execute, self._keys.executor_control):
            self._served[key] = False
            self._ends.append(self._bus.watch_served(key, functools.partial(self.on_served, key)))
        self._tasks.append(loop.create_task(self._dispatch_loop()))
        if self._queue.stopped:  # latched before a restart: held still again
            # An order restored as running ends as the stop ended it: a stop latched
            # before the restart may not have reached the executor (the supervisor died
            # first), and the state never says stopped beside a running order. The
            # executor is latched once it is heard (`_online`).
            ended = self._queue.stop_current(RESTORED_STOP)
            if ended is not None:
                loop.call_later(EXECUTOR_TIMEOUT, self._stop_waiting, ended.id)
            self._hold()
        if not self._queue.current_verified:
            self._tasks.append(loop.create_task(self._expire_unverified()))
        self._changed()

    async def stop(self) -> None:
        for end in self._ends:
            end()
        tasks = [*self._tasks, *([self._holding] if self._holding is not None else [])]
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        if self._publish_handle is not None:
            self._publish_handle.cancel()

    @property
    def stopped(self) -> bool:
        """The emergency stop is latched."""
        return self._queue.stopped

    @property
    def holds_orders(self) -> bool:
        """Whether it has orders or a latched stop: what must not be dropped."""
        queue = self._queue
        return bool(queue.current or queue.queue or queue.stopped)

    @property
    def idle(self) -> bool:
        """Nothing to keep it for: no executor, no order, no latched stop."""
        return not (self._token or self.holds_orders)

    # --- requests ------------------------------------------------------------------------

    async def handle(self, request: SupervisorRequest) -> Message:
        match request:
            case Submit():
                # One submit alone; the service takes them by batches (`_take_submits`).
                accepted = self.accept(request)
                if isinstance(accepted, Failed):
                    return accepted
                ids, new = accepted
                try:
                    await asyncio.shield(self._store.write(self.changes()))
                except Exception as exc:
                    return self.not_stored(request, new, exc)
                return Submitted(order_ids=ids)
            case Cancel(order_id=order_id):
                return await self._cancel(order_id, "cancelled by user")
            case CancelAll():
                cleared = self._queue.clear_queue("cancelled by user")
                self._changed()
                current = self._queue.current
                if current is not None:
                    await self._cancel(current.id, "cancelled by user")
                return Done(detail=cancelled_words(cleared, current))
            case EmergencyStop():
                return await self._emergency_stop()
            case Release():
                if not self._queue.stopped:
                    return Done(detail="the emergency stop was not on")
                self._queue.release()
                self._store.set_stopped(self.robot, False)
                self._changed()
                problem = await self._executor_latch.release()
                if problem:
                    return Done(detail=f"emergency stop released; EXECUTOR: {problem}")
                return Done(detail="emergency stop released")
            case Resume():
                if not self._queue.paused:
                    return Done(detail="the queue was not paused")
                self._queue.paused = ""
                self._changed()
                return Done(detail="the queue runs again")
            case Reorder(order_id=order_id, position=position):
                moved = self._queue.reorder(order_id, position)
                if moved is None:
                    return Failed(reason=f"order '{order_id}' is not queued")
                detail = f"moved {order_id} to position {moved}"
                saved = self._changed()
                if saved is not None and not await self._committed(saved):
                    detail += f" (not on disk yet: {self._store.trouble or 'the store is slow'})"
                return Done(detail=detail)
            case GetState():
                return StateReply(state=self._queue.snapshot())
            case GetHistory(offset=offset, limit=limit):
                records, total = await self._store.call(
                    self._store.history_page(self.robot, offset, limit), reads=True
                )
                return HistoryPage(records=records, total=total, offset=offset)

    def accept(self, submit: Submit) -> tuple[list[str], bool] | Failed:
        """Queue a submit's orders: their ids, and whether they are new (not a retry's);
        or say why not. They are accepted only once they are stored: whoever calls this
        writes `changes()` and answers after the commit."""
        if not submit.request_id:
            return Failed(reason="submit needs a non-empty request_id")
        if self._queue.stopped:
            return Failed(
                reason="the emergency stop is on: release it first "
                f"({voicectl_command('release')}, or Release in the panel)"
            )
        new = not self._queue.knows(submit.request_id)
        try:
            ids = self._queue.submit(submit.request_id, submit.orders, submit.transcript)
        except (RequestConflict, QueueFull) as exc:
            return Failed(reason=str(exc))
        return ids, new

    def not_stored(self, submit: Submit, new: bool, error: BaseException) -> Failed:
        """A submit whose orders could not be stored: they were never accepted, and none
        of them ran, since an order starts only once it is stored (`_recorded`); a
        retry's failure leaves the first one's orders as they are."""
        if new:
            self._queue.withdraw(submit.request_id)
            self._changed()
        return Failed(reason=f"could not store the orders, so none was queued or run: {error}")

    async def _cancel(self, order_id: str, why: str) -> Message:
        if self._queue.remove_queued(order_id, why):
            self._changed()
            return Done(detail=f"removed {order_id} from the queue")
        current = self._queue.current
        if current is None or current.id != order_id:
            return Failed(reason=f"order '{order_id}' is neither queued nor running")
        reply = await self._send_control(CancelOrder(order_id=order_id))
        match reply:
            case OrderFinished(status=status, message=message):
                # It finished as the cancel arrived: record what really happened.
                self._finish(order_id, status, message)
            case Failed(reason=reason):
                self._finish(order_id, OrderStatus.CANCELLED, f"{why}; executor: {reason}")
        return Done(detail=f"cancelling {order_id}")

    async def _emergency_stop(self) -> Message:
        """Zero velocity first, at once, before anything is asked of anyone; then latch,
        clear the queue, and in parallel latch the executor (answered off its event loop)
        and cancel every navigation goal on the robot's keys (`StopProcedure`), so that
        STOP stops the robot whatever process has died or blocked. Acknowledged after at
        most `CONFIRM_WAIT`, with what answered by then; later answers land in the state."""
        stop = StopProcedure.begin(self._robot_stop(), self._executor_latch)
        cleared, latch_saved = self._latch_queue()
        # The latch on disk before the answer, within the same bound: a supervisor killed
        # just after answering must come back stopped. A disk that refuses it holds no
        # answer back; the write is kept and tried again.
        outcome, _ = await asyncio.gather(
            stop.outcome(CONFIRM_WAIT), asyncio.wait([latch_saved], timeout=CONFIRM_WAIT)
        )
        detail = _stop_detail(outcome, cleared)
        self._queue.stop_detail = detail
        self._changed()
        if not outcome.settled:
            self._tasks.append(asyncio.ensure_future(self._stop_settles(stop, cleared)))
        return Stopped(confirmed=outcome.confirmed, detail=detail)

    def _latch_queue(self) -> tuple[int, asyncio.Future[None]]:
        """This supervisor's side of a stop: latched (remembered across restarts), the
        queue cleared, the robot held still; returns how many orders were cleared, and
        the latch's commit."""
        self._queue.stopped = True
        cleared = self._queue.clear_queue("emergency stop")
        ended = self._queue.stop_current("emergency stop")
        if ended is not None:
            # Its executor's word on it comes within milliseconds, after a stubborn
            # executor's cancel deadline at worst. Word that never comes (an executor out
            # of reach) holds no order back past this: the executor itself refuses a
            # second order while it still runs one.
            loop = asyncio.get_running_loop()
            loop.call_later(EXECUTOR_TIMEOUT, self._stop_waiting, ended.id)
        saved = self._store.set_stopped(self.robot, True)
        self._hold()
        return cleared, saved

    async def _stop_settles(self, stop: StopProcedure, cleared: int) -> None:
        """The stop's late answers, into the state and the log. (The running order ended
        with the stop itself: `_latch_queue`.)"""
        outcome = await stop.outcome()
        detail = _stop_detail(outcome, cleared)
        if self._queue.stopped:
            self._queue.stop_detail = detail
        _LOGGER.info("%s: emergency stop: %s", self.robot, detail)
        self._changed()

    def _stop_waiting(self, order_id: str) -> None:
        if self._queue.stop_waiting(order_id):
            self._wake.set()

    def _robot_stop(self) -> RobotStop:
        return RobotStop.of(self.executor_info, self._bus, STOP_NODE)

    def _hold(self) -> None:
        """While the stop is latched, keep the robot at zero velocity and without goals,
        so that no late command (a stuck executor, another client) moves it."""
        if self._holding is None or self._holding.done():
            self._holding = asyncio.ensure_future(self._hold_still())

    async def _hold_still(self) -> None:
        stop = self._robot_stop()
        goals = asyncio.Event()
        unsubscribe = stop.transport.subscribe(
            stop.names.navigate("feedback"), NAVIGATE_FEEDBACK, bytes, lambda _raw: goals.set()
        )
        said = ""
        try:
            while self._queue.stopped:
                stop = self._robot_stop()
                stop.zero_velocity()
                if goals.is_set():  # navigation works on a goal: nobody may, now
                    goals.clear()
                    cancelled = await stop.cancel_goals()
                    if cancelled.detail != said:  # once, not ten times a second
                        said = cancelled.detail
                        _LOGGER.warning("%s: a goal during the stop: %s", self.robot, said)
                await asyncio.sleep(HOLD_EVERY)
        finally:
            unsubscribe()

    async def _send_control(self, request: CancelOrder | Halt | GetRunning | GetResult) -> Message:
        try:
            return await self._bus.request(
                self._keys.executor_control,
                request,
                self._reply_decode,
                EXECUTOR_TIMEOUT,
                urgent=isinstance(request, Halt),
            )
        except BusError as exc:
            return Failed(reason=f"executor unreachable: {exc}")

    # --- dispatch ------------------------------------------------------------------------------

    async def _dispatch_loop(self) -> None:
        while True:
            await self._wake.wait()
            self._wake.clear()
            if self._settling():
                continue
            pending = self._pending()  # goes first, kept, and not into the start's write
            if pending:
                self._store.keep(pending)
            record = self._queue.start_next()
            if record is None:
                continue
            if await self._recorded(record):
                await self._dispatch(record.id, Execute(order_id=record.id, order=record.order))

    async def _recorded(self, record: OrderRecord) -> bool:
        """Write that `record` starts, and say whether it may be sent to the executor now:
        nothing runs that is not recorded. Its submit must have committed (it commits in
        the same transaction, or earlier), and the start too; otherwise it goes back to
        the head of the queue (or is gone, with its refused submit), and the queue pauses
        saying why. Things that happened meanwhile (a STOP, a cancel) win."""
        try:
            await self._store.write([self._store.require_stored(record.id), *self.changes()])
        except Exception as exc:
            if self._queue.unstart(record.id):
                self._queue.paused = f"order {record.id} could not start: {exc}; then resume"
                _LOGGER.error("%s: %s", self.robot, self._queue.paused)
                self._changed()
            return False
        current = self._queue.current
        if current is None or current.id != record.id:
            # Cancelled, or ended by a stop, while its start was written: never sent, so
            # no executor will say how it ended.
            self._queue.stop_waiting(record.id)
            return False
        if self._queue.stopped:
            self._finish(record.id, OrderStatus.CANCELLED, "emergency stop")
            return False
        return True

    def _settling(self) -> bool:
        """Whether an executor back after a loss is still within `SETTLE`; the dispatcher
        is woken again when it has settled."""
        loop = asyncio.get_running_loop()
        left = (self._settled_at or 0.0) - loop.time()
        if not self._queue.executor_online or left <= 0:
            return False
        loop.call_later(left, self._wake.set)
        return True

    async def _dispatch(self, order_id: str, execute: Execute) -> None:
        try:
            reply = await self._bus.request(
                self._keys.executor_execute, execute, self._reply_decode, EXECUTOR_TIMEOUT
            )
        except BusError as exc:
            # It may have started anyway (an executor killed before it could answer had
            # the robot moving): stop the robot here at once, and tell the executor, if it
            # still listens, to drop the order.
            loop = asyncio.get_running_loop()
            self._tasks.append(loop.create_task(self._halt_after_loss("an order was sent")))
            await self._send_control(CancelOrder(order_id=order_id))
            self._finish(order_id, OrderStatus.FAILED, f"executor did not take it: {exc}")
            return
        match reply:
            case Accepted():
                _LOGGER.debug("%s: %s started", self.robot, order_id)
            case Rejected(latched=latched) if latched or self._queue.stopped:
                # STOP reached the executor before this order did: it never ran, and it
                # ends as every other order the stop caught, not as a refusal. A stop this
                # supervisor has not heard of yet (a client latches the executor directly
                # too, and its request here may still be on the way) stops the queue now,
                # so that no other order is sent in between.
                self._finish(order_id, OrderStatus.CANCELLED, "emergency stop")
                if not self._queue.stopped:
                    _LOGGER.warning("%s: the executor is under an emergency stop", self.robot)
                    self._latch_queue()
                    self._changed()
            case Rejected(reason=reason):
                self._finish(order_id, OrderStatus.REJECTED, reason)
            case Failed(reason=reason):
                self._finish(order_id, OrderStatus.FAILED, reason)
            case _:
                self._finish(order_id, OrderStatus.FAILED, f"executor answered {reply!r}")

    # --- events from the executor -----------------------------------------------------------

    def on_event(self, event: ExecutorEvent) -> None:
        match event:
            case OrderProgress(order_id=order_id, progress=progress):
                if self._queue.progress(order_id, progress):
                    self._publish_soon()
            case OrderFinished(order_id=order_id, status=status, message=message):
                # A final status (the type says so). An order restored after a restart and
                # not verified yet ran while this supervisor was away: it ended by a loss.
                lost = not self._queue.current_verified
                self._finish(order_id, status, message, lost)

    def on_executor(self, alive: bool) -> None:
        """The executor's token came or went."""
        self._token = alive
        self.heard_at = asyncio.get_running_loop().time()
        self._online(self._token and all(self._served.values()))

    def on_served(self, key: str, served: bool) -> None:
        """One of the executor's services became reachable, or stopped being so."""
        self._served[key] = served
        self._online(self._token and all(self._served.values()))

    def _online(self, alive: bool) -> None:
        """The executor is online when its token and its services are all heard: after a
        link comes back the token can arrive first, and an order dispatched then would
        reach nobody and fail."""
        if alive == self._queue.executor_online:
            return
        _LOGGER.info("%s: executor %s", self.robot, "online" if alive else "lost")
        self._queue.executor_online = alive
        current = self._queue.current
        loop = asyncio.get_running_loop()
        if alive:
            self._settled_at = 0.0 if self._settled_at is None else loop.time() + SETTLE
        if alive and self._queue.stopped:
            # An executor heard while the stop is latched is latched too, whatever it
            # missed while it or this supervisor was away.
            self._tasks.append(loop.create_task(self._relatch()))
        if alive and current is not None and self._lost_pending:
            # Back (or a new one) before the grace ran out: ask it whether it still runs it.
            self._lost_pending = False
            self._queue.current_verified = False
            self._tasks.append(loop.create_task(self._verify(current.id, "the executor")))
        elif alive and current is not None and not self._queue.current_verified:
            self._tasks.append(loop.create_task(self._verify(current.id)))
        elif not alive and current is not None and self._queue.current_verified:
            # Its last result may still be on the way: a token's end travels ahead of data.
            self._lost_pending = True
            loop.call_later(LOST_GRACE, self._lost, current.id)
        self._changed()

    async def _relatch(self) -> None:
        answer = await self._executor_latch.latch()
        _LOGGER.info("%s: the emergency stop is latched: %s", self.robot, answer.detail)

    def _lost(self, order_id: str) -> None:
        self._lost_pending = False
        current = self._queue.current
        if self._queue.executor_online or current is None or current.id != order_id:
            return
        # Nobody is in charge of that motion any more: the robot must not go on with it.
        self._finish(order_id, OrderStatus.FAILED, "executor lost; halting the robot")
        loop = asyncio.get_running_loop()
        self._tasks.append(loop.create_task(self._halt_after_loss("an order ran")))

    async def _halt_after_loss(self, when: str) -> None:
        """Zero velocity and every navigation goal cancelled, on the robot's transport and
        names as the executor announced them; logged with what it did."""
        halted = await self._robot_stop().halt()
        _LOGGER.warning("%s: executor lost while %s: %s", self.robot, when, halted.detail)

    async def _verify(self, order_id: str, restarted: str = "the supervisor") -> None:
        """After a restart (of `restarted`): resume the current order if the executor
        still runs it, else record how it ended, or that it was interrupted."""
        reply = await self._send_control(GetRunning())
        current = self._queue.current
        if current is None or current.id != order_id or self._queue.current_verified:
            return
        if isinstance(reply, Running) and reply.order_id == order_id:
            _LOGGER.info("%s: resumed %s, still running on the executor", self.robot, order_id)
            self._queue.current_verified = True
            self._changed()
            return
        # It ended while the supervisor was away: the executor may still know how.
        result = await self._send_control(GetResult(order_id=order_id))
        if isinstance(result, OrderFinished) and result.order_id == order_id:
            _LOGGER.info("%s: %s ended while %s restarted", self.robot, order_id, restarted)
            self._finish(order_id, result.status, result.message, lost=True)
        else:
            self._finish(
                order_id,
                OrderStatus.INTERRUPTED,
                f"{restarted} restarted while it ran and the executor no longer runs it",
            )

    async def _expire_unverified(self) -> None:
        await asyncio.sleep(RESUME_GRACE)
        current = self._queue.current
        if current is not None and not self._queue.current_verified:
            self._finish(
                current.id,
                OrderStatus.INTERRUPTED,
                "the supervisor restarted while it ran and no executor was there",
            )

    # --- bookkeeping -----------------------------------------------------------------------------

    def _finish(self, order_id: str, status: OrderStatus, message: str, lost: bool = False) -> None:
        if self._queue.finish(order_id, status, message, lost):
            _LOGGER.info("%s: %s %s %s", self.robot, order_id, status, message)
            self._changed()

    def _changed(self) -> asyncio.Future[None] | None:
        """Store what changed (in order), publish soon, wake the dispatcher; the store's
        commit of it, if anything is to be stored."""
        operations = self.changes()
        return self._store.keep(operations) if operations else None

    @staticmethod
    async def _committed(saved: asyncio.Future[None]) -> bool:
        """Whether `saved` is on disk within SAVE_WAIT (it is kept in any case)."""
        try:
            await asyncio.wait_for(asyncio.shield(saved), SAVE_WAIT)
        except Exception:  # slow, or failed alone: logged by the store
            return False
        return True

    def changes(self) -> list[Operation]:
        """What changed since the last call, as store operations to run in order; the
        state is published soon and the dispatcher woken."""
        operations = self._pending()
        self._publish_soon()
        self._wake.set()
        return operations

    def _pending(self) -> list[Operation]:
        """What changed since the last call, as store operations, and nothing else."""
        records, requests = self._queue.take_changes()
        operations = [self._store.save_orders(self.robot, records)] if records else []
        if requests:
            operations.append(self._store.save_requests(self.robot, requests))
        return operations

    def _publish_soon(self) -> None:
        if self._publish_handle is not None:
            return
        loop = asyncio.get_running_loop()
        delay = max(0.0, self._last_publish + PUBLISH_INTERVAL - loop.time())
        self._publish_handle = loop.call_later(delay, self._publish)

    def _publish(self) -> None:
        self._publish_handle = None
        self._last_publish = asyncio.get_running_loop().time()
        # Each snapshot is whole and replaces the last: dropped under congestion, never
        # waited for on the loop. Clients that must know ask (GetState).
        self._bus.publish(
            self._keys.state, StateUpdate(state=self._queue.snapshot()), superseded=True
        )


def _stop_detail(outcome: StopOutcome, cleared: int) -> str:
    """A stop's outcome in one line, with the queued orders it cancelled."""
    return f"{outcome.detail}; cancelled {cleared} queued order(s)"


def cancelled_words(queued: int, running: OrderRecord | None) -> str:
    """What a cancel-all cancelled, for a person: 'cancelled 2 queued orders and the
    running order (move forward 5 m)', or that there was nothing."""
    if running is None and not queued:
        return "nothing to cancel: the queue was empty and no order was running"
    waiting = f"{queued} queued order{'s' if queued != 1 else ''}" if queued else ""
    current = f"the running order ({running.order.description})" if running else ""
    return "cancelled " + " and ".join(part for part in (waiting, current) if part)
