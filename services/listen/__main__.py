"""`voicectl listen`: the robot's own microphone (or a file, or standard input) as an ear."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import sys
from collections.abc import Iterator

from voicectl.shared.errors import ServiceError
from voicectl.shared.process import open_bus, run_service, serve

from .audio_io import AudioError, list_devices, open_sink, open_source
from .config import listen_config, parse_args
from .listener import Listener, Speak
from .spotter import SpotterError


async def main(args: argparse.Namespace) -> None:
    config = listen_config(args)
    with contextlib.ExitStack() as stack:
        try:
            source = open_source(args.source)
            stack.callback(source.close)
            # Standard input's first bytes say what it is: told here, in one line, not
            # once the listener runs. Off the loop, so that Ctrl-C closes it meanwhile.
            await asyncio.to_thread(source.ready)
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
        # espeak-ng speaks the listener's language in its own voice for it; flite, English.
        spoken = args.language if args.speak == "espeak-ng" and args.language != "en" else None
        voice = load_voice(args.speak, voice=spoken)
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
