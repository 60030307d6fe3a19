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
    write_secret(path, (token + "\n").encode())
    return token


def write_secret(path: Path, content: bytes) -> Path:
    """Write `content` to a file only its owner reads (0600), whatever mode a file of that
    name had: a new file takes the old one's place, so no byte is ever in a file others
    read, nor reaches a descriptor opened on the old one."""
    fresh = path.with_name(f".{path.name}.{secrets.token_hex(4)}")
    descriptor = os.open(fresh, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    try:
        with os.fdopen(descriptor, "wb") as out:
            out.write(content)
        os.replace(fresh, path)
    except BaseException:
        fresh.unlink(missing_ok=True)
        raise
    return path
