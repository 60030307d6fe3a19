"""Long recordings through `voicectl transcribe`: time, CPU and peak memory.

    .venv/bin/python -m bench.long_audio [--minutes 5]

Three recordings of `--minutes` each, made with sox: digital silence, a quiet room (pink
noise at about -50 dBFS), and the same room with one command ("go forward two meters",
Flite's slt) in the middle. Each is transcribed by `voicectl transcribe` in a process of
its own, whose wall time, CPU time and peak RSS are read from `wait4`; beside them, the
baseline of the same run: reading and resampling the file alone, with nothing listening.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from harness.processes import REPO

COMMAND = "go forward two meters"


def measured(argv: list[str]) -> tuple[float, float, float, str]:
    """Wall seconds, CPU seconds and peak RSS (MB) of a child running `argv`, and what it
    printed."""
    started = time.monotonic()
    with tempfile.TemporaryFile() as out:
        child = subprocess.Popen(argv, cwd=REPO, stdout=out, stderr=subprocess.DEVNULL)
        _, status, usage = os.wait4(child.pid, 0)
        child.returncode = os.waitstatus_to_exitcode(status)
        wall = time.monotonic() - started
        out.seek(0)
        printed = out.read().decode()
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024, printed


def recordings(folder: Path, minutes: float) -> dict[str, Path]:
    half = f"{minutes * 30:g}"
    silence, room, command = folder / "silence.wav", folder / "room.wav", folder / "said.wav"
    sox = ["sox", "-R", "-D", "-n", "-r", "16000", "-c", "1", "-b", "16"]
    subprocess.run([*sox, str(silence), "trim", "0", f"{minutes * 60:g}"], check=True)
    subprocess.run([*sox, str(room), "synth", half, "pinknoise", "vol", "0.003"], check=True)
    raw = folder / "raw.wav"
    subprocess.run(["flite", "-voice", "slt", "-t", COMMAND, "-o", str(raw)], check=True)
    subprocess.run(["sox", "-D", str(raw), "-r", "16000", str(command)], check=True)
    quiet_room = folder / "quiet-room.wav"
    subprocess.run(["sox", "-D", str(room), str(room), str(quiet_room)], check=True)
    said = folder / "room-with-a-command.wav"
    subprocess.run(["sox", "-D", str(room), str(command), str(room), str(said)], check=True)
    return {"silence": silence, "quiet room": quiet_room, "room with a command": said}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=5.0)
    args = parser.parse_args()
    load = os.getloadavg()[0]
    print(f"{os.cpu_count()} cores, load average {load:.1f}; {args.minutes:g} minutes each")
    reader = (
        "import sys; from voicectl.services.stt.audio import read_blocks; "
        "print(sum(len(b) for b in read_blocks(__import__('pathlib').Path(sys.argv[1]))))"
    )
    with tempfile.TemporaryDirectory() as folder:
        for name, path in recordings(Path(folder), args.minutes).items():
            seconds = args.minutes * 60
            base = measured([sys.executable, "-c", reader, str(path)])
            wall, cpu, rss, printed = measured(
                [sys.executable, "-m", "voicectl", "transcribe", str(path)]
            )
            line = json.loads(printed)
            heard = [
                (u["start"], [o["description"] for o in u["orders"]])
                for u in line["utterances"]
                if u["orders"]
            ]
            print(
                f"{name:<20} transcribe: {wall:6.1f} s wall ({seconds / wall:5.1f}x real time), "
                f"{cpu:6.1f} CPU-s, peak {rss:5.0f} MB, {len(line['utterances'])} utterances, "
                f"orders {heard}"
            )
            print(
                f"{'':<20} baseline, reading the file alone: {base[0]:5.1f} s wall, "
                f"{base[1]:5.1f} CPU-s, peak {base[2]:4.0f} MB"
            )


if __name__ == "__main__":
    main()
