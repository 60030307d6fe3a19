"""Speech in a language one ear hears alone (Spanish, German): wrong orders, confirmations,
non-commands refused, end of speech to decision, per language and condition.

    .venv/bin/python -m bench.languages --language es --split dev [--limit 60] [--features]

The set is harness/speech_languages.py's (generated into --set when missing). Each file is
streamed through the recogniser in this process as a microphone sends it, 20 ms frames,
the last `--paced` seconds of speech and the silence after it at real-time pace (the rest
at once), heard by the `whisper` engine in the file's language (Whisper alone: the
grammar's ear and Moonshine hear English only), and decided as the converter decides
(decide.py), under the shipped rule or `--rule evidence`. A command is:

- right: the orders it says, sent by themselves;
- confirmed: the orders it says, read back for a yes (counted apart);
- wrong: other orders sent by themselves (the target is none);
- offered wrong: other orders read back for a yes (the person says no);
- refused: nothing.

`--features` also prints, per utterance, the evidence the one ear has of its own words, to
choose the rule on dev: its confidence, its no-speech probability, whether its second
decode (prompted with the orders' words) made the same orders, and its likelihood of the
parsed sentence (the orders' words as the parser read them, numbers in words) beside its
own words, in nats a token.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import re
import time
from dataclasses import dataclass, field
from pathlib import Path

from harness.measure import percentile
from harness.speech_languages import LANGUAGES, Spoken, generate
from voicectl.services.converter.decide import SHIPPED, Decision, Rule, decide, readings
from voicectl.services.converter.grammar import build_grammar
from voicectl.services.converter.orders import OrderSet
from voicectl.services.converter.parser import Parser
from voicectl.services.converter.text import normalise
from voicectl.services.stt.audio import frames, read_wav
from voicectl.services.stt.ears import Ears, load_three, written
from voicectl.services.stt.engine import EngineOptions, Final
from voicectl.services.stt.service import transcript_of
from voicectl.shared.config import cache_dir
from voicectl.shared.messages import Order

REPO = Path(__file__).resolve().parents[1]
FRAME = 0.02


@dataclass
class Outcome:
    spoken: Spoken
    decision: Decision | None = None
    final: Final | None = None
    latency: float | None = None
    """Seconds from the end of the speech (its last frame fed) to the decision."""
    features: dict[str, object] = field(default_factory=dict)


def verdict(outcome: Outcome, parser: Parser) -> str:
    """right, confirmed, wrong, offered wrong or refused (a command); refused, confirmed
    or accepted (a non-command)."""
    decision = outcome.decision
    if decision is None or decision.rejected or not decision.orders:
        return "refused"
    asked = decision.confirm or bool(decision.doubts)
    if not outcome.spoken.command:
        return "confirmed" if asked else "accepted"
    expected = parser.parse(outcome.spoken.text).orders
    same = same_orders(decision.orders, expected)
    if asked:
        return "confirmed" if same else "offered wrong"
    return "right" if same else "wrong"


def same_orders(made: list[Order], expected: list[Order]) -> bool:
    """The same orders, the descriptions aside (one ear's words, another's)."""
    return [(o.order, o.case, o.params, o.target_pose) for o in made] == [
        (o.order, o.case, o.params, o.target_pose) for o in expected
    ]


def hear(
    engine: Ears, parser: Parser, spoken: Spoken, directory: Path, paced: float, rule: Rule
) -> Outcome:
    """One file streamed through a recogniser in its language, decided."""
    pcm = read_wav(directory / spoken.file)
    recogniser = engine.recogniser(15.0, True, spoken.language)
    outcome = Outcome(spoken)
    fast_until = max(0.0, spoken.speech_end - paced)
    clock = 0.0
    ended_at: float | None = None
    started = time.perf_counter()
    try:
        for frame in frames(pcm):
            clock += FRAME
            if clock > fast_until:
                due = started + (clock - fast_until)
                time.sleep(max(0.0, due - time.perf_counter()))
            if ended_at is None and clock >= spoken.speech_end:
                ended_at = time.perf_counter()
            for event in recogniser.accept(frame):
                if isinstance(event, Final) and outcome.final is None:
                    outcome.final = event
                    _decided(outcome, parser, rule, ended_at)
        if outcome.final is None:
            for event in recogniser.finish():
                if isinstance(event, Final) and outcome.final is None:
                    outcome.final = event
                    _decided(outcome, parser, rule, ended_at)
    finally:
        recogniser.close()
    return outcome


def _decided(outcome: Outcome, parser: Parser, rule: Rule, ended_at: float | None) -> None:
    assert outcome.final is not None
    transcript = transcript_of(outcome.final, language=parser.orders.language)
    outcome.decision = decide(*readings(transcript, parser), rule=rule)
    if ended_at is not None:
        outcome.latency = time.perf_counter() - ended_at


def features(engine: Ears, parser: Parser, outcome: Outcome) -> None:
    """The one ear's evidence of its own words, for choosing the rule on dev."""
    final = outcome.final
    heard = final.transcription if final is not None else None
    if heard is None or not heard.text:
        return
    found = {
        "text": heard.text,
        "confidence": heard.confidence,
        "no_speech": heard.no_speech,
        "second": heard.second,
    }
    result = parser.parse(parser.spell_units(heard.text))
    whisper = engine._third  # the bench weighs the model itself
    if whisper is not None and result.orders and not result.errors:
        pcm = read_wav(directory_of[outcome.spoken.file])
        again = whisper.transcribe(pcm, parser.orders.language)
        sentence = _in_words(normalise(parser.spell_units(heard.text)), parser)
        own = math.log(max(again.confidence, 1e-12))
        found["parsed"] = sentence
        found["support"] = round(
            whisper.likelihood(again, written(sentence), parser.orders.language) - own, 3
        )
    outcome.features = found


