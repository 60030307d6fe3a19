"""Pronunciations for the words of the orders, across accents.

pocketsphinx ships the CMU dictionary: American pronunciations, one per word in most
cases. Two gaps matter for commands:

- British and other non-rhotic speakers drop the r after a vowel: "dumpster" ends in a
  schwa, "forward" has no r. Every pronunciation gets a non-rhotic variant (an r-coloured
  vowel becomes a schwa, an r after a vowel and before a consonant or the end is dropped).
  On generated British speech this turned "take a picture" from a miss into a hit.
- Words the dictionary lacks (a place called "zanzibar", a made-up robot name) get their
  American and British pronunciations from espeak-ng when it is installed (Debian package
  espeak-ng), converted from its IPA to the ARPAbet phones of the acoustic model. Without
  it such words are reported: commands that use them cannot be heard.
"""

from __future__ import annotations

import logging
import shutil
import subprocess
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

_LOGGER = logging.getLogger(__name__)

VOWELS = frozenset(
    ["AA", "AE", "AH", "AO", "AW", "AY", "EH", "ER", "EY", "IH", "IY", "OW", "OY", "UH", "UW"]
)
"""ARPAbet vowels, as in the CMU dictionary without stress marks."""


def non_rhotic(phones: list[str]) -> list[str]:
    """The pronunciation of a speaker who drops the r after a vowel ("dumpster" ends
    in a schwa, "forward" sounds like "fo-wad")."""
    result = []
    for position, phone in enumerate(phones):
        following = phones[position + 1] if position + 1 < len(phones) else None
        if following in VOWELS:
            result.append(phone)
        elif phone == "ER":
            result.append("AH")
        elif phone != "R" or position == 0 or phones[position - 1] not in VOWELS:
            result.append(phone)
    return result


# IPA as espeak-ng writes English, longest symbols first when matching.
_IPA = {
    "aɪə": "AY AH", "aʊə": "AW AH", "ɔːɹ": "AO R", "ɑːɹ": "AA R", "ɪəɹ": "IH R",
    "aɪ": "AY", "aʊ": "AW", "eɪ": "EY", "oʊ": "OW", "əʊ": "OW", "ɔɪ": "OY", "ɪə": "IH AH",
    "eə": "EH AH", "ʊə": "UH AH", "tʃ": "CH", "dʒ": "JH", "ɑː": "AA", "ɔː": "AO", "ɜː": "ER",
    "iː": "IY", "uː": "UW", "oː": "AO", "ɑ": "AA", "æ": "AE", "a": "AE", "ʌ": "AH",
    "ə": "AH", "ɐ": "AH", "ɔ": "AO", "ɒ": "AA", "ɛ": "EH", "e": "EH", "ɜ": "ER", "ɝ": "ER",
    "ɚ": "ER", "ɪ": "IH", "ᵻ": "IH", "i": "IY", "ʊ": "UH", "u": "UW", "o": "OW", "b": "B",
    "d": "D", "ð": "DH", "f": "F", "ɡ": "G", "g": "G", "h": "HH", "k": "K", "l": "L",
    "m": "M", "n": "N", "ŋ": "NG", "p": "P", "ɹ": "R", "r": "R", "s": "S", "ʃ": "SH",
    "t": "T", "θ": "TH", "v": "V", "w": "W", "j": "Y", "z": "Z", "ʒ": "ZH", "ɾ": "T",
    "ʔ": "T", "x": "K", "ɬ": "L",
}  # fmt: skip
_MARKS = set("ˈˌ\u0329‿- ")
"""Stress, syllabic and linking marks: they change no phone."""
_LONGEST = max(len(symbol) for symbol in _IPA)


def ipa_to_arpabet(ipa: str) -> list[str] | None:
    """ARPAbet phones for espeak-ng's IPA, or None if a symbol has no equivalent."""
    text = "".join(char for char in ipa if char not in _MARKS)
    phones: list[str] = []
    position = 0
    while position < len(text):
        for size in range(_LONGEST, 0, -1):
            symbol = text[position : position + size]
            if symbol in _IPA:
                phones.extend(_IPA[symbol].split())
                position += size
                break
        else:
            if text[position] != "ː":  # a length mark after a symbol matched without it
                return None
            position += 1
    return phones or None


def espeak_pronunciations(word: str) -> list[list[str]]:
    """American and British pronunciations of `word` from espeak-ng; none if not installed."""
    if shutil.which("espeak-ng") is None:
        return []
    found: list[list[str]] = []
    for voice in ("en-us", "en-gb"):
        try:
            done = subprocess.run(
                ["espeak-ng", "-q", "--ipa", "-v", voice, word],
                capture_output=True,
                text=True,
                timeout=10,
                check=True,
            )
        except (OSError, subprocess.SubprocessError) as exc:
            _LOGGER.warning("espeak-ng could not pronounce %r: %s", word, exc)
            continue
        phones = ipa_to_arpabet(done.stdout.strip())
        if phones and phones not in found:
            found.append(phones)
    return found


@dataclass
class Pronunciations:
    """What to add to a recogniser's dictionary for a grammar."""

    added: dict[str, list[list[str]]] = field(default_factory=dict)
    """New pronunciations by word (variants of known words, or all of a new word's)."""
    unpronounceable: list[str] = field(default_factory=list)


def pronunciations(
    words: Iterable[str],
    known: Callable[[str], list[list[str]]],
    guess: Callable[[str], list[list[str]]] = espeak_pronunciations,
) -> Pronunciations:
    """Pronunciations to add for `words`, given the dictionary's (`known`) and a guesser
    for words it lacks; every pronunciation also gets its non-rhotic variant."""
    result = Pronunciations()
    for word in sorted(set(words)):
        existing = known(word)
        candidates = existing or guess(word)
        if not candidates:
            result.unpronounceable.append(word)
            continue
        wanted = list(candidates)
        for phones in candidates:
            variant = non_rhotic(phones)
            if variant not in wanted:
                wanted.append(variant)
        new = [phones for phones in wanted if phones not in existing]
        if new:
            result.added[word] = new
    return result
