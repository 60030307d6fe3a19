"""A soak: the whole stack under a steady stream of orders, with every service's memory.

    .venv/bin/python -m bench.soak [--minutes 10] [--rate 3]

Starts `voicectl up` (simulator at x10, a data directory of its own, free ports) and, for
`--minutes`, sends `--rate` requests a second through the panel's HTTP API the way a
panel does: mostly short spoken-style commands through /api/say, some parses, state and
history reads, cancels, and every half minute a STOP and its release. Every minute it
samples the resident memory of each service from /proc. At the end it prints the RSS
table, the requests by answer, and every log line at WARNING or above (there should be
none beyond the STOPs' own), then stops the stack with SIGINT as a person would.
"""

from __future__ import annotations

import argparse
import collections
import json
import random
import time
import urllib.error
import urllib.request

from harness.processes import rss_mb
from harness.stack import children, stack_up

SAYINGS = (
    "turn left",
    "wait one second",
    "turn right then wait two seconds",
    "go forward one meter",
    "move back half a meter",
    "rotate left ninety degrees",
    "reach kitchen",
    "turn back",
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--rate", type=float, default=3.0, help="requests a second")
    parser.add_argument("--quick", action="store_true", help="half a minute")
    args = parser.parse_args()
    if args.quick:
        args.minutes = 0.5
    with stack_up("voicectl-soak-", "--time-scale", "10") as (up, lines, data, port, _router):
        token = (data / "token").read_text().strip()
        base = f"http://127.0.0.1:{port}"
        answers: collections.Counter[str] = collections.Counter()
        samples: list[tuple[float, dict[str, float]]] = []

        def call(path: str, body: object | None = None) -> object:
            request = urllib.request.Request(
                base + path,
                data=None if body is None else json.dumps(body).encode(),
                headers={"Authorization": f"Bearer {token}", "Content-Type": "application/json"},
                method="GET" if body is None else "POST",
            )
            try:
                with urllib.request.urlopen(request, timeout=30) as response:
                    answers[f"{path.split('?')[0]} {response.status}"] += 1
                    return json.loads(response.read())
            except urllib.error.HTTPError as exc:
                answers[f"{path.split('?')[0]} {exc.code}"] += 1
                return None

        started = time.monotonic()
        end = started + args.minutes * 60
        next_sample, next_stop = started, started + 30
        random.seed(1)
        while time.monotonic() < end:
            now = time.monotonic()
            if now >= next_sample:
                pids = children(up.pid)
                samples.append(((now - started) / 60, {n: rss_mb(p) for n, p in pids.items()}))
                next_sample += 60
            if now >= next_stop:
                call("/api/stop", {})
                call("/api/release", {})
                next_stop += 30
            roll = random.random()
            if roll < 0.6:
                call("/api/say", {"text": random.choice(SAYINGS)})
            elif roll < 0.75:
                call("/api/parse", {"text": random.choice(SAYINGS)})
            elif roll < 0.85:
                call("/api/state")
            elif roll < 0.95:
                call("/api/history?limit=20")
            else:
                call("/api/cancel_all", {})
            time.sleep(max(0.0, 1.0 / args.rate - (time.monotonic() - now)))
        pids = children(up.pid)
        samples.append(((time.monotonic() - started) / 60, {n: rss_mb(p) for n, p in pids.items()}))
    names = sorted({n for _, sample in samples for n in sample})
    print(f"soak: {args.minutes:g} min at {args.rate:g} requests/s, {time.strftime('%Y-%m-%d')}")
    print("minute " + " ".join(f"{n:>11}" for n in names) + "   (RSS, MB)")
    for minute, sample in samples:
        print(f"{minute:6.1f} " + " ".join(f"{sample.get(n, float('nan')):11.1f}" for n in names))
    print("answers: " + ", ".join(f"{k}: {v}" for k, v in sorted(answers.items())))
    worrying = [
        line
        for line in lines
        if any(level in line for level in (" WARNING ", " ERROR ", " CRITICAL ", "Traceback"))
        and "emergency stop" not in line
    ]
    print(f"log lines at WARNING or above, besides the STOPs': {len(worrying)}")
    for line in worrying[:40]:
        print("  " + line)
    print(f"voicectl up exited with {up.returncode}")


if __name__ == "__main__":
    main()
