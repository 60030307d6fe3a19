"""Where voicectl keeps its files, and the panel's access token."""

from __future__ import annotations

import os
import secrets
from pathlib import Path

TOKEN_ENV = "VOICECTL_TOKEN"


def data_dir() -> Path:
    """$VOICECTL_DATA, else $XDG_DATA_HOME/voicectl, else ~/.local/share/voicectl."""
    explicit = os.environ.get("VOICECTL_DATA")
    if explicit:
        return Path(explicit)
    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(base) / "voicectl"


def cache_dir() -> Path:
    """$VOICECTL_CACHE, else $XDG_CACHE_HOME/voicectl, else ~/.cache/voicectl: what can be
    made again (prepared models), never what must be kept."""
    explicit = os.environ.get("VOICECTL_CACHE")
    if explicit:
        return Path(explicit)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "voicectl"


def default_token_file() -> Path:
    return data_dir() / "token"


def load_or_create_token(path: Path) -> str:
    """The panel token: $VOICECTL_TOKEN if set, else the file's, else a new one saved 0600."""
    from_env = os.environ.get(TOKEN_ENV, "").strip()
    if from_env:
        return from_env
    if path.exists():
        token = path.read_text(encoding="utf-8").strip()
        if token:
            return token
    path.parent.mkdir(parents=True, exist_ok=True)
    token = secrets.token_urlsafe(24)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as file:
        file.write(token + "\n")
    return token
