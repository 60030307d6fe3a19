"""Hearing only commands: real recordings of people, values out of range, the judge's rules.

The recordings are pocketsphinx's own test data (a man saying "go forward ten meters",
read literature from LibriVox, card names), fetched from PyPI once per run.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pocketsphinx
import pytest

from harness.speech_set import pink_noise
from voicectl.services.converter.grammar import build_grammar
from voicectl.services.converter.orders import OrderSet
from voicectl.services.stt import sphinx
from voicectl.services.stt.audio import Loudness, Suppressor, frames, read_wav
from voicectl.services.stt.engine import EngineOptions, Final, finals
from voicectl.services.stt.judge import OFF, Thresholds, Vocabulary, Word, judge
from voicectl.services.stt.load import load_engine
from voicectl.shared.edits import QUEUE_LABEL

from .conftest import Speak, voicectl


def transcribe(*files: Path) -> list[dict[str, object]]:
    done = voicectl("transcribe", *map(str, files))
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    # Exit status 1 says some file was rejected; each line says which.
    assert done.returncode == (1 if any(line["rejected"] for line in lines) else 0), done.stderr
    return lines


def test_a_person_saying_ten_metres_is_heard_as_ten_never_as_two(
    people: dict[str, Path],
) -> None:
    [line] = transcribe(people["real-goforward"])
    orders = line["orders"]
    assert isinstance(orders, list)
    doubts = line["doubts"]
    assert isinstance(doubts, list)
    if doubts:  # asked, never sent by itself: ten must be one of the choices
        assert any("ten" in [d["words"], *d["alternatives"]] for d in doubts)
    else:
        assert line["rejected"] is False, line
        [order] = orders
        assert order["order"] == "drive"
        assert order["target_pose"]["x"] == 10.0


def test_read_literature_and_card_names_become_no_orders(people: dict[str, Path]) -> None:
    reading = people["real-sense_and_sensibility_01_austen_64kb-0890"]
    cards = people["real-005"]
    for line in transcribe(reading, cards):
        assert line["rejected"] is True, line
        assert line["doubts"] == []


def test_a_value_out_of_range_is_refused_by_name_not_heard_as_a_neighbour(
    speech: Speak,
) -> None:
    [line] = transcribe(speech("go forward twenty meters", "festival:kal_diphone"))
    said = str(line["transcript"]).replace("metres", "meters")
    assert said in ("go forward twenty meters", "go forward 20 meters"), line
    assert line["rejected"] is True
    assert "out of range: 0.1 to 10 m" in str(line["reason"])


# --- the judge's rules, on made-up decodes ----------------------------------------------

_DECODER = pocketsphinx.Decoder(loglevel="FATAL", lm=None)


def _sounds(word: str) -> frozenset[str]:
    found, variant = set(), 1
    while (
        phones := _DECODER.lookup_word(word if variant == 1 else f"{word}({variant})")
    ) is not None:
        found.add(phones)
        variant += 1
    return frozenset(found)


VOCABULARY = Vocabulary(
    words=frozenset(
        ["go", "forward", "move", "back", "turn", "left", "ten", "two", "meters", "the", "a", "to"]
    ),
    skip_words=frozenset({"the", "a", "to"}),
    number_words=frozenset({"ten", "two"}),
    sounds=_sounds,
)


def words(text: str, posterior: float = 0.9) -> list[Word]:
    """`text` one word per 30 frames."""
    return [Word(w, 30 * i, 30 * i + 29, posterior) for i, w in enumerate(text.split())]


def timed(*ends: tuple[str, int]) -> list[Word]:
    """Words heard surely (posterior 1), each from the frame after the last one's end."""
    starts = [0] + [end + 1 for _, end in ends[:-1]]
    return [Word(w, start, end, 1.0) for (w, end), start in zip(ends, starts, strict=True)]


def test_the_judge_accepts_what_both_decodes_heard() -> None:
    verdict = judge(
        words("go forward ten meters"), words("go forward ten meters"), VOCABULARY, Thresholds()
    )
    assert verdict.rejection == ""
    assert verdict.doubts == []
    assert all(c > 0.5 for c in verdict.confidences)


def test_the_judge_asks_about_a_number_the_open_decode_heard_otherwise() -> None:
    verdict = judge(
        words("go forward two meters"), words("go forward ten meters"), VOCABULARY, Thresholds()
    )
    assert verdict.rejection == ""
    [doubt] = verdict.doubts
    assert (doubt.position, doubt.words, doubt.alternatives) == (2, "two", ["ten"])


