"""A ROS 2 graph on DDS, reached as a plain ROS 2 node with rclpy: no bridge, no Zenoh.

For the robots that run neither zenoh-bridge-ros2dds nor rmw_zenoh. The executor joins the
robot's graph as `voicectl_executor`, with the robot's own ROS 2 (apt's, sourced) or
PyPI's wheels (`pip install 'voicectl[ros2]'`); rclpy is imported only when this
transport is opened. What crosses the seam stays CDR bytes: publications go out raw
(`publish` of serialized bytes), subscriptions come in raw, and a service call's request is
read into rclpy's type only to be sent. Types are found by their ROS names in the
installed interface packages: a robot whose environment has no `nav2_msgs` (no Nav2, or
PyPI's wheels alone) is driven all the same, and its navigation is said to be unavailable
(`lacks`, services/executor/robot.py).

QoS as rcl and rcl_action set it, and as voicectl's other transports announce it:
publications and service calls reliable and volatile, 10 deep; an action's status
transient local, 1 deep; a latched topic (a map) reliable and transient local. Other
subscriptions are best effort, which matches a reliable publisher and a sensor's best
effort one alike.

rclpy spins on a thread of its own: what arrives is handed to the bus's event loop, and
what is sent is sent from whichever thread asks (a STOP on Zenoh's thread, the watchdog's),
so a blocked loop holds up neither. What the graph shows (who publishes and subscribes
what, which services have a server) is looked at every `GRAPH_EVERY` seconds on that
thread.

A process that only has Zenoh (the supervisor, the panel, `voicectl stop`) cannot reach a
DDS graph: it stops such a robot through the STOP relay (services/relay), which serves the
bridge's layout for the robot's cmd_vel and navigation cancel, and nothing else
(`stop_through`).
"""

from __future__ import annotations

import asyncio
import importlib
import importlib.util
import logging
import threading
import time
from collections.abc import Awaitable, Callable, Iterable
from typing import Any, Self, TypeVar

from ..bus import Bus
from ..errors import BusError, ServiceError
from ..hints import pip_install
from ..kinds import RosDistro, TransportKind
from .transport import (
    Announcements,
    Decode,
    Handle,
    Interface,
    RobotTransport,
    Role,
    Unsubscribe,
    action_of,
)

_LOGGER = logging.getLogger(__name__)

T = TypeVar("T")

GRAPH_EVERY = 0.1
"""Seconds between two looks at the ROS graph."""
MATCH_WAIT = 0.5
"""Seconds a new publisher's first message waits, at most, for DDS to match it with the
subscribers the graph shows: sent before, it reaches none of them."""


def rclpy_hint() -> str:
    return (
        "the ros2 transport needs rclpy and the robot's interface packages: source the "
        f"robot's ROS 2 (. /opt/ros/$ROS_DISTRO/setup.bash) or {pip_install('ros2')}"
    )


FROM_THE_EXTRA = frozenset(
    {
        "builtin_interfaces",
        "std_msgs",
        "geometry_msgs",
        "nav_msgs",
        "sensor_msgs",
        "action_msgs",
        "unique_identifier_msgs",
    }
)
"""The interface packages `pip install 'voicectl[ros2]'` brings (PyPI's Kilted wheels)."""
_MEMBERS = (
    ("_SendGoal", ("Impl", "SendGoalService")),
    ("_GetResult", ("Impl", "GetResultService")),
    ("_FeedbackMessage", ("Impl", "FeedbackMessage")),
)
"""The types rcl_action derives from an action type, and where rclpy keeps them."""


def interface_class(ros_type: str) -> Any:
    """The rclpy class of a message or service type, an action's derived types included
    ('nav2_msgs/action/NavigateToPose_SendGoal'); BusError naming what to install."""
    package, kind, name = ros_type.split("/")
    try:
        module = importlib.import_module(f"{package}.{kind}")
        for suffix, path in _MEMBERS:
            if kind == "action" and name.endswith(suffix):
                found = getattr(module, name.removesuffix(suffix))
                for part in path:
                    found = getattr(found, part)
                return found
        return getattr(module, name)
    except (ImportError, AttributeError) as exc:
        raise BusError(f"no ROS 2 type {ros_type} here ({exc}): {install_hint(package)}") from exc


