"""`voicectl`: one command for every service, the local stack and typed commands."""

from __future__ import annotations

import argparse
import asyncio
import datetime
import getpass
import importlib
import socket
import stat
import sys
from collections.abc import Callable
from pathlib import Path
from typing import NoReturn

import msgspec

from voicectl.services.converter.shipped import shipped_orders
from voicectl.services.executor.config import add_limit_arguments, limit_flags, limits_of
from voicectl.services.stt.config import add_engine_arguments, engine_options
from voicectl.services.web.tls import add_tls_arguments, tls_problem
from voicectl.shared.bus import DEFAULT_ROUTER, Bus
from voicectl.shared.client import Refused, SayRefused, Sent, VoicectlClient
from voicectl.shared.config import data_dir, default_token_file, load_or_create_token
from voicectl.shared.errors import BusError, OrdersFileError
from voicectl.shared.hints import extra_for, pip_install, voicectl_command
from voicectl.shared.keys import ConverterKeys, RobotKeys
from voicectl.shared.kinds import ON_ZENOH, TransportKind
from voicectl.shared.messages import (
    HISTORY_LIMIT_MAX,
    HISTORY_OFFSET_MAX,
    Answered,
    Asked,
    Cancel,
    CancelAll,
    GetHistory,
    GetState,
    Message,
    ParseProblem,
    ParseResult,
    Release,
    Reorder,
    Resume,
    StateReply,
    Via,
)
from voicectl.shared.process import add_bus_arguments, bus_options, robot_name
from voicectl.shared.robot.keys import RobotNames, check_ros_name

from .health import add_health_arguments, check
from .stack import Child, PanelAddress, port_in_use, run_stack

SERVICES = ("router", "converter", "stt", "supervisor", "executor", "relay", "sim", "web", "listen")
COMMAND_EXTRAS = {
    "up": "host",
    "converter": "converter",
    "parse": "converter",
    "stt": "stt",
    "transcribe": "stt",
    "web": "web",
    "cert": "web",
    "listen": "listen",
    "wake": "listen",
}
"""The extra each command needs beyond the core, named when one of its modules is missing."""
SHIPPED_ORDERS = shipped_orders()
"""orders/ of the checkout, or the installed copy of its files."""
_ENCODER = msgspec.json.Encoder()


def _print_json(value: object) -> None:
    print(msgspec.json.format(_ENCODER.encode(value), indent=2).decode())


