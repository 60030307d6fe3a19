"""Pronunciations for the words of the orders, across accents.

pocketsphinx ships the CMU dictionary: American pronunciations, one per word in most
cases. What a command recogniser adds to it, for every word of the grammar:

- Accent variants by rule (`variants`): non-rhotic (British "dumpster" ends in a schwa,
  "forward" has no r), a broad a (British "back", "bathroom" with the open vowel of
  "father"), and American flapped or dropped t after n ("ninety" as "niney").
- espeak-ng's American and British pronunciations when it is installed (Debian package
  espeak-ng), converted from its IPA to the acoustic model's ARPAbet phones. For a word the
  dictionary lacks (a place called "zanzibar") they are the only ones; without espeak-ng
  such a word is reported, and commands that use it cannot be heard.

On the generated set (docs/benchmarks.md) these took the commands heard exactly right from
68 to 71 of 75. That set is spoken by espeak-ng itself, so the part of the gain that comes
from espeak-ng's own pronunciations may not carry over to people.
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


def variants(phones: list[str]) -> list[list[str]]:
    """`phones` and each of its accent variants, one change at a time: non-rhotic, broad
    a, flapped t after n."""
    found = [phones]
    for changed in (non_rhotic(phones), broad_a(phones), *flapped(phones)):
        if changed not in found:
            found.append(changed)
    return found


def broad_a(phones: list[str]) -> list[str]:
    """British TRAP and BATH vowels are more open than American [æ]: AE becomes AA."""
    return ["AA" if phone == "AE" else phone for phone in phones]


def flapped(phones: list[str]) -> list[list[str]]:
    """American t after n and before a vowel, dropped or voiced ("twenty" as "twenny")."""
    found = []
    for position in range(1, len(phones) - 1):
        if (
            phones[position] == "T"
            and phones[position - 1] == "N"
            and phones[position + 1] in VOWELS
        ):
            found.append(phones[:position] + phones[position + 1 :])
            found.append([*phones[:position], "D", *phones[position + 1 :]])
    return found


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
    "iː": "IY", "uː": "UW", "oː": "AO", "ɑ": "AA", "æ": "AE", "a": "AA", "ʌ": "AH",
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


def espeak_pronunciations(words: list[str], voice: str) -> dict[str, list[str]]:
    """Pronunciations of `words` by one espeak-ng voice ("en-gb"), in one call; empty when
    espeak-ng is not installed or fails."""
    if shutil.which("espeak-ng") is None or not words:
        return {}
    try:
        done = subprocess.run(
            ["espeak-ng", "-q", "--ipa", "-v", voice],
            input="\n".join(words),
            capture_output=True,
            text=True,
            timeout=30,
            check=True,
        )
    except (OSError, subprocess.SubprocessError) as exc:
        _LOGGER.warning("espeak-ng could not pronounce the grammar's words: %s", exc)
        return {}
    lines = done.stdout.strip().splitlines()
    if len(lines) != len(words):
        _LOGGER.warning("espeak-ng answered %d lines for %d words", len(lines), len(words))
        return {}
    found = {}
    for word, ipa in zip(words, lines, strict=True):
        phones = ipa_to_arpabet(ipa.strip())
        if phones:
            found[word] = phones
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
    speak: Callable[[list[str], str], dict[str, list[str]]] = espeak_pronunciations,
) -> Pronunciations:
    """Pronunciations to add for `words`: the dictionary's (`known`), espeak-ng's (`speak`)
    British one for every word and American one for words the dictionary lacks, and the
    accent variants of each."""
    ordered = sorted(set(words))
    british = speak(ordered, "en-gb")
    unknown = [word for word in ordered if not known(word)]
    american = speak(unknown, "en-us")
    result = Pronunciations()
    for word in ordered:
        existing = known(word)
        spoken = [american[word]] if word in american else []
        if word in british and british[word] not in spoken:
            spoken.append(british[word])
        candidates = existing + [p for p in spoken if p not in existing]
        if not candidates:
            result.unpronounceable.append(word)
            continue
        wanted: list[list[str]] = []
        for phones in candidates:
            wanted.extend(v for v in variants(phones) if v not in wanted)
        new = [phones for phones in wanted if phones not in existing]
        if new:
            result.added[word] = new
    return result