def test_the_judge_hears_for_as_four_and_to_as_two() -> None:
    vocabulary = Vocabulary(
        VOCABULARY.words | {"four"}, VOCABULARY.skip_words, frozenset({"two", "four"}), _sounds
    )
    verdict = judge(
        words("move back two meters"), words("move back to meters"), vocabulary, Thresholds()
    )
    assert verdict.doubts == []
    assert verdict.rejection == ""


def test_the_judge_rejects_conversation_with_what_it_heard() -> None:
    verdict = judge(
        words("move back two meters"),
        words("could you please pass me the salt"),
        VOCABULARY,
        Thresholds(),
    )
    assert verdict.rejection == "I heard 'could you please pass me the salt': not a command"


def test_foreign_words_that_sound_like_the_command_weigh_little() -> None:
    # Flite's "reach the dumpster": the open decode spelled it "reach the dumps there".
    vocabulary = Vocabulary(
        frozenset(["reach", "the", "dumpster", "turn", "left"]),
        frozenset({"the", "a"}),
        frozenset(),
        _sounds,
    )
    grammar = words("reach the dumpster")
    heard = timed(("reach", 29), ("the", 59), ("dumps", 79), ("there", 89))
    verdict = judge(grammar, heard, vocabulary, Thresholds())
    assert verdict.rejection == ""
    # Two foreign words, each of posterior 1: counted in full they would weigh 2.0. The
    # stretch "dumps there" sounds 62.5 % like "dumpster" (3 phones of 8 differ).
    assert verdict.foreign == pytest.approx(0.75)
    # "turn on the lights" is not "turn a left": its foreign words sound unlike "a left".
    grammar = words("turn a left")
    heard = timed(("turn", 29), ("on", 44), ("the", 59), ("lights", 89), ("[NOISE]", 99))
    verdict = judge(grammar, heard, vocabulary, Thresholds(max_foreign=1.0))
    assert verdict.rejection == "I heard 'turn on the lights': not a command"
    assert verdict.heard == "turn on the lights"  # markers are no words


def test_the_judge_rejects_a_command_word_the_grammar_was_unsure_of() -> None:
    # "drive back one meter" in a reverberant room: the grammar's lattice gave "ahead" 0.58.
    grammar = words("move forward ten meters")
    grammar[1] = Word("forward", grammar[1].start, grammar[1].end, 0.58)
    verdict = judge(grammar, words("move ten meters"), VOCABULARY, Thresholds())
    assert verdict.rejection == "not sure I heard 'forward': say it again"
    # The open decode hearing the word too is enough.
    verdict = judge(grammar, words("move forward ten meters"), VOCABULARY, Thresholds())
    assert verdict.rejection == ""
    assert verdict.confidences[1] == 0.9


def test_the_judge_doubts_a_value_the_grammar_was_unsure_of() -> None:
    grammar = words("go forward ten meters")
    grammar[2] = Word("ten", grammar[2].start, grammar[2].end, 0.6)
    verdict = judge(grammar, words("go forward ten meters"), VOCABULARY, Thresholds())
    assert verdict.rejection == ""
    [doubt] = verdict.doubts
    assert (doubt.position, doubt.words, doubt.alternatives, doubt.confidence) == (
        2,
        "ten",
        [],
        0.6,
    )


def test_the_judge_rejects_a_word_the_search_squeezed_in() -> None:
    # "on the left" came out of the grammar as "turn the left", its "the" (two phones) six
    # frames long: the shortest a path can make it, three frames a phone.
    heard = timed(("on", 20), ("the", 31), ("left", 70))
    squeezed = timed(("turn", 25), ("the", 31), ("left", 70))
    verdict = judge(squeezed, heard, VOCABULARY, Thresholds())
    assert verdict.rejection == "I heard 'on the left': not a command"
    # One frame more, and it could have been said.
    said = timed(("turn", 24), ("the", 31), ("left", 70))
    assert judge(said, heard, VOCABULARY, Thresholds()).rejection == ""
    # The grammar alone (the benchmark's comparison) keeps no such rule.
    assert judge(squeezed, heard, VOCABULARY, OFF).rejection == ""


# --- where an utterance ends ---------------------------------------------------------------