class _OneLineParser(argparse.ArgumentParser):
    """Usage errors in one line, as every other error of voicectl: what, and where help is."""

    def error(self, message: str) -> NoReturn:
        helps = voicectl_command(*self.prog.split()[1:], "--help")
        self.exit(2, f"{self.prog}: {message} (see {helps})\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _OneLineParser(
        prog="voicectl",
        description="Voice control for robots. Services: "
        + ", ".join(SERVICES)
        + " (voicectl SERVICE --help); voicectl wake train PHRASE trains a wake phrase.",
    )
    sub = parser.add_subparsers(dest="command", required=True)

    up = sub.add_parser("up", help="run the whole local stack with the simulator")
    up.add_argument("--router", default=DEFAULT_ROUTER, help="Zenoh endpoint of the router")
    up.add_argument("--host", default="127.0.0.1", help="panel address")
    up.add_argument("--port", type=int, default=8000, help="panel port")
    up.add_argument("--robot", type=robot_name, default="robot")
    up.add_argument(
        "--language",
        default="en",
        metavar="CODE",
        help="what people speak to the robot's microphone by default (the panel says its "
        "own); the orders in that language are heard (default %(default)s)",
    )
    up.add_argument(
        "--orders",
        type=Path,
        default=SHIPPED_ORDERS,
        help="orders file or directory (default: every shipped file in orders/)",
    )
    up.add_argument("--time-scale", type=float, default=1.0, help="simulator speed-up")
    up.add_argument(
        "--transport",
        choices=list(ON_ZENOH),
        default=TransportKind.BRIDGE.value,
        help="how the simulated robot shows its ROS 2 graph: as zenoh-bridge-ros2dds does "
        "('bridge', the default) or as nodes on rmw_zenoh ('rmw-zenoh')",
    )
    up.add_argument("--no-web", action="store_true", help="do not start the panel")
    up.add_argument("--no-stt", action="store_true", help="do not start speech recognition")
    add_tls_arguments(up)
    add_engine_arguments(up)
    add_limit_arguments(up)
    up.add_argument(
        "--executor",
        action="append",
        default=[],
        metavar="MODULE:CLASS[=LABEL,...]",
        help="bind a user executor in the executor process (repeatable)",
    )
    up.add_argument(
        "--executors",
        action="append",
        default=[],
        metavar="FILE",
        help="YAML file of executor bindings with constructor arguments (repeatable)",
    )

    parse = sub.add_parser(
        "parse",
        help="print the orders a text becomes, as JSON (exit 1 if any part did not make one)",
    )
    parse.add_argument(
        "--orders",
        type=Path,
        default=SHIPPED_ORDERS,
        help="orders file or directory (default: orders/)",
    )
    parse.add_argument(
        "--grammar",
        action="store_true",
        help="print the recogniser grammar (JSGF, phrases, words) as JSON instead",
    )
    parse.add_argument(
        "--language",
        default="en",
        metavar="CODE",
        help="the language of the text: the orders files in it are read (default %(default)s)",
    )
    parse.add_argument("text", nargs="?", help="what was said or typed")

    transcribe = sub.add_parser(
        "transcribe",
        help="recognise WAV files offline with a grammar from orders; one JSON line per file "
        "(exit 1 if any file was rejected or unreadable, 2 if one does not exist)",
    )
    transcribe.add_argument(
        "--orders",
        type=Path,
        default=SHIPPED_ORDERS,
        help="orders file or directory (default: orders/)",
    )
    add_engine_arguments(transcribe)
    transcribe.add_argument(
        "--language",
        default="en",
        metavar="CODE",
        help="the language spoken: the orders in it are read, and heard in it "
        "(default %(default)s)",
    )
    transcribe.add_argument("audio", type=Path, nargs="+", metavar="AUDIO.wav")

    say = sub.add_parser(
        "say", help="convert a text on the bus and submit its orders if all of it made orders"
    )
    say.add_argument("--robot", type=robot_name, default="robot")
    say.add_argument(
        "--partial",
        action="store_true",
        help="submit the orders that were understood even if some words were not",
    )
    say.add_argument(
        "--language",
        default="",
        metavar="CODE",
        help="the language of the text (default: the converter's)",
    )
    add_bus_arguments(say)
    say.add_argument("text")

    def supervisor_command(name: str, help_text: str) -> argparse.ArgumentParser:
        command = sub.add_parser(name, help=help_text)
        command.add_argument("--robot", type=robot_name, default="robot")
        add_bus_arguments(command)
        return command

    supervisor_command("state", "print the supervisor's state as JSON")
    history = supervisor_command("history", "print a page of finished orders as JSON")
    history.add_argument(
        "--offset",
        type=_whole_number(0, HISTORY_OFFSET_MAX),
        default=0,
        help="how many of the newest to skip (default 0)",
    )
    history.add_argument(
        "--limit",
        type=_whole_number(1, HISTORY_LIMIT_MAX),
        default=20,
        help=f"how many to print, 1 to {HISTORY_LIMIT_MAX} (default 20)",
    )
    supervisor_command("cancel", "cancel a queued or running order").add_argument("order_id")
    supervisor_command("cancel-all", "cancel the queue and the running order")
    supervisor_command(
        "stop",
        "emergency stop: zero velocity now, clear the queue, latch; the robot is stopped "
        "from here when no supervisor answers (exit status 4: sent but not confirmed)",
    )
    supervisor_command("release", "release the emergency stop: accept orders again")
    supervisor_command("resume", "run orders that wait since a restart")
    reorder = supervisor_command("reorder", "move a queued order (position 0 is next)")
    reorder.add_argument("order_id")
    reorder.add_argument("position", type=_position, help="0 or more; 0 is next")

    cert = sub.add_parser(
        "cert", help="write a self-signed TLS certificate for the panel's LAN names and addresses"
    )
    cert.add_argument("hosts", nargs="+", metavar="HOST", help="a name or an IP address")
    cert.add_argument("--out", type=Path, default=None, help="directory (default: data dir/tls)")

    secrets = sub.add_parser(
        "bus-secrets",
        help="make a secured bus's CA, router certificate, passwords and per-service configs",
        description="Make a secured bus's CA, router certificate, passwords and one client "
        "config per user: one per host service, and an executor-NAME and a robot-NAME per "
        "robot, which may speak only for that robot. The robot named 'robot' also gets "
        "executor.json5 and robot.json5.",
    )
    secrets.add_argument(
        "directory", type=Path, nargs="?", default=None, help="default: data dir/bus"
    )
    secrets.add_argument(
        "--host",
        action="append",
        default=[],
        metavar="HOST",
        help="a name or address clients use to reach the router (repeatable; the first is "
        "the one their configs connect to; localhost and 127.0.0.1 are always included)",
    )
    secrets.add_argument("--port", type=int, default=7447, help="the router's TLS port")
    secrets.add_argument(
        "--if-missing",
        action="store_true",
        help="when the directory holds secrets already, keep them and exit 0 (a step run "
        "at every start, as compose.yaml runs it)",
    )
    secrets.add_argument(
        "--client",
        metavar="USER",
        default=None,
        help="write nothing: print USER's client config from the directory, its CA inside, "
        "for a command run elsewhere (save it mode 0600: it holds a password)",
    )
    secrets.add_argument(
        "--endpoint",
        default="",
        metavar="ENDPOINT",
        help="with --client: the router's endpoint as seen from where the config is used "
        "(tls/127.0.0.1:7447 for the port compose.yaml publishes)",
    )
    secrets.add_argument(
        "--robot",
        action="append",
        type=robot_name,
        default=[],
        metavar="NAME",
        help="a robot of this deployment, as its services' --robot names it (repeatable; "
        "default: robot)",
    )
    secrets.add_argument(
        "--namespace",
        action="append",
        type=_robot_namespace,
        default=[],
        metavar="NAME=NAMESPACE",
        help="a robot's ROS namespace, as its executor's --namespace (repeatable): its "
        "executor may then drive and ask only the topics and actions under it, and its "
        "robot side speak only under it",
    )

    token = sub.add_parser("token", help="print the panel's API token (creating it if needed)")
    token.add_argument("--token-file", type=Path, default=None)

    health = sub.add_parser(
        "health",
        help="exit 0 if a service (or, with no name, every one) is up, 1 if not, a line each",
        description="Whether a service is up: its liveliness token is on the bus (the "
        "router: a session to it opens; the panel: its health address answers). Exit "
        "status 0 if it is, 1 if not. With no SERVICE, every service, one line each on "
        "stdout, and exit status 1 if any is down.",
    )
    add_health_arguments(health)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    try:
        return _main(argv)
    except ModuleNotFoundError as exc:
        if (exc.name or "").partition(".")[0] in ("shared", "services", "voicectl"):
            raise  # one of ours: a bug, not a missing package
        # A robot installs only the core, a host may lack an extra: the command says which
        # extra brings what is missing, and how to install it here.
        command = argv[0] if argv else "voicectl"
        extra = extra_for(exc.name or "", COMMAND_EXTRAS.get(command, ""))
        print(
            f"voicectl {command}: {exc}; this installation lacks voicectl's [{extra}] extra "
            f"({pip_install(extra)})",
            file=sys.stderr,
        )
        return 2


