"""`voicectl`: one command for every service, the local stack and typed commands."""

from __future__ import annotations

import argparse
import asyncio
import importlib
import sys
import uuid
from pathlib import Path

import msgspec

from shared.bus import DEFAULT_ROUTER, Bus, BusOptions, add_bus_arguments, bus_options, json_decoder
from shared.config import default_token_file, load_or_create_token
from shared.errors import BusError, OrdersFileError
from shared.keys import ConverterKeys, RobotKeys, check_chunk
from shared.messages import (
    Failed,
    GetState,
    ParseReply,
    ParseRequest,
    StateReply,
    Submit,
    Submitted,
    SupervisorReply,
)

from .stack import Child, run_stack

SERVICES = ("router", "converter", "supervisor", "executor", "sim", "web")
REPO_ORDERS = Path(__file__).resolve().parents[1] / "orders" / "demo.yaml"
_ENCODER = msgspec.json.Encoder()


def _print_json(value: object) -> None:
    print(msgspec.json.format(_ENCODER.encode(value), indent=2).decode())


def _robot(name: str) -> str:
    return check_chunk(name, "robot name")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="voicectl",
        description="Voice control for robots. Services: "
        + ", ".join(SERVICES)
        + " (voicectl SERVICE --help).",
    )
    sub = parser.add_subparsers(dest="command", required=True)

    up = sub.add_parser("up", help="run the whole local stack with the simulator")
    up.add_argument("--router", default=DEFAULT_ROUTER, help="Zenoh endpoint of the router")
    up.add_argument("--host", default="127.0.0.1", help="panel address")
    up.add_argument("--port", type=int, default=8000, help="panel port")
    up.add_argument("--robot", type=_robot, default="robot")
    up.add_argument("--orders", type=Path, default=REPO_ORDERS, help="orders file or directory")
    up.add_argument("--time-scale", type=float, default=1.0, help="simulator speed-up")
    up.add_argument("--no-web", action="store_true", help="do not start the panel")
    up.add_argument(
        "--executor",
        action="append",
        default=[],
        metavar="MODULE:CLASS[=LABEL,...]",
        help="bind a user executor in the executor process (repeatable)",
    )

    parse = sub.add_parser("parse", help="print the orders a text becomes, as JSON")
    parse.add_argument("--orders", type=Path, default=REPO_ORDERS, help="orders file or directory")
    parse.add_argument("text")

    say = sub.add_parser("say", help="convert a text on the bus and submit its orders")
    say.add_argument("--robot", type=_robot, default="robot")
    add_bus_arguments(say)
    say.add_argument("text")

    state = sub.add_parser("state", help="print the supervisor's state as JSON")
    state.add_argument("--robot", type=_robot, default="robot")
    add_bus_arguments(state)

    token = sub.add_parser("token", help="print the panel's API token (creating it if needed)")
    token.add_argument("--token-file", type=Path, default=None)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] in SERVICES:
        module = importlib.import_module(f"services.{argv[0]}.__main__")
        result: int = asyncio.run(module.main(argv[1:]))
        return result
    args = build_parser().parse_args(argv)
    match args.command:
        case "up":
            return _up(args)
        case "parse":
            return _parse(args)
        case "say":
            return asyncio.run(_say(args))
        case "state":
            return asyncio.run(_state(args))
        case "token":
            print(load_or_create_token(args.token_file or default_token_file()))
            return 0
    return 2


def _up(args: argparse.Namespace) -> int:
    connect = ["--connect", args.router]
    robot = ["--robot", args.robot]
    children = [
        Child("router", ["services.router", "--listen", args.router]),
        Child("converter", ["services.converter", "--orders", str(args.orders), *connect]),
        Child("supervisor", ["services.supervisor", *robot, *connect]),
        Child(
            "executor",
            ["services.executor", *robot, *connect]
            + [arg for spec in args.executor for arg in ("--executor", spec)],
        ),
        Child("sim", ["services.sim", "--time-scale", str(args.time_scale), *connect]),
    ]
    web = None
    if not args.no_web:
        load_or_create_token(default_token_file())
        port = ["--port", str(args.port), "--host", args.host]
        children.append(Child("web", ["services.web", *robot, *port, *connect]))
        web = (args.host, args.port)
    keys = RobotKeys(args.robot)
    ready = [ConverterKeys().alive, keys.alive("supervisor"), keys.alive("executor")]
    return run_stack(children, web, args.router, ready)


def _parse(args: argparse.Namespace) -> int:
    from services.converter.orders import OrderSet
    from services.converter.parser import Parser

    try:
        orders = OrderSet.load(args.orders)
    except OrdersFileError as exc:
        print(f"voicectl parse: {exc}", file=sys.stderr)
        return 2
    _print_json(Parser(orders).parse(args.text))
    return 0


async def _say(args: argparse.Namespace) -> int:
    options: BusOptions = bus_options(args)
    keys = RobotKeys(args.robot)
    with Bus.open(options, asyncio.get_running_loop()) as bus:
        try:
            parsed = await bus.request(
                ConverterKeys().parse,
                ParseRequest(text=args.text),
                json_decoder(ParseReply | Failed),
                timeout=5.0,
            )
            if isinstance(parsed, Failed):
                print(f"voicectl say: converter: {parsed.reason}", file=sys.stderr)
                return 1
            result = parsed.result
            order_ids: list[str] = []
            if result.orders:
                reply = await bus.request(
                    keys.supervisor,
                    Submit(request_id=uuid.uuid4().hex, orders=result.orders, transcript=args.text),
                    json_decoder(SupervisorReply),
                    timeout=5.0,
                )
                if not isinstance(reply, Submitted):
                    print(f"voicectl say: supervisor: {reply}", file=sys.stderr)
                    return 1
                order_ids = reply.order_ids
        except BusError as exc:
            print(f"voicectl say: {exc}", file=sys.stderr)
            return 3
    _print_json({"orders": result.orders, "errors": result.errors, "order_ids": order_ids})
    return 0 if result.orders and not result.errors else 1


async def _state(args: argparse.Namespace) -> int:
    keys = RobotKeys(args.robot)
    with Bus.open(bus_options(args), asyncio.get_running_loop()) as bus:
        try:
            reply = await bus.request(
                keys.supervisor, GetState(), json_decoder(SupervisorReply), timeout=5.0
            )
        except BusError as exc:
            print(f"voicectl state: {exc}", file=sys.stderr)
            return 3
    if not isinstance(reply, StateReply):
        print(f"voicectl state: unexpected reply {reply}", file=sys.stderr)
        return 1
    _print_json(reply.state)
    return 0


def run() -> None:
    sys.exit(main())
