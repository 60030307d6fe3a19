"""A generated orders file of any size, the equivalent hassil intents, and test sentences.

Used by bench/converter.py. Deterministic for a seed. The shapes mimic real orders files:
verbs with optional articles and cases (most orders), whole-phrase orders without cases,
and orders with a spoken number. Several orders share a first word, as they do in practice.
"""

from __future__ import annotations

import random
from dataclasses import dataclass, field
from typing import Any

import yaml

# fmt: off
VERBS = [
    "reach", "fetch", "bring", "open", "close", "scan", "inspect", "clean", "check", "carry",
    "lift", "drop", "push", "pull", "follow", "find", "guard", "light", "load", "unload", "mark",
    "measure", "paint", "patrol", "photograph", "pick", "place", "record", "repair", "sort",
    "stack", "sweep", "tidy", "track", "visit", "wash", "water", "weigh", "wipe", "wrap",
    "count", "dock",
]
THINGS = [
    "kitchen", "garage", "door", "shelf", "table", "chair", "window", "box", "crate", "pallet",
    "ramp", "gate", "corridor", "office", "lab", "desk", "bench", "cabinet", "drawer", "fridge",
    "oven", "sink", "counter", "bin", "bucket", "cart", "trolley", "ladder", "panel", "switch",
    "valve", "pump", "tank", "pipe", "hose", "cable", "rack", "bay", "dock", "yard", "lawn",
    "garden", "porch", "hall", "stairs", "lift", "tray", "cup", "bottle", "plate", "bowl",
    "towel", "mop", "broom", "lamp", "sensor", "camera", "charger", "battery", "printer",
    "screen", "keyboard", "badge", "parcel", "letter", "package", "basket", "pillow", "blanket",
    "carpet", "curtain", "mirror", "plant", "vase", "book", "folder", "tool", "drill", "hammer",
    "wrench",
]
# fmt: on
UNRELATED = [
    "what is the weather today",
    "play some music",
    "tell me a joke",
    "how are you doing",
    "set an alarm for seven",
    "who won the game last night",
]


@dataclass
class Generated:
    orders_yaml: str
    hassil: dict[str, Any]
    """hassil's intents dict: one intent per command, equivalent templates."""
    commands: list[str] = field(default_factory=list)
    """One sample sentence per command."""


def generate(n_orders: int = 200, seed: int = 7) -> Generated:
    rng = random.Random(seed)
    orders: dict[str, Any] = {}
    intents: dict[str, Any] = {}
    samples: list[str] = []
    used: set[tuple[str, str]] = set()

    def pick_pair() -> tuple[str, str]:
        while True:
            pair = (rng.choice(VERBS), rng.choice(THINGS))
            if pair not in used:
                used.add(pair)
                return pair

    for i in range(n_orders):
        name = f"o{i:03d}"
        kind = rng.random()
        if kind < 0.6:
            verb = rng.choice(VERBS)
            things = []
            while len(things) < rng.randint(2, 5):
                thing = rng.choice(THINGS)
                if (verb, thing) not in used:
                    used.add((verb, thing))
                    things.append(thing)
            orders[name] = {
                "voice_alias": f"{verb}( the)?",
                "description": verb,
                "label": "bench",
                "cases": {t: {"voice_alias": t, "target": t} for t in things},
            }
            for thing in things:
                intents[f"{name}/{thing}"] = {"data": [{"sentences": [f"{verb} [the] {thing}"]}]}
                samples.append(f"{verb} the {thing}" if rng.random() < 0.5 else f"{verb} {thing}")
        elif kind < 0.85:
            verb, thing = pick_pair()
            orders[name] = {
                "voice_alias": f"(please )?{verb} (the )?{thing}( now)?",
                "description": f"{verb} {thing}",
                "label": "bench",
            }
            intents[name] = {"data": [{"sentences": [f"[please] {verb} [the] {thing} [now]"]}]}
            samples.append(f"please {verb} the {thing}")
        else:
            verb, thing = pick_pair()
            orders[name] = {
                "voice_alias": f"{verb} {{count}} {thing}s?",
                "description": f"{verb} {{count}} {thing}",
                "label": "bench",
                "slots": {"count": {"type": "integer", "min": 1, "max": 20}},
            }
            intents[name] = {"data": [{"sentences": [f"{verb} {{count}} {thing}[s]"]}]}
            number = rng.randint(1, 20)
            samples.append(f"{verb} {number} {thing}s")
    orders_yaml = yaml.safe_dump({"orders_list": {"separator": "then", "orders": orders}})
    hassil = {
        "language": "en",
        "intents": intents,
        "lists": {"count": {"range": {"from": 1, "to": 20}}},
    }
    return Generated(orders_yaml, hassil, samples)


def near_misses(samples: list[str], rng: random.Random, count: int) -> list[str]:
    """Sentences a recogniser could make of commands: a word swapped, dropped or added."""
    out = []
    for sentence in rng.sample(samples, min(count, len(samples))):
        words = sentence.split()
        match rng.randrange(3):
            case 0:
                i = rng.randrange(len(words))
                words[i] = words[i][:-1] + "e" if len(words[i]) > 3 else words[i]
            case 1 if len(words) > 2:
                del words[rng.randrange(len(words))]
            case _:
                words.insert(rng.randrange(len(words) + 1), "uh")
        out.append(" ".join(words))
    return out
