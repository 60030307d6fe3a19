"""`voicectl health [SERVICE]`: whether a voicectl service is up, said in one line, or
every service of the stack, a line each.

Exit status 0 when it is (all are) and 1 when it is not (one is not), for container
healthchecks (Docker reserves every other status) and scripts. A service is up when its
liveliness token is on the bus (converter, stt, supervisor, executor, sim), the router
when a session to it opens, and the panel when its health address answers. The
executor's line also says whether the robot's navigation is available, as the executor
last said (its `ExecutorInfo`): a robot without Nav2 is up all the same. Needs only what
a robot installs.
"""

from __future__ import annotations

import argparse
import asyncio
import ssl
import sys
import urllib.error
import urllib.parse
import urllib.request

import zenoh

from voicectl.shared.bus import Bus, json_decoder
from voicectl.shared.errors import BusError
from voicectl.shared.keys import ConverterKeys, RobotKeys
from voicectl.shared.messages import ExecutorInfo
from voicectl.shared.process import add_bus_arguments, argument_type, bus_options, robot_name
from voicectl.shared.robot.keys import RobotNames, check_ros_name

SERVICES = ("router", "converter", "stt", "supervisor", "executor", "sim", "web")
PER_ROBOT = ("stt", "supervisor", "executor")
"""The services that serve one robot, whose token is under the robot's name."""
DEFAULT_URL = "http://127.0.0.1:8000/api/health"
UP, DOWN = 0, 1


_namespace = argument_type(lambda text: check_ros_name(text, "ROS namespace"))


def _web_url(text: str) -> str:
    if urllib.parse.urlsplit(text).scheme not in ("http", "https"):
        raise argparse.ArgumentTypeError(f"{text!r} is not an http:// or https:// address")
    return text


def add_health_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "service",
        nargs="?",
        choices=SERVICES,
        help="the service to check (default: every one, a line each on stdout)",
    )
    parser.add_argument(
        "--robot",
        type=robot_name,
        default="robot",
        help=f"the robot it serves ({', '.join(PER_ROBOT)}; default: robot)",
    )
    parser.add_argument(
        "--namespace",
        type=_namespace,
        default="",
        help="the ROS namespace the simulator plays (sim; default: none)",
    )
    parser.add_argument(
        "--url",
        type=_web_url,
        default=DEFAULT_URL,
        help=f"the panel's health address (web; default: {DEFAULT_URL})",
    )
    parser.add_argument(
        "--timeout",
        type=float,
        default=2.0,
        metavar="SECONDS",
        help="how long the answer may take once the router is reached (default: 2)",
    )
    add_bus_arguments(parser)


def token_key(service: str, robot: str, namespace: str = "") -> str | None:
    """The liveliness token that says `service` is up; None for the router, which holds
    none (reaching it is the check)."""
    match service:
        case "router" | "web":
            return None
        case "converter":
            return ConverterKeys().alive()
        case "sim":
            return RobotNames(namespace).simulator
        case _:
            return RobotKeys(robot).alive(service)


def check(args: argparse.Namespace) -> int:
    """Check the service the parsed `args` name, or every one; print a line each; return
    the exit status."""
    if args.service is None:
        return _check_all(args)
    if args.service == "web":
        up, said = _check_web(args.url, args.timeout)
    else:
        [(up, said)] = asyncio.run(_check_bus(args, [args.service]))
    if up:
        print(said)
        return UP
    print(f"voicectl health: {said}", file=sys.stderr)
    return DOWN


def _check_all(args: argparse.Namespace) -> int:
    """Every service, one line each on stdout ("up" or "DOWN" first, so a person sees the
    odd one out); exit status 1 when any is down."""
    bus_services = [service for service in SERVICES if service != "web"]
    results = [*asyncio.run(_check_bus(args, bus_services)), _check_web(args.url, args.timeout)]
    for up, said in results:
        print(f"{'up' if up else 'DOWN':<4}  {said}")
    return UP if all(up for up, _ in results) else DOWN


def _subject(args: argparse.Namespace, service: str) -> str:
    if service in PER_ROBOT:
        return f"{service} of robot {args.robot!r}"
    if service == "sim" and args.namespace:
        return f"sim in namespace {args.namespace!r}"
    return service


async def _check_bus(args: argparse.Namespace, services: list[str]) -> list[tuple[bool, str]]:
    """Whether each of `services` is up, over one session to the router."""
    options = bus_options(args, wait=False)
    keys = [token_key(service, args.robot, args.namespace) for service in services]
    try:
        with Bus.open(options, asyncio.get_running_loop()) as bus:
            present = await asyncio.gather(
                *(
                    asyncio.to_thread(_token_present, bus.session, key, args.timeout)
                    for key in keys
                    if key is not None
                )
            )
            executor = RobotKeys(args.robot).alive("executor")
            up = dict(zip([key for key in keys if key is not None], present, strict=True))
            navigation = None
            if up.get(executor):  # what it says of its robot's navigation
                navigation = await _navigation(bus, args.robot, args.timeout)
    except BusError as exc:  # no router: nothing behind it can be up either
        return [
            (False, f"{_subject(args, service)} is not reachable: {exc}") for service in services
        ]
    answers = iter(present)
    results = []
    for service, key in zip(services, keys, strict=True):
        if key is None:
            results.append((True, f"router at {options.where} is up"))
        elif next(answers):
            said = f"{_subject(args, service)} is up ({key})"
            if service == "executor" and navigation is not None:
                said += f"; {navigation or 'navigation available'}"
            results.append((True, said))
        else:
            results.append(
                (False, f"{_subject(args, service)} is not up: no liveliness token on {key}")
            )
    return results


async def _navigation(bus: Bus, robot: str, timeout: float) -> str | None:
    """What `robot`'s executor last said of its navigation ('' available, else why not,
    'navigation unavailable: ...'); None when it said nothing within `timeout` seconds."""
    said: asyncio.Future[ExecutorInfo] = asyncio.get_running_loop().create_future()

    def heard(_key: str, info: ExecutorInfo) -> None:
        if not said.done():
            said.set_result(info)

    stop = bus.subscribe(
        RobotKeys(robot).executor_info, json_decoder(ExecutorInfo), heard, history=True
    )
    try:
        async with asyncio.timeout(timeout):
            return (await said).navigation
    except TimeoutError:
        return None
    finally:
        stop()


def _token_present(session: zenoh.Session, key: str, timeout: float) -> bool:
    """Whether a liveliness token matches `key` (blocks up to `timeout` seconds: run it in
    a thread). The router answers for every token it knows of."""
    replies = session.liveliness().get(key, timeout=timeout)
    return any(reply.ok is not None for reply in replies)


def _check_web(url: str, timeout: float) -> tuple[bool, str]:
    # The panel's certificate is its own self-signed one, made for its LAN names: asking
    # it whether it is up on its own address needs no proof of who it is.
    context = ssl.create_default_context()
    context.check_hostname = False
    context.verify_mode = ssl.CERT_NONE
    try:
        with urllib.request.urlopen(url, timeout=timeout, context=context) as response:
            status = response.status
    except urllib.error.HTTPError as exc:
        status = exc.code
        exc.close()
    except (urllib.error.URLError, OSError) as exc:
        reason = exc.reason if isinstance(exc, urllib.error.URLError) else exc
        return False, f"panel at {url} is not up: {reason}"
    if status != 200:
        return False, f"panel at {url} is not up: HTTP {status}"
    return True, f"panel at {url} is up"
