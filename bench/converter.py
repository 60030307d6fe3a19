"""Benchmark the converter's parser against Home Assistant's hassil on the same sentences.

    .venv/bin/python -m bench.converter [--orders-count 200] [--rounds 5]

Prints parses per second and p50/p99 latency per utterance for a generated orders file and
for orders/demo.yaml, each with hassil on an equivalent template set, and the ratio.
Not a test: numbers depend on the machine (recorded in docs/benchmarks.md).
"""

from __future__ import annotations

import argparse
import os
import platform
import random
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from hassil import Intents, recognize

from bench.orders_gen import UNRELATED, generate, near_misses
from voicectl.services.converter.grammar import build_grammar
from voicectl.services.converter.orders import OrderSet
from voicectl.services.converter.parser import Parser

REPO = Path(__file__).resolve().parents[1]

DEMO_HASSIL = {
    "language": "en",
    "intents": {
        "rotation/left": {"data": [{"sentences": ["turn left"]}]},
        "rotation/right": {"data": [{"sentences": ["turn right"]}]},
        "rotation/back": {"data": [{"sentences": ["turn back[ward]"]}]},
        "goal/base": {"data": [{"sentences": ["reach base"]}]},
        "goal/bathroom": {"data": [{"sentences": ["reach bathroom"]}]},
        "goal/kitchen": {"data": [{"sentences": ["reach kitchen"]}]},
        "goal/dumpster": {"data": [{"sentences": ["reach dumpster"]}]},
        "local_goal/forward": {"data": [{"sentences": ["move (forward|straight)"]}]},
        "local_goal/back": {"data": [{"sentences": ["move back[ward]"]}]},
    },
}
DEMO_SENTENCES = [
    "turn left",
    "turn right",
    "turn back",
    "turn backward",
    "reach base",
    "reach bathroom",
    "reach kitchen",
    "reach dumpster",
    "move forward",
    "move straight",
    "move back",
    "move backward",
    "reach kitchn",
    "turn lift",
    *UNRELATED,
]


@dataclass
class Stats:
    per_second: float
    p50_us: float
    p99_us: float
    cpu_p50_us: float
    cpu_p99_us: float

    def line(self, name: str) -> str:
        return (
            f"{name:<36} {self.per_second:>9,.0f}/s  wall p50 {self.p50_us:>7.1f} "
            f"p99 {self.p99_us:>7.1f} µs  cpu p50 {self.cpu_p50_us:>7.1f} "
            f"p99 {self.cpu_p99_us:>7.1f} µs"
        )


def measure(func: Callable[[str], object], sentences: list[str], rounds: int) -> Stats:
    """Time every call separately, in wall time and in this thread's CPU time (which other
    processes on a shared machine disturb less); the first round warms up, uncounted."""
    wall: list[int] = []
    cpu: list[int] = []
    for round_ in range(rounds + 1):
        for sentence in sentences:
            start_cpu = time.thread_time_ns()
            start = time.perf_counter_ns()
            func(sentence)
            end = time.perf_counter_ns()
            end_cpu = time.thread_time_ns()
            if round_:
                wall.append(end - start)
                cpu.append(end_cpu - start_cpu)
    wall.sort()
    cpu.sort()

    def at(values: list[int], share: float) -> float:
        return values[min(len(values) - 1, int(len(values) * share))] / 1000

    return Stats(
        per_second=1e9 / statistics.fmean(wall),
        p50_us=at(wall, 0.5),
        p99_us=at(wall, 0.99),
        cpu_p50_us=at(cpu, 0.5),
        cpu_p99_us=at(cpu, 0.99),
    )


def machine() -> str:
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{model}, {os.cpu_count()} CPUs, Python {platform.python_version()}"


def compare(
    title: str, orders: OrderSet, hassil_dict: dict[str, object], same: list[str], rounds: int
) -> None:
    parser = Parser(orders)
    intents = Intents.from_dict(hassil_dict)
    ours_hits = sum(bool(parser.parse(s).orders) for s in same)
    theirs_hits = sum(recognize(s, intents) is not None for s in same)
    print(f"\n== {title}: {len(orders.orders)} orders, {len(orders.commands)} commands")
    print(f"   {len(same)} sentences; understood: voicectl {ours_hits}, hassil {theirs_hits}")
    ours = measure(parser.parse, same, rounds)
    theirs = measure(lambda s: recognize(s, intents), same, max(1, rounds // 5))
    print(ours.line("voicectl Parser.parse"))
    print(theirs.line("hassil recognize"))
    throughput = ours.per_second / theirs.per_second
    p99 = theirs.p99_us / ours.p99_us
    cpu_p99 = theirs.cpu_p99_us / ours.cpu_p99_us
    print(
        f"   voicectl/hassil: {throughput:.1f}x the throughput, "
        f"p99 {p99:.1f}x lower (cpu {cpu_p99:.1f}x)"
    )


def main() -> int:
    args = argparse.ArgumentParser(description=__doc__)
    args.add_argument("--orders-count", type=int, default=200)
    args.add_argument("--rounds", type=int, default=5)
    args.add_argument("--quick", action="store_true", help="one round")
    options = args.parse_args()
    if options.quick:
        options.rounds = 1
    rng = random.Random(1)
    print(f"machine: {machine()}")

    generated = generate(options.orders_count)
    started = time.perf_counter()
    orders = OrderSet.from_yaml(generated.orders_yaml, "generated.yaml")
    loaded = time.perf_counter()
    grammar = build_grammar(orders)
    built = time.perf_counter()
    print(
        f"generated file: load+validate {1000 * (loaded - started):.0f} ms, grammar "
        f"{1000 * (built - loaded):.0f} ms ({len(grammar.phrases)} phrases, "
        f"{len(grammar.jsgf) // 1024} KiB JSGF)"
    )
    singles = generated.commands
    misses = near_misses(singles, rng, len(singles) // 5)
    same = [*singles, *misses, *UNRELATED * 5]
    compare("generated orders, same sentences", orders, generated.hassil, same, options.rounds)

    sequences = [f"{rng.choice(singles)} then {rng.choice(singles)}" for _ in range(200)]
    mix = [*singles, *sequences, *misses, *UNRELATED * 5]
    print(f"\n== generated orders, voicectl only: {len(mix)} sentences with 200 sequences")
    print(measure(Parser(orders).parse, mix, options.rounds).line("with first-word index"))
    unindexed = Parser(orders, use_index=False)
    print(measure(unindexed.parse, mix, 1).line("without index (every regex tried)"))
    print(measure(Parser(orders).parse, misses, options.rounds).line("near-misses only"))

    demo = OrderSet.load(REPO / "orders" / "demo.yaml")
    compare("orders/demo.yaml", demo, DEMO_HASSIL, DEMO_SENTENCES, options.rounds * 20)
    return 0


if __name__ == "__main__":
    sys.exit(main())