def _main(argv: list[str]) -> int:
    if argv and argv[0] in SERVICES:
        module = importlib.import_module(f"voicectl.services.{argv[0]}.__main__")
        result: int = module.run(argv[1:])
        return result
    if argv and argv[0] == "wake":  # its own parser, with the listener's packages
        wake = importlib.import_module("voicectl.services.listen.wake_train")
        trained: int = wake.main(argv[1:])
        return trained
    args = build_parser().parse_args(argv)
    match args.command:
        case "up":
            return _up(args)
        case "parse":
            return _parse(args)
        case "transcribe":
            return _transcribe(args)
        case "say":
            return asyncio.run(_say(args))
        case "state":
            return asyncio.run(_ask_supervisor(args, GetState()))
        case "history":
            return asyncio.run(
                _ask_supervisor(args, GetHistory(offset=args.offset, limit=args.limit))
            )
        case "cancel":
            return asyncio.run(_ask_supervisor(args, Cancel(order_id=args.order_id)))
        case "cancel-all":
            return asyncio.run(_ask_supervisor(args, CancelAll()))
        case "stop":
            return asyncio.run(_stop(args))
        case "release":
            return asyncio.run(_ask_supervisor(args, Release()))
        case "resume":
            return asyncio.run(_ask_supervisor(args, Resume()))
        case "reorder":
            request = Reorder(order_id=args.order_id, position=args.position)
            return asyncio.run(_ask_supervisor(args, request))
        case "token":
            print(load_or_create_token(args.token_file or default_token_file()))
            return 0
        case "cert":
            return _cert(args)
        case "bus-secrets":
            return _bus_secrets(args)
        case "health":
            return check(args)
    return 2


