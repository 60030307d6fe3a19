"""The trained wake phrase: the shipped "hey robot" model hears the phrase in voices it
never heard (bench/wake.py's test split), and not its near-misses or ordinary speech; a
model file that is not one is said in one line; `voicectl wake train` writes a model that
says how it was made, and `voicectl listen --wake MODEL` takes it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from harness.speech_set import LEAD_SILENCE, TAIL_SILENCE
from voicectl.services.listen.config import listen_config, parse_args
from voicectl.services.listen.spotter import Spotted, SpotterError
from voicectl.services.listen.wake_model import TrainedSpotter, WakeModel
from voicectl.services.stt.audio import read_wav

from .conftest import REPO, Speak

MODEL = REPO / "services" / "listen" / "hey_robot.npz"
HELD_OUT = ["flite:slt", "festival:ked_diphone"]
"""Voices of bench/wake.py's test split: the model was neither trained nor tuned on them."""


def heard(wav: Path | bytes, model: Path = MODEL) -> list[Spotted]:
    """The phrases the trained spotter reports in `wav` (a file or its audio), streamed in
    20 ms pieces."""
    spotter = TrainedSpotter(WakeModel.load(model))
    pcm = (wav if isinstance(wav, bytes) else read_wav(wav)) + bytes(32000)
    found: list[Spotted] = []
    for at in range(0, len(pcm), 640):
        found += spotter.accept(pcm[at : at + 640])
    return found


@pytest.mark.parametrize("voice", HELD_OUT)
def test_the_shipped_model_wakes_on_a_voice_it_never_heard(speech: Speak, voice: str) -> None:
    wav = speech("hey robot", voice)
    hits = heard(wav)
    assert [hit.phrase for hit in hits] == ["hey robot"]
    # The phrase ends where the speech does (the file's last 0.6 s are silence): the
    # listener streams the command from there.
    speech_end = len(read_wav(wav)) / 32000 - 0.6
    assert abs(hits[0].end - speech_end) < 0.4, (hits[0], speech_end)


@pytest.mark.parametrize("speed", [100, 120])
def test_a_slow_speaker_s_phrase_is_placed_whole_before_the_command(
    speech: Speak, speed: int
) -> None:
    """Said slowly, the phrase outlasts the model's typical speaker and its score crosses
    the threshold before its last syllable. The listener sends the recogniser the room
    before the phrase's start and everything after its end: a start placed late hands it
    "hey", an end placed early "-bot", and it answers "I did not catch that" instead of
    taking the command."""
    voice = "espeak:en-us"
    phrase = read_wav(speech("hey robot", voice, speed))
    phrase_end = len(phrase) / 32000 - TAIL_SILENCE
    command = read_wav(speech("turn left", voice, speed))
    pause = 0.4
    said = (
        phrase[: int(phrase_end * 16000) * 2]
        + bytes(int(pause * 32000))
        + command[int(LEAD_SILENCE * 32000) :]
    )
    hits = heard(said)
    assert [hit.phrase for hit in hits] == ["hey robot"]
    assert abs(hits[0].start - LEAD_SILENCE) < 0.1, hits[0]
    assert phrase_end - 0.05 <= hits[0].end <= phrase_end + pause, (hits[0], phrase_end)


@pytest.mark.parametrize("voice", HELD_OUT)
def test_it_is_sure_of_the_phrase_and_not_of_a_near_miss_that_wakes_it(
    speech: Speak, voice: str
) -> None:
    """Said in these voices, "hey rover" scores over the threshold: the model is not sure
    of it (`TrainedSpotter.sure`), so the listener has the recogniser check it, while the
    phrase itself is taken at once (tests/test_listen.py hears both through the stack)."""

    def sureness(text: str) -> list[bool | None]:
        spotter = TrainedSpotter(WakeModel.load(MODEL))
        pcm = read_wav(speech(text, voice)) + bytes(32000)
        found: list[bool | None] = []
        for at in range(0, len(pcm), 640):
            found += [None for _ in spotter.accept(pcm[at : at + 640])]
            if found and found[-1] is None:
                found[-1] = spotter.sure()
        return found

    assert sureness("hey robot") == [True]
    assert sureness("hey rover") == [False]