directory_of: dict[str, Path] = {}


def _in_words(text: str, parser: Parser) -> str:
    """Digits as the language says them ("30" -> "treinta")."""
    say = parser.orders.numbers.say
    return re.sub(r"(?<!\S)\d+(?:\.\d+)?(?!\S)", lambda m: say(float(m.group(0))), text)


def report(outcomes: list[Outcome], parser: Parser, title: str) -> None:
    print(title)
    print(
        f"  {'condition':<16}{'right':>12}{'confirmed':>11}{'wrong':>7}{'offered wrong':>15}"
        f"{'non-commands refused':>22}{'confirmed':>11}{'p50':>7}{'p95':>7}"
    )
    groups: dict[str, list[Outcome]] = {}
    for outcome in outcomes:
        key = f"{outcome.spoken.source} {outcome.spoken.condition}"
        groups.setdefault(key, []).append(outcome)
        groups.setdefault(outcome.spoken.condition, []).append(outcome)
    for condition, group in [*sorted(groups.items()), ("all", outcomes)]:
        commands = [o for o in group if o.spoken.command]
        chatter = [o for o in group if not o.spoken.command]
        count = {
            name: sum(verdict(o, parser) == name for o in commands)
            for name in ("right", "confirmed", "wrong", "offered wrong")
        }
        refused = sum(verdict(o, parser) == "refused" for o in chatter)
        asked = sum(verdict(o, parser) == "confirmed" for o in chatter)
        latencies = [o.latency for o in group if o.latency is not None]
        n = max(len(commands), 1)
        print(
            f"  {condition:<16}"
            f"{count['right']:>3}/{len(commands):<3}{100 * count['right'] / n:4.0f} %"
            f"{count['confirmed']:>6} ({100 * (count['right'] + count['confirmed']) / n:3.0f} %)"
            f"{count['wrong']:>4}{count['offered wrong']:>12}"
            f"{refused:>12}/{len(chatter):<3}{100 * refused / max(len(chatter), 1):5.1f} %"
            f"{asked:>8}"
            + (
                f"{1e3 * percentile(latencies, 0.5):6.0f}{1e3 * percentile(latencies, 0.95):7.0f}"
                if latencies
                else ""
            )
        )
    for outcome in outcomes:
        said = verdict(outcome, parser)
        if said in ("wrong", "offered wrong", "accepted") or (
            not outcome.spoken.command and said == "confirmed"
        ):
            decision = outcome.decision
            print(
                f"    {said}: {outcome.spoken.voice} {outcome.spoken.condition} "
                f"{outcome.spoken.text!r} -> {decision.text if decision else ''!r}"
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--language", choices=LANGUAGES, default="es")
    parser.add_argument("--split", choices=("dev", "test"), default="dev")
    parser.add_argument("--set", type=Path, default=cache_dir() / "speech-languages")
    parser.add_argument("--limit", type=int, default=60, help="utterances at most (default 60)")
    parser.add_argument("--condition", action="append", help="clean, pink10 (default both)")
    parser.add_argument("--paced", type=float, default=1.0, metavar="S")
    parser.add_argument("--rule", choices=("confirm", "evidence"), default=SHIPPED.alone)
    parser.add_argument("--features", action="store_true")
    args = parser.parse_args()

    utterances = [
        s
        for s in generate(args.set, [args.language], [args.split])
        if s.condition in (args.condition or ["clean", "pink10"])
    ]
    # An even sample over the set (sentences, voices and conditions alike), at most --limit.
    step = max(1, math.ceil(len(utterances) / args.limit))
    chosen = utterances[::step][: args.limit]
    for spoken in chosen:
        directory_of[spoken.file] = args.set / spoken.file
    orders = OrderSet.load(REPO / "orders", args.language)
    text_parser = Parser(orders)
    engine = load_three(EngineOptions(name="whisper"))
    try:
        engine.use_grammar(build_grammar(orders))
        rule = Rule(alone=args.rule)
        load = os.getloadavg()
        started = time.perf_counter()
        outcomes = [hear(engine, text_parser, s, args.set, args.paced, rule) for s in chosen]
        if args.features:
            for outcome in outcomes:
                features(engine, text_parser, outcome)
                print(
                    f"  {verdict(outcome, text_parser):<13} {outcome.spoken.command:d} "
                    f"{outcome.spoken.source:<7}{outcome.spoken.condition:<7}"
                    f"{outcome.spoken.text!r:<50} {outcome.features}"
                )
    finally:
        engine.close()
    print(
        f"\n{args.language} {args.split}: {len(chosen)} of {len(utterances)} utterances, rule "
        f"{args.rule}; {platform.node()}, {os.cpu_count()} cores, load {load[0]:.1f} at start; "
        f"{time.perf_counter() - started:.0f} s; {time.strftime('%Y-%m-%d')}"
    )
    report(outcomes, text_parser, "")


if __name__ == "__main__":
    main()