def _up(args: argparse.Namespace) -> int:
    # The host's packages, before any child starts: one line, not a traceback per child.
    for needed in ("voicectl.services.converter.service", "voicectl.services.web.app"):
        importlib.import_module(needed)
    busy = _busy_ports(args)
    if busy:
        print(f"voicectl up: {busy}", file=sys.stderr)
        return 2
    try:
        limits = limit_flags(limits_of(args))
    except ValueError as exc:
        print(f"voicectl up: {exc}", file=sys.stderr)
        return 2
    connect = ["--connect", args.router]
    robot = ["--robot", args.robot]
    transport = ["--transport", args.transport]
    children = [
        Child("router", ["voicectl.services.router", "--listen", args.router]),
        # The robot before the services that drive it, so that it stops after them: on
        # Ctrl-C the executor cancels a running order while the robot still listens.
        Child(
            "sim",
            ["voicectl.services.sim", "--time-scale", str(args.time_scale), *transport, *connect],
        ),
        Child("converter", ["voicectl.services.converter", "--orders", str(args.orders), *connect]),
        Child("supervisor", ["voicectl.services.supervisor", *robot, *connect]),
        Child(
            "executor",
            ["voicectl.services.executor", *robot, *transport, *limits, *connect]
            + [arg for spec in args.executor for arg in ("--executor", spec)]
            + [arg for path in args.executors for arg in ("--executors", path)],
        ),
    ]
    if not args.no_stt:
        engine = engine_options(args).argv()
        spoken = ["--language", args.language]
        children.insert(
            3, Child("stt", ["voicectl.services.stt", *robot, *spoken, *engine, *connect])
        )
    web = None
    if not args.no_web:
        problem = tls_problem(args)
        if problem:
            print(f"voicectl up: {problem}", file=sys.stderr)
            return 2
        token = load_or_create_token(default_token_file())
        serve = ["--port", str(args.port), "--host", args.host]
        if args.certfile is not None:
            serve += ["--certfile", str(args.certfile), "--keyfile", str(args.keyfile)]
        children.append(Child("web", ["voicectl.services.web", *robot, *serve, *connect]))
        scheme = "https" if args.certfile is not None else "http"
        shown = "127.0.0.1" if args.host in ("0.0.0.0", "::") else args.host
        # The token rides in the fragment: one click logs in, and a browser never sends a
        # fragment to the server, so no access log can keep it.
        address = f"{scheme}://{shown}:{args.port}/"
        web = PanelAddress(args.host, args.port, address, f"{address}#token={token}")
    keys = RobotKeys(args.robot)
    ready = [
        ConverterKeys().alive(),
        keys.alive("supervisor"),
        keys.alive("executor"),
        RobotNames().simulator,
    ] + ([] if args.no_stt else [keys.alive("stt")])
    return run_stack(children, web, args.router, ready)


