"""Moonshine's English model on onnxruntime (services/stt/moonshine.py) and the two-ear
engine (services/stt/ears.py): the real weights from PyPI's moonshine-cpp, on a
person's recording and generated speech."""

from __future__ import annotations

import importlib.metadata
import os
import re
from pathlib import Path

import pytest

from harness.speech_set import in_pink_noise
from voicectl.services.converter.grammar import build_grammar
from voicectl.services.converter.orders import OrderSet
from voicectl.services.converter.parser import Parser
from voicectl.services.stt import moonshine
from voicectl.services.stt.audio import frames, read_wav
from voicectl.services.stt.ears import Ears
from voicectl.services.stt.engine import EngineError, EngineOptions, Final
from voicectl.services.stt.load import load_engine
from voicectl.services.stt.moonshine import Moonshine, prepare, weights_dir
from voicectl.shared.config import cache_dir

from .conftest import REPO, Speak, voicectl

ORDERS = OrderSet.load(REPO / "orders")
PARSER = Parser(ORDERS)


@pytest.fixture(scope="module")
def model() -> Moonshine:
    source = weights_dir()
    return Moonshine.prepared(source, prepare(source, cache_dir()))


def drives(text: str) -> list[float]:
    """How far forward the orders of `text` drive, one number per order."""
    return [o.target_pose.x for o in PARSER.parse(text).orders if o.target_pose is not None]


def test_a_person_saying_go_forward_ten_meters_is_heard_clean_and_in_noise(
    model: Moonshine, people: dict[str, Path]
) -> None:
    said = read_wav(people["real-goforward"])
    assert drives(model.transcribe(said).text) == [10.0]
    for snr in (10.0, 5.0):
        heard = model.transcribe(in_pink_noise(said, snr)).text
        assert drives(heard) == [10.0], (snr, heard)


def test_the_prepared_model_hears_what_the_shipped_one_hears(
    model: Moonshine, people: dict[str, Path], speech: Speak
) -> None:
    """The int8 products (`quantized_products`) compute with the very weights shipped: each
    model finds the other's words as likely as its own, within a hair. Not the same words:
    the products round differently, and on some CPUs (AMD EPYC here) a near-tie splits the
    other way ("Go forward ten metres" for the shipped "meters", 0.02 nats a token apart);
    one wrong weight costs whole nats."""
    shipped = Moonshine.shipped(weights_dir())
    for path in (people["real-goforward"], speech("turn left then reach the kitchen", "flite:slt")):
        pcm = read_wav(path)
        ours, theirs = model.transcribe(pcm).text, shipped.transcribe(pcm).text
        assert ours
        assert theirs
        heard, heard_shipped = model.encode(pcm), shipped.encode(pcm)
        assert heard is not None
        assert heard_shipped is not None
        for text in (ours, theirs):
            by_ours, by_theirs = (
                model.likelihood(heard, text),
                shipped.likelihood(heard_shipped, text),
            )
            assert abs(by_ours - by_theirs) < 0.05, (text, by_ours, by_theirs)
        assert model.likelihood(heard, theirs) > model.likelihood(heard, ours) - 0.05


def test_preparing_twice_reuses_the_first(tmp_path: Path) -> None:
    source = weights_dir()
    first = prepare(source, tmp_path)
    stamp = (first / "decoder.onnx").stat().st_mtime_ns
    assert prepare(source, tmp_path) == first
    assert (first / "decoder.onnx").stat().st_mtime_ns == stamp
    assert [p.name for p in (tmp_path / "moonshine").iterdir()] == [first.name]


def test_missing_weights_stop_the_engine_with_one_line_naming_them(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "tokenizer.bin").write_bytes(b"")
    done = voicectl(
        "transcribe",
        str(REPO / "README.md"),
        env={**os.environ, "VOICECTL_MOONSHINE": str(tmp_path)},
    )
    assert done.returncode == 2
    [line] = done.stderr.strip().splitlines()
    assert "encoder_model.ort, decoder_model_merged.ort are missing from" in line
    assert re.search(r"pip install (-e '[^']*|'voicectl)\[stt\]'", line), line
    monkeypatch.setattr(moonshine, "DISTRIBUTION", "no-such-moonshine-package")
    with pytest.raises(EngineError, match="Moonshine's English model is not installed"):
        weights_dir()
    with pytest.raises(importlib.metadata.PackageNotFoundError):
        importlib.metadata.distribution("no-such-moonshine-package")


def test_moonshine_starts_at_the_pause_and_an_utterance_is_transcribed_once(
    speech: Speak,
) -> None:
    """A pause inside the command (shorter than the end) drops the run started there;
    the end reuses the run started at the last pause: no audio is transcribed twice."""
    engine = load_engine(EngineOptions())
    assert isinstance(engine, Ears)
    engine.use_grammar(build_grammar(ORDERS))
    first = read_wav(speech("turn left", "flite:slt"))
    second = read_wav(speech("then reach the kitchen", "flite:slt"))
    # Each file has 0.5 s of silence before and 0.6 s after its speech: keep 0.15 s of
    # the first's tail and none of the second's lead, a pause too short to end on.
    gap = first[: len(first) - int(0.45 * 16000) * 2] + second[int(0.5 * 16000) * 2 :]
    recogniser = engine.recogniser(15.0)
    try:
        events = [e for frame in frames(gap) for e in recogniser.accept(frame)]
        events += recogniser.finish()
    finally:
        recogniser.close()
        engine.close()
    [final] = [e for e in events if isinstance(e, Final)]
    assert final.transcription is not None
    said = [o.description for o in PARSER.parse(final.transcription.text).orders]
    assert said == ["turn left", "reach kitchen"], final.transcription
    runs = engine.runs
    assert runs.at_pause >= 2, runs  # at the pause inside, and at the end
    assert runs.at_pause - runs.dropped == 1, runs  # only the last one was used
    assert runs.at_end == 0, runs


def test_a_cache_that_cannot_be_written_is_one_line_saying_what_to_set(tmp_path: Path) -> None:
    blocked = tmp_path / "a-file"
    blocked.write_text("not a folder")
    with pytest.raises(EngineError, match="set VOICECTL_CACHE to a folder this user may write"):
        prepare(weights_dir(), blocked)


def test_onnxruntime_reports_to_nobody_and_leaves_nothing_behind(tmp_path: Path) -> None:
    """PyPI's onnxruntime carries Microsoft's telemetry, which writes a session file into
    the temporary directory (and would report to Microsoft): voicectl turns it off."""
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    environment = {**os.environ, "TMPDIR": str(scratch)}
    environment.pop("ORT_DISABLE_TELEMETRY", None)
    done = voicectl("transcribe", str(REPO / "README.md"), env=environment)
    assert done.returncode == 1, done.stderr  # README.md is no audio: one unreadable file
    assert list(scratch.iterdir()) == []
