"""The recogniser's command line, and the `SttConfig` it becomes; the engine flags are
shared with `voicectl transcribe` and bench/stt.py."""

from __future__ import annotations

import argparse
import re
from dataclasses import dataclass, field

from voicectl.shared.process import add_bus_arguments, robot_name

from .engine import ENGINES, EngineOptions
from .service import SessionLimits


@dataclass(frozen=True)
class SttConfig:
    """One robot's recogniser: which engine, and how much audio it takes."""

    robot: str = "robot"
    engine: EngineOptions = field(default_factory=EngineOptions)
    limits: SessionLimits = field(default_factory=SessionLimits)
    language: str = "en"
    """What its sessions are heard in, unless a session says otherwise."""

    @classmethod
    def of(cls, args: argparse.Namespace) -> SttConfig:
        """The config the command line (`parse_args`) gives."""
        return cls(
            robot=args.robot,
            language=args.language,
            engine=engine_options(args),
            limits=SessionLimits(
                max_utterance=args.max_utterance,
                max_sessions=args.max_sessions,
                idle_seconds=args.idle,
                max_session=args.max_session,
                min_audio=args.min_audio,
                audio_window=args.audio_window,
            ),
        )


def add_engine_arguments(parser: argparse.ArgumentParser) -> None:
    """The engine flags of every command that loads an engine, each engine's own among them."""
    parser.add_argument(
        "--engine",
        choices=list(ENGINES),
        default=EngineOptions.name,
        help="speech engine (default %(default)s)",
    )
    for kind in ENGINES.values():
        for flag in kind.flags:
            parser.add_argument(
                f"--{flag.name}",
                type=flag.type,
                metavar=flag.metavar,
                help=f"{flag.help}, with --engine {kind.name}",
            )
    parser.add_argument(
        "--min-confidence",
        type=float,
        default=0.5,
        metavar="C",
        help="reject utterances recognised with less confidence, 0 to 1 (default %(default)s)",
    )
    parser.add_argument(
        "--workers",
        type=_count,
        default=0,
        metavar="N",
        help="decode in N worker processes, one engine each, for several people speaking "
        "at once on several cores (default 0: in this process)",
    )


def _language(text: str) -> str:
    if not re.fullmatch(r"[a-z]{2,3}", text):
        raise argparse.ArgumentTypeError(f"{text!r} is not a language code (en, es, de...)")
    return text


def _count(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number of 0 or more")
    return value


def engine_options(args: argparse.Namespace) -> EngineOptions:
    return EngineOptions(
        name=args.engine,
        min_confidence=args.min_confidence,
        workers=args.workers,
        settings={flag.dest: getattr(args, flag.dest) for flag in ENGINES[args.engine].flags},
    )


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="voicectl stt",
        description="Speech to text for one robot, listening only for the orders' commands.",
    )
    parser.add_argument("--robot", type=robot_name, default="robot")
    parser.add_argument(
        "--language",
        default="en",
        type=_language,
        metavar="CODE",
        help="what people speak to this robot (ISO 639-1: en, es, de...), unless a session "
        "says otherwise; heard with the orders in that language (default %(default)s)",
    )
    add_engine_arguments(parser)
    limits = SessionLimits()
    for flag, kind, default, metavar, text in (
        ("--max-utterance", float, limits.max_utterance, "SECONDS", "cut longer utterances"),
        ("--max-sessions", int, limits.max_sessions, "N", "audio sessions open at once"),
        ("--idle", float, limits.idle_seconds, "SECONDS", "end a session silent this long"),
        ("--max-session", float, limits.max_session, "SECONDS", "end a session open this long"),
        (
            "--min-audio",
            float,
            limits.min_audio,
            "RATIO",
            "end a session that sends less audio than this, in seconds per second",
        ),
        ("--audio-window", float, limits.audio_window, "SECONDS", "over this long (--min-audio)"),
    ):
        help_text = f"{text} (default %(default)s)"
        parser.add_argument(flag, type=kind, default=default, metavar=metavar, help=help_text)
    add_bus_arguments(parser)
    return parser.parse_args(argv)
