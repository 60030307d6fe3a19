"""The listener's command line, and the `ListenConfig` it becomes."""

from __future__ import annotations

import argparse
from pathlib import Path

from voicectl.shared.messages import check_phrase
from voicectl.shared.process import add_bus_arguments, robot_name

from .listener import ListenConfig
from .spotter import STOP_THRESHOLD, WAKE_THRESHOLD, SpotterError
from .wake_model import WakeModel, is_model_path


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="voicectl listen",
        description="The robot's own microphone (or a file, or standard input) as an ear.",
    )
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
        type=_wake_phrase,
        default="",
        metavar="PHRASE|MODEL",
        help="hear commands only after this phrase: words pocketsphinx spells ('hey robot'), "
        "or a model `voicectl wake train` made (a .npz file); default: every utterance",
    )
    parser.add_argument(
        "--wake-threshold",
        type=float,
        default=None,
        help=f"the spotter's threshold (pocketsphinx: {WAKE_THRESHOLD:.0e}; a model: its own)",
    )
    parser.add_argument(
        "--wake-check",
        action="store_true",
        help="with a trained model, have the recogniser's neural ear confirm every phrase, "
        "not only those the model is not sure of (pocketsphinx's phrases always are)",
    )
    parser.add_argument(
        "--language",
        default="en",
        metavar="CODE",
        help="what people say to it (en, es, de...): heard, answered and confirmed in that "
        "language (default %(default)s)",
    )
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


def _wake_phrase(text: str) -> str:
    """A wake phrase the recogniser will check (`check_phrase`), or a model file's path;
    '' for none."""
    if not text.strip():
        return ""
    if is_model_path(text):
        try:  # a wrong file is said at once, not once the bus is joined
            WakeModel.load(Path(text))
        except SpotterError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from exc
        return text
    try:
        return check_phrase(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


def listen_config(args: argparse.Namespace) -> ListenConfig:
    """The config the command line (`parse_args`) gives."""
    model = is_model_path(args.wake)
    return ListenConfig(
        robot=args.robot,
        wake="" if model else " ".join(args.wake.lower().split()),
        wake_model=args.wake if model else "",
        wake_threshold=args.wake_threshold,
        wake_check=args.wake_check or not model,
        stop_word=not args.no_stop_word,
        stop_threshold=args.stop_threshold,
        awake=args.awake,
        language=args.language,
    )