@pytest.mark.parametrize("voice", HELD_OUT)
def test_it_does_not_wake_on_near_misses_or_ordinary_speech(speech: Speak, voice: str) -> None:
    for text in ["hey robin", "go to the kitchen", "the robot is in the kitchen"]:
        assert heard(speech(text, voice)) == [], text


def test_nor_on_a_person_reading(people: dict[str, Path]) -> None:
    for name in ["real-goforward", "real-sense_and_sensibility_01_austen_64kb-0870"]:
        assert heard(people[name]) == [], name


def test_a_file_that_is_no_model_is_said_in_one_line(tmp_path: Path) -> None:
    with pytest.raises(SpotterError, match=r"wake model .*missing.npz: no such file"):
        WakeModel.load(tmp_path / "missing.npz")
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip archive")
    with pytest.raises(SpotterError, match=r"bad.npz: not a voicectl wake model"):
        WakeModel.load(bad)
    other = tmp_path / "other.npz"
    np.savez(other, meta=np.array('{"format": 1}'), hidden_weights=np.zeros((3, 2)))
    with pytest.raises(SpotterError, match=r"other.npz: format 1, weights \(3, 2\)"):
        WakeModel.load(other)


def test_listen_takes_a_model_file_for_wake_and_a_phrase_as_before() -> None:
    config = listen_config(parse_args(["--wake", str(MODEL)]))
    assert (config.wake, config.wake_model, config.wake_check) == ("", str(MODEL), False)
    config = listen_config(parse_args(["--wake", "Hey  Robot"]))
    assert (config.wake, config.wake_model, config.wake_check) == ("hey robot", "", True)


def test_listen_refuses_a_missing_model_before_it_joins_the_bus(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exited:
        parse_args(["--wake", str(tmp_path / "missing.npz")])
    assert exited.value.code == 2
    error = capsys.readouterr().err.strip().splitlines()[-1]
    wanted = f"wake model {tmp_path}/missing.npz: no such file"
    assert error == f"voicectl listen: error: argument --wake: {wanted}"


def test_the_shipped_model_says_how_it_was_made() -> None:
    made = WakeModel.load(MODEL).made
    assert made["command"].startswith("voicectl wake train 'hey robot'")
    assert made["seed"] == 1
    assert made["counts"]["phrase takes"] > 100
    assert not set(made["training voices"]) & set(made["dev voices"])


@pytest.mark.timeout(900)
def test_wake_train_writes_a_model_trained_apart_from_its_dev_voices(tmp_path: Path) -> None:
    """A small model (`--size 0.02`, espeak-ng alone): the command end to end."""
    out = tmp_path / "hey_robot.npz"
    env = {**os.environ, "VOICECTL_CACHE": str(tmp_path / "cache"), "OMP_NUM_THREADS": "1"}
    train = [sys.executable, "-m", "voicectl", "wake", "train", "Hey Robot", "--size", "0.02"]
    done = subprocess.run(
        [*train, "--no-kokoro", "--near", "hey robin", "--seed", "7", "--out", str(out)],
        capture_output=True,
        text=True,
        env=env,
        cwd=REPO,
    )
    assert done.returncode == 0, done.stderr
    assert "hearing the clips" in done.stdout
    assert f"wrote {out}" in done.stdout
    model = WakeModel.load(out)
    assert model.phrase == "hey robot"
    assert model.made["seed"] == 7
    assert "hey robin" in model.made["near-misses"]
    assert all(v.startswith("espeak:") for v in model.made["training voices"])
    dev = {v.partition("@")[0] for v in model.made["dev voices"]}
    assert not dev & {v.partition("@")[0] for v in model.made["training voices"]}
    assert 0.5 <= model.threshold < 1.0


def test_wake_train_refuses_a_bad_phrase_in_one_line(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "voicectl", "wake", "train", "hey r0bot!", "--out", "x.npz"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert done.returncode == 2
    assert done.stderr.strip() == (
        "voicectl wake train: wake phrase 'hey r0bot!': words of letters only, please"
    )
