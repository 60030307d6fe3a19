"""The one normal form that utterances, aliases and phrases are compared in."""

from __future__ import annotations

import re

# Punctuation becomes a space; a dot between digits ("2.5") and a minus sign starting a
# number ("-3") stay.
_PUNCTUATION = re.compile(r"(?<!\d)\.|\.(?!\d)|(?!(?<!\S)-\d)[^\w\s.]")
_SPACES = re.compile(r"\s+")


def normalise(text: str) -> str:
    """Lower-case, punctuation-free, single-spaced text."""
    return _SPACES.sub(" ", _PUNCTUATION.sub(" ", text.lower())).strip()


def whole_words(pattern: str) -> str:
    """Wrap a regex so that it only matches whole words of normalised text.

    Words are what spaces separate, so "2.5" is one word and "turn" does not match "return".
    """
    return rf"(?<!\S)(?:{pattern})(?!\S)"
