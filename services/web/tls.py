"""The panel's HTTPS flags, shared with `voicectl up`; nothing of the web server is
imported here, so that the `voicectl` command builds its parser without it."""

from __future__ import annotations

import argparse
from pathlib import Path

from voicectl.shared.hints import voicectl_command


def add_tls_arguments(parser: argparse.ArgumentParser) -> None:
    """HTTPS: browsers give pages a microphone only on https or on localhost."""
    parser.add_argument("--certfile", type=Path, help="TLS certificate (PEM); see voicectl cert")
    parser.add_argument("--keyfile", type=Path, help="its private key (PEM)")


def tls_problem(args: argparse.Namespace) -> str:
    """Why the TLS flags cannot be used, or ''."""
    if (args.certfile is None) != (args.keyfile is None):
        return "--certfile and --keyfile go together"
    for path in (args.certfile, args.keyfile):
        if path is not None and not path.is_file():
            writes = voicectl_command("cert", "HOST...")
            return f"{path}: no such file ({writes} writes a certificate and key)"
    return ""
