"""Every word voicectl says to a person, from one catalogue per language: the panel's and
the spoken answers' (shared/answers.py, the panel's answers.js and words.js read the same
files, shared/words/<language>.json).

English is the whole catalogue; another language's file may lack a word, which then falls
back to English, never to its key. A language is chosen by a code ("es"), or from a
browser's Accept-Language header.
"""

from __future__ import annotations

import functools
import json
import re
from pathlib import Path
from typing import Any

ENGLISH = "en"
FOLDER = Path(__file__).resolve().parent / "words"
_CODE = re.compile(r"^[a-z]{2,3}$")

Entry = str | list[str] | dict[str, str]
"""A word or sentence ("{what} failed", with its values in braces); a list of words
(the words for "yes"); or a table (the past tense of an order's first word)."""


def languages() -> list[str]:
    """The languages that have a catalogue, English first."""
    found = sorted(path.stem for path in FOLDER.glob("*.json") if _CODE.match(path.stem))
    return [ENGLISH, *(code for code in found if code != ENGLISH)]


@functools.cache
def _file(language: str) -> dict[str, Entry]:
    path = FOLDER / f"{language}.json"
    if not _CODE.match(language) or not path.is_file():
        return {}
    loaded: dict[str, Entry] = json.loads(path.read_text(encoding="utf-8"))
    return loaded


@functools.cache
def catalogue(language: str) -> dict[str, Entry]:
    """Every entry in `language`, English where it has none."""
    return {**_file(ENGLISH), **_file(language)}


def known(language: str) -> str:
    """`language` if it has a catalogue, else English."""
    return language if _file(language) else ENGLISH


def word(language: str, key: str, **values: Any) -> str:
    """One sentence in `language` with `values` put in ("{what} failed")."""
    entry = catalogue(language).get(key)
    if not isinstance(entry, str):
        entry = _file(ENGLISH).get(key)
    if not isinstance(entry, str):
        raise KeyError(f"no word {key!r} in the English catalogue")
    return entry.format(**values) if values else entry


def words(language: str, key: str) -> list[str]:
    entry = catalogue(language).get(key)
    return list(entry) if isinstance(entry, list) else []


def table(language: str, key: str) -> dict[str, str]:
    entry = catalogue(language).get(key)
    return dict(entry) if isinstance(entry, dict) else {}


def from_header(accept: str) -> str:
    """The language a browser asks for (`Accept-Language: es-ES,es;q=0.9,en;q=0.8`): the
    first, by preference, that has a catalogue; English when none has."""
    wanted: list[tuple[float, int, str]] = []
    for position, part in enumerate(accept.split(",")):
        tag, _, parameters = part.strip().partition(";")
        quality = 1.0
        match = re.search(r"q=([0-9.]+)", parameters)
        if match:
            try:
                quality = float(match.group(1))
            except ValueError:
                quality = 0.0
        code = tag.strip().lower().split("-")[0]
        if code and quality > 0:
            wanted.append((-quality, position, code))
    for _, _, code in sorted(wanted):
        if _file(code):
            return code
    return ENGLISH