def test_a_command_in_steady_noise_ends_when_the_voice_does(speech: Speak) -> None:
    """A robot's fan never stops: the utterance must end when the person stops speaking,
    not when the noise does (the voice activity detector alone calls such noise speech)."""
    voice = np.frombuffer(read_wav(speech("turn left", "flite:slt")), "<i2").astype(np.float64)
    loud = np.flatnonzero(np.abs(voice) > 1000)
    speech_end = loud[-1] / 16000
    padded = np.concatenate([voice, np.zeros(4 * 16000)])  # four more seconds of the room
    active = voice[loud[0] : loud[-1]]
    noise = pink_noise(len(padded), np.sqrt(np.mean(active**2)) / 10 ** (12 / 20), seed=3)
    pcm = np.clip(padded + noise, -32768, 32767).astype("<i2").tobytes()

    engine = load_engine(EngineOptions())
    engine.use_grammar(build_grammar(OrderSet.load(Path(__file__).parents[1] / "orders")))
    recogniser = engine.recogniser(15.0)
    heard_at, clock = None, 0.0
    try:
        for frame in frames(pcm):
            clock += len(frame) / 32000
            if any(isinstance(e, Final) for e in recogniser.accept(frame)) and heard_at is None:
                heard_at = clock
    finally:
        recogniser.close()
    assert heard_at is not None, "no final while the noise went on"
    assert heard_at - speech_end < 0.8


def test_a_frame_counts_as_loud_only_above_the_room() -> None:
    room = Loudness(margin=6.0, window=100, needed=10)
    quiet = pink_noise(int(0.03 * 16000), 300.0, seed=1).astype("<i2").tobytes()
    voice = pink_noise(int(0.03 * 16000), 3000.0, seed=2).astype("<i2").tobytes()
    assert not room.stands_out(voice)  # the room is not known yet
    for _ in range(20):
        assert not room.stands_out(quiet)
    assert room.stands_out(voice)
    assert not room.stands_out(quiet)


def test_a_loud_room_has_a_narrow_spread_of_levels() -> None:
    quiet, noisy = (Loudness(margin=6.0, window=100, needed=10) for _ in range(2))
    for index in range(100):
        voice = pink_noise(int(0.03 * 16000), 3000.0 if index % 2 else 30.0, seed=index)
        fan = pink_noise(int(0.03 * 16000), 1000.0, seed=1000 + index)
        quiet.stands_out(voice.astype("<i2").tobytes())
        noisy.stands_out((voice + fan).astype("<i2").tobytes())
    assert quiet.spread() > sphinx.NOISY_SPREAD > noisy.spread()


def test_the_suppressor_lowers_steady_noise_and_keeps_every_sample() -> None:
    noise = pink_noise(int(2.0 * 16000), 1000.0, seed=5).astype("<i2").tobytes()
    suppressor = Suppressor(3)
    out = b"".join(suppressor.process(noise[i : i + 960]) for i in range(0, len(noise), 960))
    assert len(out) == len(noise)
    before, after = (np.frombuffer(b, "<i2")[16000:].astype(float) for b in (noise, out))
    # from the second second on, once it has learnt the noise
    assert np.sqrt(np.mean(after**2)) < np.sqrt(np.mean(before**2)) / 4


def test_a_command_in_noise_rejected_at_first_is_taken_when_a_second_look_agrees(
    speech: Speak, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Flite's "move forward" in pink noise 12 dB below it: the grammar's first pass is
    unsure of both words; on the same audio with WebRTC's noise suppression it is sure,
    and the first pass heard the same words, so the command is taken."""
    voice = np.frombuffer(read_wav(speech("move forward", "flite:slt")), "<i2").astype(np.float64)
    loud = np.flatnonzero(np.abs(voice) > 1000)
    active = voice[loud[0] : loud[-1]]
    noise = pink_noise(len(voice), np.sqrt(np.mean(active**2)) / 10 ** (12 / 20), seed=3)
    pcm = np.clip(voice + noise[: len(voice)], -32768, 32767).astype("<i2").tobytes()
    engine = load_engine(EngineOptions())
    # The orders without the queue's edits and questions: with them, this first pass hears
    # "why" (of "why did that fail"), unsure, and the second look has nothing to agree
    # with; the mechanism is tested here, the shipped grammar's accuracy is bench/stt.py's.
    shipped = Path(__file__).parents[1] / "orders"
    files = [OrderSet.load(path) for path in sorted(shipped.glob("*.yaml"))]
    english = [f for f in files if f.language == "en" and not is_queue(f)]
    engine.use_grammar(build_grammar(OrderSet.merge(english)))

    [final] = finals(engine, pcm)
    assert (final.text, final.rejection) == ("move forward", "")
    monkeypatch.setattr(sphinx, "NOISY_SPREAD", -1.0)  # no room is noisy: no second look
    [first] = finals(engine, pcm)
    assert first.text == "move forward"
    assert "not sure" in first.rejection


def is_queue(orders: OrderSet) -> bool:
    """Whether an orders file holds the queue's edits and questions (label `queue`)."""
    return any(order.label == QUEUE_LABEL for order in orders.orders)