def install_hint(package: str) -> str:
    """How the interface package `package` gets where this process runs, in words."""
    apt = f"apt install ros-$ROS_DISTRO-{package.replace('_', '-')}"
    if package == "nav2_msgs":
        return (
            "Nav2's interfaces come with Nav2, from no Python package index: start the "
            "executor where the robot's ROS 2 with Nav2 is sourced (. /opt/ros/$ROS_DISTRO/"
            f"setup.bash; {apt} installs them), or build nav2_msgs into its environment"
        )
    pip = f", or {pip_install('ros2')}" if package in FROM_THE_EXTRA else ""
    return (
        f"the ROS package {package} is not installed here: source the robot's ROS 2 "
        f"(. /opt/ros/$ROS_DISTRO/setup.bash; {apt} installs it){pip}"
    )


class Ros2Transport(RobotTransport):
    """This process as ROS 2 node `node` on DDS, in ROS domain `domain_id`."""

    kind = TransportKind.ROS2
    stop_through = TransportKind.BRIDGE

    def __init__(self, bus: Bus, node: str, domain_id: int = 0) -> None:
        try:
            import rclpy
            from rclpy.executors import MultiThreadedExecutor
            from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
            from rclpy.serialization import deserialize_message, serialize_message
            from rclpy.signals import SignalHandlerOptions
        except ImportError as exc:
            raise ServiceError(f"{rclpy_hint()} ({exc})") from exc
        self._bus = bus
        self._serialize = serialize_message
        self._deserialize = deserialize_message
        self._qos = {
            "default": QoSProfile(depth=10),
            "status": QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL),
            "latched": QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL),
            "sensor": QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT),
        }
        self._context = rclpy.Context()
        # The service's own handlers stop it on SIGINT and SIGTERM, not rclpy's.
        rclpy.init(
            context=self._context,
            domain_id=domain_id,
            signal_handler_options=SignalHandlerOptions.NO,
        )
        self._node_name = node
        self._node = rclpy.create_node(node, context=self._context, start_parameter_services=False)
        self._executor = MultiThreadedExecutor(num_threads=2, context=self._context)
        self._executor.add_node(self._node)
        self._lock = threading.Lock()
        self._publishers: dict[tuple[str, str], Any] = {}
        self._clients: dict[tuple[str, str], Any] = {}
        self._graph: set[Interface] = set()
        self._watchers: list[Callable[[Interface, bool], None]] = []
        self._subscribed: dict[str, list[str]] = {}
        """Topic name -> the ROS types its subscribers (not this node) take."""
        self._timer: Any = None
        self._spinner = threading.Thread(target=self._spin, name="rclpy", daemon=True)
        self._spinner.start()
        bus.at_close(self.close)
        _LOGGER.info("ROS 2 node '%s' on DDS, domain %d", node, domain_id)

    @classmethod
    def open(
        cls, bus: Bus, node: str, namespace: str, domain_id: int, distro: RosDistro | None
    ) -> Self:
        # Names come whole from `RobotNames` (namespace included); rclpy reads any layout.
        return cls(bus, node, domain_id)

    @classmethod
    def announcements(cls, domain_id: int, own: str) -> Announcements | None:
        return None  # a DDS graph announces nothing on Zenoh

    @classmethod
    def unavailable(cls) -> str | None:
        if importlib.util.find_spec("rclpy") is None:
            return f"rclpy cannot be imported: {rclpy_hint()}"
        return None

    @classmethod
    def prepare(cls, distro: RosDistro, ros_types: Iterable[str]) -> None:
        pass  # nothing is built per type: rclpy's type support is the robot's

    def lacks(self, ros_type: str) -> str | None:
        try:
            interface_class(ros_type)
        except BusError as exc:
            return str(exc)
        return None

    def _spin(self) -> None:
        try:
            self._executor.spin()
        except Exception:  # the context shut down under it: the process is closing
            _LOGGER.debug("rclpy's executor ended", exc_info=True)

    def close(self) -> None:
        """Leave the graph: the node, then the context, then the thread that spun it."""
        self._executor.shutdown(timeout_sec=1.0)
        self._node.destroy_node()
        self._context.try_shutdown()
        self._spinner.join(timeout=5.0)

    # --- topics ---------------------------------------------------------------------------

    def publisher(self, name: str, ros_type: str) -> Any:
        """This node's publisher on topic `name`, created on first use, and then matched
        (`matched`) with the subscribers the graph shows, at most `MATCH_WAIT` seconds: a
        new publisher reaches a subscriber only once DDS has matched the two. Whoever must
        not wait then (a STOP) creates it ahead."""
        with self._lock:
            found = self._publishers.get((name, ros_type))
            if found is None:
                found = self._node.create_publisher(
                    interface_class(ros_type), f"/{name}", self._qos["default"]
                )
                self._publishers[(name, ros_type)] = found
                created = True
            else:
                created = False
        if created:
            deadline = time.monotonic() + MATCH_WAIT
            while not self.matched(name, ros_type) and time.monotonic() < deadline:
                time.sleep(0.005)
        return found

    def matched(self, name: str, ros_type: str) -> bool:
        """Whether this node's publisher on `name` reaches every subscriber of `ros_type`
        the graph shows (at least one)."""
        publisher = self._publishers.get((name, ros_type))
        subscribers = self._node.get_subscriptions_info_by_topic(f"/{name}")
        wanted = sum(s.topic_type == ros_type for s in subscribers)
        return publisher is not None and 0 < wanted <= publisher.get_subscription_count()

    def send(self, name: str, ros_type: str, payload: bytes, urgent: bool = False) -> None:
        self.publisher(name, ros_type).publish(payload)

    def subscribe(
        self, name: str, ros_type: str, decode: Decode[T], handler: Handle[T], latched: bool = False
    ) -> Unsubscribe:
        if latched:
            qos = self._qos["latched"]
        elif name.endswith("/_action/status"):
            qos = self._qos["status"]
        elif name.endswith("/_action/feedback"):
            qos = self._qos["default"]
        else:
            qos = self._qos["sensor"]
        noise = f"'{name}' ({ros_type})"

        def on_message(raw: bytes) -> None:  # on rclpy's thread
            try:
                message = decode(raw)
            except Exception as exc:
                _LOGGER.debug("dropped a sample on %s that does not decode: %s", noise, exc)
                return
            self._bus.call_soon(handler, message)

        subscription = self._node.create_subscription(
            interface_class(ros_type), f"/{name}", on_message, qos, raw=True
        )

        def unsubscribe() -> None:
            self._node.destroy_subscription(subscription)

        return unsubscribe

    # --- services -------------------------------------------------------------------------

    def client(self, name: str, service_type: str) -> Any:
        """This node's client of service `name`, created on first use (ahead, by whoever
        must not wait for DDS to match it when it first calls)."""
        with self._lock:
            found = self._clients.get((name, service_type))
            if found is None:
                found = self._node.create_client(
                    interface_class(service_type), f"/{name}", qos_profile=self._qos["default"]
                )
                self._clients[(name, service_type)] = found
        return found

    def _request(self, client: Any, request: bytes) -> Any:
        try:
            return self._deserialize(request, client.srv_type.Request)
        except Exception as exc:
            raise BusError(
                f"a request for {client.srv_type.__name__} does not decode: {exc}"
            ) from exc

    async def call(
        self, name: str, service_type: str, request: bytes, timeout: float, urgent: bool = False
    ) -> bytes:
        client = self.client(name, service_type)
        message = self._request(client, request)
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        # A server DDS has not matched yet would never get the request: wait for the match.
        while not client.service_is_ready():
            if loop.time() >= deadline:
                raise BusError(f"no server of '{name}' answered in {timeout:g} s")
            await asyncio.sleep(0.01)
        answered: asyncio.Future[Any] = loop.create_future()

        def settle(done: Any) -> None:  # on the loop
            if answered.done():
                return
            if done.exception() is not None:
                answered.set_exception(BusError(f"'{name}' failed: {done.exception()}"))
            else:
                answered.set_result(done.result())

        future = client.call_async(message)
        future.add_done_callback(lambda done: self._bus.call_soon(settle, done))
        try:
            async with asyncio.timeout(max(0.0, deadline - loop.time())):
                response = await answered
        except TimeoutError:
            client.remove_pending_request(future)
            raise BusError(f"'{name}' did not answer in {timeout:g} s") from None
        return bytes(self._serialize(response))

    def call_and_forget(self, name: str, service_type: str, request: bytes, timeout: float) -> None:
        client = self.client(name, service_type)
        future = client.call_async(self._request(client, request))
        timer = threading.Timer(timeout, client.remove_pending_request, (future,))
        timer.daemon = True
        timer.start()

    def call_now(
        self,
        name: str,
        service_type: str,
        request: bytes,
        timeout: float,
        on_reply: Callable[[bytes | None], None],
    ) -> None:
        """Call a service from any thread, waiting for nothing, the loop least of all (a
        STOP relayed from Zenoh's thread): `on_reply(reply)` on rclpy's thread once the
        server answers, or `on_reply(None)` once `timeout` seconds have passed without an
        answer, and at once where the graph shows no server (a robot without Nav2): a
        request DDS has not matched with a server reaches none. The client is made ahead
        (`client`), so that it is matched by then."""
        client = self.client(name, service_type)
        if not client.service_is_ready():
            on_reply(None)
            return
        lock = threading.Lock()

        def settle(reply: bytes | None) -> None:
            if lock.acquire(blocking=False):  # once: the answer or the timeout, first
                on_reply(reply)

        def answered(done: Any) -> None:  # on rclpy's thread
            timer.cancel()
            try:
                settle(bytes(self._serialize(done.result())))
            except Exception as exc:
                _LOGGER.warning("'%s' failed: %s", name, exc)
                settle(None)

        def expired() -> None:
            client.remove_pending_request(future)
            settle(None)

        timer = threading.Timer(timeout, expired)
        timer.daemon = True
        future = client.call_async(self._request(client, request))
        future.add_done_callback(answered)
        timer.start()

    def serve(
        self, name: str, service_type: str, handler: Callable[[bytes], Awaitable[bytes | None]]
    ) -> None:
        raise BusError(
            "the ros2 transport serves nothing: a robot on DDS serves its own services "
            "(voicectl's simulator plays robots on Zenoh: --transport bridge or rmw-zenoh)"
        )

    def offer(self, interface: Interface) -> None:
        pass  # DDS announces every entity itself as it is created

    # --- the graph ------------------------------------------------------------------------

    def discover(self, handler: Callable[[Interface, bool], None]) -> None:
        with self._lock:
            known = list(self._graph)
            self._watchers.append(handler)
        for interface in known:
            self._bus.call_soon(handler, interface, True)
        self.follow()

    def follow(self) -> None:
        with self._lock:
            if self._timer is not None:
                return
            self._timer = self._node.create_timer(GRAPH_EVERY, self._look)

    def expect(self, interface: Interface) -> None:
        pass  # a DDS topic hears any writer of its type: nothing to expect

    def subscriber_types(self, name: str) -> list[str]:
        return list(self._subscribed.get(name, ()))

    def _look(self) -> None:
        """On rclpy's thread: what the graph shows now, against what it showed before."""
        node = self._node
        seen: set[Interface] = set()
        subscribed: dict[str, list[str]] = {}

        def others(endpoints: list[Any]) -> list[Any]:
            return [e for e in endpoints if e.node_name != self._node_name]

        for topic, _types in node.get_topic_names_and_types():
            name = topic.lstrip("/")
            for endpoint in others(node.get_publishers_info_by_topic(topic)):
                seen.add(Interface(Role.PUBLISHER, name, endpoint.topic_type))
            for endpoint in others(node.get_subscriptions_info_by_topic(topic)):
                seen.add(Interface(Role.SUBSCRIBER, name, endpoint.topic_type))
                types = subscribed.setdefault(name, [])
                if endpoint.topic_type not in types:
                    types.append(endpoint.topic_type)
        for service, types in node.get_service_names_and_types():
            if not node.count_services(service):
                continue  # clients alone (this node's own among them)
            name = service.lstrip("/")
            for ros_type in types:
                seen.add(Interface(Role.SERVICE_SERVER, name, ros_type))
                action = action_of(name, ros_type)
                if action is not None:
                    seen.add(Interface(Role.ACTION_SERVER, *action))
        self._subscribed = subscribed
        with self._lock:
            gone, came = self._graph - seen, seen - self._graph
            self._graph = seen
            watchers = list(self._watchers)
        for handler in watchers:
            for interface in came:
                self._bus.call_soon(handler, interface, True)
            for interface in gone:
                self._bus.call_soon(handler, interface, False)
