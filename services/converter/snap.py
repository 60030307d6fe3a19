"""A free transcript's words snapped to the orders' words, for an ear that hears alone.

Whisper base, hearing Spanish or German by itself, writes words of the orders a letter or
two off ("Kira a la derecha", "Abanza 2 metros", "Toma un nafoto"), where a grammar-bound
ear would have been held to the orders' words. Each word that is not one of the orders' is
replaced by the nearest that is, when `rapidfuzz.fuzz.ratio` finds them at least `CUTOFF`
alike; numbers and the orders' own words stay as they are, and no number word is ever a
target (a misheard number is never guessed). The result is a guess: the converter only
reads it back for a yes (decide.py, `alone_reading`).
"""

from __future__ import annotations

import re
from collections.abc import Collection

from rapidfuzz import fuzz, process

CUTOFF = 70.0
"""How alike (0-100) a word must be to an order's word to be snapped to it. On the dev
split of harness/speech_languages.py (Spanish, Whisper base alone; whole files decoded
once, greedy, then prompted with five hypotheses), 70 made the said orders of 43 of 84
commands against 36 unsnapped, 75 of 41, 80 of 40; none made other orders, and no
non-command made any at any cutoff. In German it changed nothing."""
_WORD = re.compile(r"[^\W_]+|\d+(?:[.,]\d+)?")


def snapped(text: str, vocabulary: Collection[str], cutoff: float = CUTOFF) -> str:
    """`text` in lower case, each word outside `vocabulary` replaced by its nearest word
    in it when they are at least `cutoff` alike; '' when nothing changed."""
    words = _WORD.findall(text.lower())
    out = []
    for word in words:
        if word in vocabulary or word[0].isdigit():
            out.append(word)
            continue
        match = process.extractOne(word, vocabulary, scorer=fuzz.ratio, score_cutoff=cutoff)
        out.append(match[0] if match else word)
    return " ".join(out) if out != words else ""
