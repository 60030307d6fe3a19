"""`voicectl listen`: the robot's own microphone (or a file, or standard input) as an ear."""

from __future__ import annotations

import argparse
import contextlib
import sys
from collections.abc import Iterator

from voicectl.shared.errors import ServiceError
from voicectl.shared.process import add_bus_arguments, open_bus, robot_name, run_service, serve

from .audio_io import AudioError, list_devices, open_sink, open_source
from .listener import ListenConfig, Listener, Speak
from .spotter import STOP_THRESHOLD, WAKE_THRESHOLD, SpotterError


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="voicectl listen", description=__doc__)
    parser.add_argument(
        "source",
        nargs="?",
        default="mic",
        help="'mic' (the default input device), 'mic:NAME' or 'mic:INDEX' (see "
        "--list-devices), a sound file, or '-' for standard input (WAV, or raw 16 kHz "
        "mono 16-bit: arecord -f S16_LE -r 16000 -c 1 | voicectl listen -)",
    )
    parser.add_argument("--list-devices", action="store_true", help="list sound devices")
    parser.add_argument("--robot", type=robot_name, default="robot")
    parser.add_argument(
        "--wake",
        default="",
        metavar="PHRASE",
        help="hear commands only after this phrase ('hey robot'); default: every utterance",
    )
    parser.add_argument("--wake-threshold", type=float, default=WAKE_THRESHOLD)
    parser.add_argument(
        "--no-stop-word",
        action="store_true",
        help="do not stop a moving robot on hearing 'stop' alone (it needs no wake phrase)",
    )
    parser.add_argument("--stop-threshold", type=float, default=STOP_THRESHOLD)
    parser.add_argument(
        "--awake",
        type=float,
        default=5.0,
        metavar="SECONDS",
        help="after the wake phrase, listen until a pause this long (default 5)",
    )
    parser.add_argument(
        "--speak",
        nargs="?",
        const="espeak-ng",
        default=None,
        metavar="ENGINE",
        help="answer aloud (espeak-ng, the default, or flite); the microphone is muted "
        "while the robot speaks",
    )
    parser.add_argument(
        "--speaker",
        default="speaker",
        help="where answers play: 'speaker', 'speaker:NAME', or a .wav file to append to",
    )
    add_bus_arguments(parser)
    return parser.parse_args(argv)


async def main(args: argparse.Namespace) -> None:
    config = ListenConfig(
        robot=args.robot,
        wake=" ".join(args.wake.lower().split()),
        wake_threshold=args.wake_threshold,
        stop_word=not args.no_stop_word,
        stop_threshold=args.stop_threshold,
        awake=args.awake,
    )
    with contextlib.ExitStack() as stack:
        try:
            source = open_source(args.source)
            stack.callback(source.close)
            speak = _voice(args, stack)
        except AudioError as exc:
            raise ServiceError(str(exc)) from exc
        with open_bus(args) as bus:
            try:
                listener = Listener(bus, config, source.read, source.close, speak)
            except SpotterError as exc:
                raise ServiceError(str(exc)) from exc
            await serve(listener)


def _voice(args: argparse.Namespace, stack: contextlib.ExitStack) -> Speak | None:
    if args.speak is None:
        return None
    from voicectl.shared.errors import TtsError
    from voicectl.shared.tts import load_voice

    try:
        voice = load_voice(args.speak)
    except TtsError as exc:
        raise AudioError(str(exc)) from exc
    sink = open_sink(args.speaker)
    stack.callback(sink.close)

    def speak(words: str) -> None:
        speech = voice.speak(words)
        sink.play(speech.pcm, speech.sample_rate)

    return speak


def _devices() -> Iterator[str]:
    for device in list_devices():
        yield f"{device.index}: {device.name} ({device.host_api})"


def run(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if args.list_devices:
        try:
            print("\n".join(_devices()) or "no sound devices")
        except AudioError as exc:
            print(f"voicectl listen: {exc}", file=sys.stderr)
            return 2
        return 0
    return run_service("voicectl listen", args, main)


if __name__ == "__main__":
    sys.exit(run())
