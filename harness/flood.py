"""A flood of made-up robots on a router: for each of `--robots` names nobody configured,
an executor's liveliness token, its announcement (`ExecutorInfo`), an order's result and
(with `--owners`) a supervisor's owner token, held until SIGTERM or SIGINT. What issue 32
probed the supervisor with; the tests start it as a process of its own.

    python -m harness.flood --connect tcp/127.0.0.1:7447 --robots 5000 [--prefix fake] [--owners]

It prints "flooding: N robots" once everything is declared and sent.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading

import msgspec
import zenoh

from voicectl.shared.bus import BusOptions
from voicectl.shared.keys import RobotKeys
from voicectl.shared.messages import ExecutorInfo, OrderFinished, OrderStatus


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m harness.flood", description=__doc__)
    parser.add_argument("--connect", required=True, metavar="ENDPOINT")
    parser.add_argument("--robots", type=int, default=5000)
    parser.add_argument("--prefix", default="fake", help="names are PREFIX0, PREFIX1, ...")
    parser.add_argument("--owners", action="store_true", help="also hold owner tokens")
    args = parser.parse_args(argv)

    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda _sig, _frame: stop.set())
    encode = msgspec.json.encode
    info = encode(ExecutorInfo(namespace="made_up"))
    with zenoh.open(BusOptions(connect=[args.connect]).zenoh_config()) as session:
        tokens = []
        for i in range(args.robots):
            keys = RobotKeys(f"{args.prefix}{i}")
            tokens.append(session.liveliness().declare_token(keys.alive("executor")))
            if args.owners:
                tokens.append(session.liveliness().declare_token(keys.supervisor_owner("f0rged")))
            session.put(keys.executor_info, info)
            finished = OrderFinished(order_id=f"o{i}", status=OrderStatus.SUCCEEDED)
            session.put(keys.executor_events, encode(finished))
        print(f"flooding: {args.robots} robots", flush=True)
        stop.wait()
        for token in tokens:
            token.undeclare()
    return 0


if __name__ == "__main__":
    sys.exit(main())
