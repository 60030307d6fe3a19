"""Moonshine's model as shipped against as prepared, and onnxruntime's settings.

    .venv/bin/python -m bench.moonshine [--set DIR] [--files 60]

Each variant runs in a process of its own (so that its memory is its own): the ORT-format
files as `moonshine-cpp` ships them, run as they are (the baseline), and the prepared model
(services/stt/moonshine.py) with one and two onnxruntime threads and with the memory arena
off. Per variant: load time, resident memory after loading and at the peak, and the wall
and CPU time of a transcription of 1.5, 3 and 6 s of speech (median of five). Then the
words: the prepared model against the shipped one on --files utterances of the speech
set's dev split (every condition), counting identical transcripts and those whose orders
are the same.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from harness.processes import REPO, rss_mb
from harness.speech_set import Voice, generate, speak
from voicectl.services.converter.orders import OrderSet
from voicectl.services.converter.parser import Parser
from voicectl.services.stt.audio import read_wav
from voicectl.services.stt.moonshine import Moonshine, prepare, weights_dir
from voicectl.shared.config import cache_dir

VARIANTS = {
    "shipped (.ort), 1 thread": ("shipped", 1, True),
    "shipped (.ort), 2 threads": ("shipped", 2, True),
    "prepared, 1 thread": ("prepared", 1, True),
    "prepared, 2 threads": ("prepared", 2, True),
    "prepared, 1 thread, no memory arena": ("prepared", 1, False),
}
SENTENCES = {
    1.5: "turn left",
    3.0: "turn right then go forward three meters",
    6.0: "please turn left then go to the kitchen then take a photo then go to base now",
}


def model(kind: str, threads: int, arena: bool) -> Moonshine:
    """The model as `kind` says, with these onnxruntime settings."""
    source = weights_dir()
    if kind == "shipped":
        encoder, decoder = source / "encoder_model.ort", source / "decoder_model_merged.ort"
    else:
        folder = prepare(source, cache_dir())
        encoder, decoder = folder / "encoder.onnx", folder / "decoder.onnx"
    prepared = kind == "prepared"
    return Moonshine(encoder, decoder, source / "tokenizer.bin", threads, arena, prepared)


def one_variant(name: str, audio: dict[float, str]) -> dict[str, object]:
    """Runs in a child process: the figures of one variant."""
    began = time.perf_counter()
    built = model(*VARIANTS[name])
    loaded = time.perf_counter() - began
    after_load = rss_mb(os.getpid())
    timings = {}
    for seconds, path in audio.items():
        pcm = read_wav(Path(path))
        built.transcribe(pcm)  # warm
        walls, cpus = [], []
        for _ in range(5):
            wall, cpu = time.perf_counter(), time.process_time()
            built.transcribe(pcm)
            walls.append(time.perf_counter() - wall)
            cpus.append(time.process_time() - cpu)
        timings[str(seconds)] = (statistics.median(walls), statistics.median(cpus))
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return {"load": loaded, "rss": after_load, "peak": peak, "timings": timings}


def words(directory: Path, count: int) -> None:
    utterances = [u for u in generate(directory, ("dev",)) if u.split == "dev"]
    chosen = utterances[:: max(1, len(utterances) // count)][:count]
    parser = Parser(OrderSet.load(REPO / "orders"))
    shipped, prepared = model("shipped", 1, True), model("prepared", 1, True)
    same_text = same_orders = 0
    for utterance in chosen:
        pcm = read_wav(directory / utterance.file)
        a, b = shipped.transcribe(pcm).text, prepared.transcribe(pcm).text
        same_text += a == b
        same_orders += parser.parse(a).orders == parser.parse(b).orders
    print(
        f"words, prepared against shipped, {len(chosen)} dev utterances: {same_text} identical "
        f"transcripts, {same_orders} with the same orders (none, for non-commands)"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--set", type=Path, default=Path(tempfile.gettempdir()) / "voicectl-speech")
    parser.add_argument("--files", type=int, default=60)
    parser.add_argument("--variant", help=argparse.SUPPRESS)
    parser.add_argument("--audio", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.variant:
        print(json.dumps(one_variant(args.variant, json.loads(args.audio))))
        return
    made = Path(tempfile.mkdtemp())
    audio = {
        seconds: str(made / speak(text, Voice("flite", "slt"), made).file)
        for seconds, text in SENTENCES.items()
    }
    lengths = {s: len(read_wav(Path(p))) / 32000 for s, p in audio.items()}
    print(
        f"{os.cpu_count()} cores; utterances of {', '.join(f'{v:.1f}' for v in lengths.values())}"
        " s (Flite slt, with 0.5 s of silence before and 0.6 s after)"
    )
    for name in VARIANTS:
        done = subprocess.run(
            [
                sys.executable,
                "-m",
                "bench.moonshine",
                "--variant",
                name,
                "--audio",
                json.dumps(audio),
            ],
            cwd=REPO,
            capture_output=True,
            text=True,
            check=True,
        )
        figures = json.loads(done.stdout)
        timing = "; ".join(
            f"{float(s):.1f} s: {1e3 * w:.0f} ms wall, {1e3 * c:.0f} ms CPU"
            for s, (w, c) in figures["timings"].items()
        )
        print(
            f"{name:<38} load {figures['load']:.2f} s, RSS {figures['rss']:.0f} MB, "
            f"peak {figures['peak']:.0f} MB; {timing}"
        )
    words(args.set, args.files)


if __name__ == "__main__":
    main()
