"""Spoken answers' engines (shared/tts.py): real espeak-ng (Debian's binary and the PyPI
wheel's library) and flite make audible speech of a plausible length; a missing engine,
a failing or hanging one, and text that cannot be said are one-line errors."""

from __future__ import annotations

import contextlib
import shutil
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from voicectl.shared.errors import TtsError
from voicectl.shared.tts import MAX_TEXT, CommandVoice, Speech, Voice, from_wav, load_voice, to_wav

from .conftest import cannot_run

PHRASE = "turn left, then reach kitchen"


def loudness(speech: Speech) -> float:
    """Root mean square of the samples, 0 to 1."""
    samples = np.frombuffer(speech.pcm, dtype="<i2").astype(np.float64) / 32768
    return float(np.sqrt(np.mean(samples**2))) if samples.size else 0.0


@pytest.fixture(params=["espeak-ng", "espeak-ng library", "flite"])
def voice(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Voice:
    """Each engine as a machine has it: the library is what a PATH without espeak-ng gets."""
    if request.param == "espeak-ng library":
        monkeypatch.setenv("PATH", str(tmp_path))
        return load_voice("espeak-ng")
    if shutil.which(request.param) is None:
        cannot_run(f"{request.param} is not installed (scripts/test installs it)")
    return load_voice(request.param)


def test_each_engine_speaks_audibly_for_a_plausible_time(voice: Voice) -> None:
    speech = voice.speak(PHRASE)
    assert 1.0 < speech.seconds < 4.0, speech.seconds
    assert loudness(speech) > 0.02
    assert speech.sample_rate in (8000, 16000, 22050)
    short = voice.speak("stopped")
    assert 0.2 < short.seconds < speech.seconds


def test_text_is_never_read_as_options_or_by_a_shell(voice: Voice, tmp_path: Path) -> None:
    marker = tmp_path / "ran"
    speech = voice.speak(f"-v --help $(touch {marker}); `touch {marker}` 'ünïcode'")
    assert not marker.exists()
    assert speech.seconds > 1.0
    assert loudness(speech) > 0.02


def test_a_phrase_said_again_comes_from_memory(voice: Voice) -> None:
    first = voice.speak("stopped")
    assert voice.speak("  stopped ") is first


@pytest.mark.parametrize("text", ["", "  \n\t ", "\x00\x07", "x" * (MAX_TEXT + 1)])
def test_empty_or_too_long_text_is_refused(text: str) -> None:
    with pytest.raises(ValueError, match=r"empty|too long") as refused:
        load_voice("espeak-ng").speak(text)
    assert "\n" not in str(refused.value)


def test_text_of_the_longest_length_is_said() -> None:
    assert load_voice("espeak-ng").speak("stop " * (MAX_TEXT // 5)).seconds > 5


def test_a_missing_engine_says_how_to_install_it(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(TtsError) as missing:
        load_voice("flite")
    assert str(missing.value) == "speech engine 'flite' is not installed (apt-get install flite)"
    monkeypatch.setitem(sys.modules, "espeakng_loader", None)  # as if never installed
    with pytest.raises(TtsError, match=r"^speech engine 'espeak-ng' is not installed \(apt-get"):
        load_voice("espeak-ng")


def test_unknown_engines_and_rates_are_refused_in_one_line() -> None:
    with pytest.raises(TtsError, match="unknown speech engine 'festival'; known: espeak-ng, flite"):
        load_voice("festival")
    with pytest.raises(TtsError, match="80 to 450"):
        load_voice("espeak-ng", rate=5)


@pytest.mark.parametrize("engine", ["espeak-ng", "espeak-ng library"])
def test_an_engine_that_fails_says_why(
    engine: str, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    if engine.endswith("library"):
        monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(TtsError, match=r"^speech engine 'espeak-ng' failed: .*voice") as failed:
        load_voice("espeak-ng", voice="nosuchvoice").speak("hello")
    assert "\n" not in str(failed.value)


def test_voice_and_rate_reach_the_engine() -> None:
    slow = load_voice("espeak-ng", voice="en-us", rate=100).speak(PHRASE)
    fast = load_voice("espeak-ng", voice="en-us", rate=300).speak(PHRASE)
    assert slow.seconds > 2 * fast.seconds


def test_an_engine_that_hangs_is_killed() -> None:
    sleeper = shutil.which("sleep")
    assert sleeper is not None
    hanging = CommandVoice("sleepy", lambda _text: ([sleeper, "30"], b""), "nothing", timeout=0.5)
    started = time.monotonic()
    with pytest.raises(TtsError, match=r"^speech engine 'sleepy' took over 0\.5 s$"):
        hanging.speak("hello")
    assert time.monotonic() - started < 5


def test_an_engine_removed_after_loading_is_reported_as_missing() -> None:
    gone = CommandVoice("flite", lambda text: (["/nonexistent/flite", text], b""), "apt-get x")
    with pytest.raises(TtsError, match=r"^speech engine 'flite' is not installed \(apt-get x\)$"):
        gone.speak("hello")


@given(st.binary(max_size=4000).map(lambda pcm: pcm[: len(pcm) // 2 * 2]))
def test_wav_round_trips(pcm: bytes) -> None:
    speech = Speech(pcm, 22050)
    assert from_wav(to_wav(speech)) == speech


@given(st.binary(max_size=200))
def test_anything_that_is_not_a_mono_wav_is_a_value_error(junk: bytes) -> None:
    for data in (junk, b"RIFF\0\0\0\0WAVE" + junk):
        with contextlib.suppress(ValueError):
            from_wav(data)


def test_a_streamed_wav_with_placeholder_sizes_reads_to_its_end() -> None:
    """What espeak-ng writes to a pipe: sizes it could not seek back to fill in."""
    wav = bytearray(to_wav(Speech(b"\x01\x02" * 100, 22050)))
    wav[4:8] = wav[40:44] = b"\xff\xff\xff\x7f"
    assert from_wav(bytes(wav)) == Speech(b"\x01\x02" * 100, 22050)
