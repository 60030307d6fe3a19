"""The panel's command line, and the `WebConfig` it becomes."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

from voicectl.shared.config import default_token_file
from voicectl.shared.keys import MAX_ROBOTS
from voicectl.shared.process import add_bus_arguments, positive_int, robot_name
from voicectl.shared.tts import VOICES

from .tls import add_tls_arguments


@dataclass(frozen=True)
class WebConfig:
    """Where the panel serves, who may use it, and how it speaks."""

    robot: str = "robot"
    """The robot shown first."""
    host: str = "127.0.0.1"
    port: int = 8000
    token_file: Path | None = None
    """None: the data directory's `token`."""
    certfile: Path | None = None
    keyfile: Path | None = None
    allow_origins: tuple[str, ...] = ()
    """Other origins whose pages may open the microphone socket."""
    voice: str | None = None
    """The engine that says the panel's answers; None: espeak-ng if installed; 'none'."""
    max_robots: int = MAX_ROBOTS
    """Robots followed at most besides `robot` (their last state, pose, parts, labels)."""

    @property
    def token_path(self) -> Path:
        return self.token_file or default_token_file()

    @property
    def scheme(self) -> str:
        return "https" if self.certfile else "http"

    @classmethod
    def of(cls, args: argparse.Namespace) -> WebConfig:
        """The config the command line (`parse_args`) gives."""
        return cls(
            robot=args.robot,
            host=args.host,
            port=args.port,
            token_file=args.token_file,
            certfile=args.certfile,
            keyfile=args.keyfile,
            allow_origins=tuple(args.allow_origin),
            voice=args.voice,
            max_robots=args.max_robots,
        )


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="voicectl web", description="The browser panel and HTTP API for the robots on the bus."
    )
    parser.add_argument("--robot", default="robot", type=robot_name, help="robot shown first")
    parser.add_argument("--host", default="127.0.0.1", help="address to serve on")
    parser.add_argument("--port", type=int, default=8000)
    parser.add_argument(
        "--token-file",
        type=Path,
        default=None,
        help="file holding the API token, created if missing (default: data dir/token; "
        "$VOICECTL_TOKEN overrides)",
    )
    parser.add_argument(
        "--max-robots",
        type=positive_int,
        default=MAX_ROBOTS,
        metavar="N",
        help="robots followed at most besides --robot (default %(default)s): names come from "
        "anyone on the bus; when full, the one heard from longest ago that no page shows and "
        "no supervisor serves makes room, else a newcomer is not followed",
    )
    add_tls_arguments(parser)
    parser.add_argument(
        "--allow-origin",
        action="append",
        default=[],
        metavar="ORIGIN",
        help="another origin (scheme://host:port) whose pages may open the microphone socket",
    )
    parser.add_argument(
        "--voice",
        default=None,
        choices=[*VOICES, "none"],
        help="speech engine that says the panel's answers when a page asks (default: "
        "espeak-ng when installed, else none); none turns spoken answers off",
    )
    add_bus_arguments(parser)
    return parser.parse_args(argv)