def _position(text: str) -> int:
    """argparse type for a queue position: said here, not as the supervisor's schema error."""
    try:
        position = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"position must be a whole number, not {text!r}") from None
    if position < 0:
        raise argparse.ArgumentTypeError(f"position must be 0 or more, not {position}")
    return position


def _whole_number(low: int, high: int) -> Callable[[str], int]:
    """argparse type for a whole number from `low` to `high`: a value out of range is a
    usage error naming the range, said before anything goes on the bus."""

    def convert(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or not low <= value <= high:
            raise argparse.ArgumentTypeError(
                f"must be a whole number from {low} to {high}, not {text!r}"
            )
        return value

    return convert


def _robot_namespace(text: str) -> tuple[str, str]:
    """argparse type for NAME=NAMESPACE."""
    name, equals, namespace = text.partition("=")
    if not equals:
        raise argparse.ArgumentTypeError(f"{text!r} is not NAME=NAMESPACE ('bot1=/bot1')")
    try:
        return robot_name(name), check_ros_name(namespace, "ROS namespace")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


def _bus_secrets(args: argparse.Namespace) -> int:
    from .bus_secrets import (
        DEFAULT_ROBOT,
        BusRobot,
        SecretsExist,
        holds_secrets,
        portable_client,
        write_bus_secrets,
    )

    directory = (args.directory or data_dir() / "bus").expanduser().resolve()
    if args.client is not None:
        try:
            print(portable_client(directory, args.client, args.endpoint), end="")
        except (OSError, ValueError) as exc:
            print(f"voicectl bus-secrets: {exc}", file=sys.stderr)
            return 1
        return 0
    if args.if_missing and holds_secrets(directory):
        print(f"bus secrets in {directory} kept: made before")
        return 0

    names = list(dict.fromkeys(args.robot or [DEFAULT_ROBOT]))
    namespaces = dict(args.namespace)
    strays = sorted(set(namespaces) - set(names))
    if strays:
        print(
            f"voicectl bus-secrets: --namespace names robot '{strays[0]}', which no --robot "
            f"names (robots: {', '.join(names)})",
            file=sys.stderr,
        )
        return 2
    robots = [BusRobot(name, namespaces.get(name, "")) for name in names]
    try:
        written = write_bus_secrets(directory, args.host, args.port, robots)
    except SecretsExist as exc:
        print(f"voicectl bus-secrets: {exc}", file=sys.stderr)
        return 1
    clients = [path.stem for path in written if path.suffix == ".json5" and path.stem != "router"]
    print(f"bus secrets in {directory} (keys, passwords and client configs mode 0600)")
    print(f"router: {voicectl_command('router', '--config', str(directory / 'router.json5'))}")
    print(f"clients: --config {directory}/<user>.json5 for {', '.join(clients)}")
    for robot in robots:
        scope = (
            f"the ROS keys under {robot.namespace}"
            if robot.namespace
            else "any robot's ROS keys (no --namespace)"
        )
        print(f"robot {robot.name}: its executor may say voice/{robot.name}/... and {scope}")
    return 0


def _cert(args: argparse.Namespace) -> int:
    from .cert import write_certificate

    directory = args.out or data_dir() / "tls"
    certfile, keyfile = directory / "panel.crt", directory / "panel.key"
    write_certificate(args.hosts, certfile, keyfile)
    mode = stat.S_IMODE(keyfile.stat().st_mode)  # what the file has, not what was meant
    print(f"certificate {certfile} for {', '.join(args.hosts)}; key {keyfile} (mode {mode:04o})")
    serve = ["up", "--host", "0.0.0.0", "--certfile", str(certfile), "--keyfile", str(keyfile)]
    print(f"serve with: {voicectl_command(*serve)}")
    return 0


def _parse(args: argparse.Namespace) -> int:
    from voicectl.services.converter.grammar import build_grammar
    from voicectl.services.converter.orders import OrderSet
    from voicectl.services.converter.parser import Parser

    if args.text is None and not args.grammar:
        print("voicectl parse: give a TEXT to parse, or --grammar", file=sys.stderr)
        return 2
    try:
        orders = OrderSet.load(args.orders, args.language)
    except OrdersFileError as exc:
        print(f"voicectl parse: {exc}", file=sys.stderr)
        return 2
    if args.grammar:
        _print_json(build_grammar(orders))
        return 0
    result = Parser(orders).parse(args.text)
    _print_json(result)
    return 0 if result.orders and not result.errors else 1


def _busy_ports(args: argparse.Namespace) -> str:
    """Why the stack cannot listen where it should (another stack runs), or ''."""
    scheme, _, address = args.router.partition("/")
    host, _, port = address.rpartition(":")
    if scheme == "tcp" and port.isdigit() and port_in_use(host.strip("[]"), int(port)):
        return f"{args.router} is in use: is another voicectl up or router running there?"
    if not args.no_web and port_in_use(args.host, args.port):
        return f"port {args.port} on {args.host} is in use (choose another with --port)"
    return ""


def _transcribe(args: argparse.Namespace) -> int:
    from voicectl.services.converter.grammar import build_grammar
    from voicectl.services.converter.orders import OrderSet
    from voicectl.services.converter.parser import Parser
    from voicectl.services.stt.engine import EngineError
    from voicectl.services.stt.load import load_engine

    from .transcribe import Unreadable, transcribe

    # A file that is not there is a mistake in the command line, said before the engine
    # loads; a file that is there but is no audio gets its own line among the others.
    missing = [str(path) for path in args.audio if not path.is_file()]
    if missing:
        print(f"voicectl transcribe: no such file: {', '.join(missing)}", file=sys.stderr)
        return 2
    try:
        orders = OrderSet.load(args.orders, args.language)
        engine = load_engine(engine_options(args))
    except (OrdersFileError, EngineError) as exc:
        print(f"voicectl transcribe: {exc}", file=sys.stderr)
        return 2
    failed = 0
    try:
        engine.use_grammar(build_grammar(orders))
        for line in transcribe(engine, Parser(orders), args.audio):
            failed += isinstance(line, Unreadable) or line.rejected
            print(_ENCODER.encode(line).decode(), flush=True)
    except EngineError as exc:
        print(f"voicectl transcribe: {exc}", file=sys.stderr)
        return 2
    finally:
        engine.close()
    return 1 if failed else 0


async def _say(args: argparse.Namespace) -> int:
    asked = Asked(via=Via.CLI, by=_who())
    try:
        with Bus.open(bus_options(args, wait=False), asyncio.get_running_loop()) as bus:
            said = await VoicectlClient(bus).say(
                args.robot,
                args.text,
                partial=args.partial,
                asked=asked,
                language=args.language,
            )
    except SayRefused as exc:
        # Refused is an answer too: the same JSON as any other, with what was understood
        # held back and why.
        _print_said(exc.result or ParseResult(), [], refused=str(exc))
        print(f"voicectl say: {exc}", file=sys.stderr)
        return 1
    except BusError as exc:  # no router, or no converter or supervisor answering
        print(f"voicectl say: {exc}", file=sys.stderr)
        return 3
    result = said.result
    done = Sent(order_ids=said.order_ids, answers=said.answers).done
    _print_said(result, said.order_ids, said.answers)
    # One line on stderr, for a person: the robot's answers, then what was not understood.
    parts = [answer.answer for answer in said.answers]
    problems = "; ".join(_unsaid(error) for error in result.errors)
    if done and problems:
        parts.append(f"submitted the rest; not understood: {problems}")
    elif not done and not said.answers:
        held = " (--partial submits what was understood)" if result.orders else ""
        why = f": {problems}" if problems else ""
        parts.append(f"nothing submitted{held}{why}")
    if parts:
        print(f"voicectl say: {' / '.join(parts)}", file=sys.stderr)
    # Exit status follows what happened: 0 when orders went to the robot (with --partial,
    # even though some words made none), the queue changed or a question was answered;
    # 1 when nothing happened (an edit refused: "there is no kitchen in the queue").
    return 0 if done else 1


def _who() -> str:
    """The person at this terminal, as the history keeps who asked: user@host."""
    try:
        user = getpass.getuser()
    except (KeyError, OSError):  # no such user in a container's passwd
        user = ""
    host = socket.gethostname()
    return f"{user}@{host}" if user else host


def _print_said(
    result: ParseResult,
    order_ids: list[str],
    answers: list[Answered] | None = None,
    refused: str | None = None,
) -> None:
    """`say`'s JSON, the same keys whatever happened. What went to the robot is under
    "orders"; what was understood and held back (or refused) is not printed as if it had
    been sent. `answers` are the supervisor's to the text's edits and questions."""
    sent = bool(order_ids) or bool(answers)
    _print_json(
        {
            "submitted": sent,
            "orders": result.orders if sent else [],
            "not_sent": [] if sent else result.orders,
            "errors": result.errors,
            "order_ids": order_ids,
            "answers": answers or [],
            "refused": refused,
        }
    )


def _unsaid(error: ParseProblem) -> str:
    """A part of a text that made no order, why, and what it may have meant."""
    maybe = [c for c in error.candidates if "/" not in c]  # phrases, not order names
    # The converter's reason may already end with the suggestion: say it once.
    unsaid = [phrase for phrase in maybe if phrase not in error.reason]
    hint = f", did you mean: {' or '.join(unsaid)}?" if unsaid else ""
    return f"{error.text!r}: {error.reason}{hint}"


async def _ask_supervisor(args: argparse.Namespace, request: Message) -> int:
    """Send one request to the robot's supervisor and print the answer as JSON."""
    try:
        with Bus.open(bus_options(args, wait=False), asyncio.get_running_loop()) as bus:
            reply = await VoicectlClient(bus).ask(args.robot, request)
    except Refused as exc:
        print(f"voicectl {args.command}: {exc.reason}", file=sys.stderr)
        return 1
    except BusError as exc:  # no router, or no supervisor answering
        print(f"voicectl {args.command}: {exc}", file=sys.stderr)
        return 3
    match reply:
        case StateReply(state=state):
            _print_json(_with_times(state))
        case _:
            _print_json(_with_times(reply))
    return 0


def _with_times(message: object) -> object:
    """`message` as JSON, every `..._at` epoch time followed by its ISO 8601 reading
    (`ended_at_iso`, local time with its offset): the epoch for scripts, the date for
    people."""

    def add(value: object) -> object:
        if isinstance(value, dict):
            out: dict[str, object] = {}
            for key, item in value.items():
                out[key] = add(item)
                if key.endswith("_at") and isinstance(item, int | float):
                    out[f"{key}_iso"] = (
                        datetime.datetime.fromtimestamp(item)
                        .astimezone()
                        .isoformat(timespec="seconds")
                    )
            return out
        if isinstance(value, list):
            return [add(item) for item in value]
        return value

    return add(msgspec.to_builtins(message))


async def _stop(args: argparse.Namespace) -> int:
    """STOP, through the supervisor or, when it does not answer, from here; prints what
    answered. Exit status 0 when the stop is confirmed, 4 when it was sent but not
    confirmed, 3 when nothing could be stopped."""
    try:
        with Bus.open(bus_options(args, wait=False), asyncio.get_running_loop()) as bus:
            stopped = await VoicectlClient(bus).stop(args.robot)
    except BusError as exc:
        print(f"voicectl stop: {exc}", file=sys.stderr)
        return 3
    _print_json(stopped)
    if not stopped.confirmed:
        print(f"voicectl stop: sent, but not confirmed: {stopped.detail}", file=sys.stderr)
        return 4
    return 0


def run() -> None:
    sys.exit(main())
