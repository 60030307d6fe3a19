"""The languages orders are written in: how each says numbers, joins commands and shows
itself, for the parser, the grammar and the check that a file is in the language it says.

Spoken numbers are read by `text2num` (English, Spanish, German, French, Portuguese,
Catalan, Italian, Dutch, Danish) and written out by `num2words`, which the grammar needs to
list a slot's values as words. What `text2num` 3.1 reads was measured rather than assumed
(tests/test_languages.py): it reads every whole number `num2words` writes in Spanish and
German up to 999, but writes German decimals with a comma ("zwei Komma fünf" -> "2,5"), and
reads neither German "einen" ("fahre einen Meter") nor Spanish "una" in German text; both
are worked around here (`Numbers.read`). A language whose numbers `text2num` cannot read is
refused for orders with number slots (`check_numbers`).
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass, field
from decimal import Decimal

from text_to_num import alpha2digit  # type: ignore[import-untyped]

from .slots import MAX_SPOKEN, NUMBER_PATTERN, NUMBER_WORDS, read_number, say_number

DEFAULT = "en"
NUMBER_LIMIT = 1000
"""Whole numbers whose words make a language's number vocabulary (a slot's values are
heard up to twice its maximum, at most `MAX_GRID` of them)."""


@dataclass(frozen=True)
class Language:
    """What the converter knows of one language beyond its orders files."""

    code: str
    """ISO 639-1, as Whisper and text2num name it ("es")."""
    name: str
    conjunctions: tuple[str, ...] = ()
    """The words for "and" between two commands ("turn left and move forward")."""
    separator: str = ""
    """The separator of a file that does not say one."""
    skip_words: tuple[str, ...] = ()
    """The skip words of a file that does not say them."""
    decimal_words: tuple[str, ...] = ()
    """Words between the whole and the fraction of a spoken number ("point", "coma")."""
    sign_words: tuple[str, ...] = ()
    decimal_comma: bool = False
    """Whether digits are written "2,5" (a transcript's "2,5 metros")."""
    one: tuple[str, ...] = ()
    """Forms of "one" that are articles too ("einen Meter"): read as one."""
    unit_words: dict[str, str] = field(default_factory=dict)
    """A unit symbol after a number, as the word an alias says ("m" -> "metros")."""
    markers: frozenset[str] = frozenset()
    """Common words of the language, and of robot commands in it, that no other language
    here shares: the words a file's aliases are told apart by (`check_language`)."""


LANGUAGES = {
    language.code: language
    for language in (
        Language(
            "en",
            "English",
            conjunctions=("and",),
            separator="then",
            skip_words=("a", "the", "to", "please", "now"),
            decimal_words=("point",),
            sign_words=("minus", "negative"),
            unit_words={
                "m": "meters",
                "cm": "centimeters",
                "mm": "millimeters",
                "deg": "degrees",
                "°": "degrees",
                "rad": "radians",
                "s": "seconds",
                "sec": "seconds",
                "secs": "seconds",
                "min": "minutes",
                "mins": "minutes",
            },
            markers=frozenset(
                [
                    "the",
                    "to",
                    "of",
                    "and",
                    "then",
                    "please",
                    "now",
                    "turn",
                    "left",
                    "right",
                    "go",
                    "reach",
                    "move",
                    "forward",
                    "back",
                    "backward",
                    "wait",
                    "seconds",
                    "meters",
                    "metres",
                    "degrees",
                    "take",
                    "picture",
                    "photo",
                    "kitchen",
                    "bathroom",
                    "drive",
                    "rotate",
                    "ahead",
                    "straight",
                    "with",
                    "this",
                    "that",
                    "is",
                    "are",
                    "you",
                ]
            ),
        ),
        Language(
            "es",
            "Spanish",
            conjunctions=("y", "e"),
            separator="luego|después",
            skip_words=("el", "la", "los", "las", "al", "por", "favor", "ahora"),
            decimal_words=("coma", "punto"),
            sign_words=("menos",),
            decimal_comma=True,
            one=("un", "una"),
            unit_words={
                "m": "metros",
                "cm": "centímetros",
                "mm": "milímetros",
                "°": "grados",
                "rad": "radianes",
                "s": "segundos",
                "seg": "segundos",
                "min": "minutos",
            },
            markers=frozenset(
                [
                    "el",
                    "la",
                    "los",
                    "las",
                    "al",
                    "del",
                    "y",
                    "luego",
                    "después",
                    "por",
                    "favor",
                    "ahora",
                    "gira",
                    "girar",
                    "gire",
                    "izquierda",
                    "derecha",
                    "ve",
                    "vete",
                    "ir",
                    "llega",
                    "avanza",
                    "adelante",
                    "atrás",
                    "retrocede",
                    "espera",
                    "segundos",
                    "metros",
                    "grados",
                    "toma",
                    "haz",
                    "una",
                    "foto",
                    "cocina",
                    "baño",
                    "basura",
                    "con",
                    "que",
                    "para",
                    "hacia",
                ]
            ),
        ),
        Language(
            "de",
            "German",
            conjunctions=("und",),
            separator="dann|danach",
            skip_words=("der", "die", "das", "den", "dem", "zur", "zum", "bitte", "jetzt"),
            decimal_words=("komma",),
            sign_words=("minus",),
            decimal_comma=True,
            one=("ein", "einen", "eine", "einem", "einer"),
            unit_words={
                "m": "meter",
                "cm": "zentimeter",
                "mm": "millimeter",
                "°": "grad",
                "rad": "radiant",
                "s": "sekunden",
                "sek": "sekunden",
                "min": "minuten",
            },
            markers=frozenset(
                [
                    "der",
                    "die",
                    "das",
                    "den",
                    "dem",
                    "zur",
                    "zum",
                    "und",
                    "dann",
                    "danach",
                    "bitte",
                    "jetzt",
                    "dreh",
                    "drehe",
                    "dich",
                    "um",
                    "nach",
                    "links",
                    "rechts",
                    "fahre",
                    "fahr",
                    "geh",
                    "gehe",
                    "vorwärts",
                    "rückwärts",
                    "zurück",
                    "warte",
                    "sekunden",
                    "grad",
                    "mach",
                    "ein",
                    "foto",
                    "küche",
                    "müll",
                    "basis",
                    "mit",
                    "ist",
                    "ich",
                ]
            ),
        ),
    )
}
"""The languages this release has commands, answers and panel words for; an orders file
may be in any other that an ear hears and text2num reads (`language_of`)."""


def language_of(code: str) -> Language:
    """What is known of `code`: a shipped language, or a bare one (numbers only)."""
    return LANGUAGES.get(code) or Language(code, code)


def _reads(code: str) -> bool:
    try:
        alpha2digit("", code)
    except ValueError:
        return False
    return True


@functools.cache
def reads_numbers(code: str) -> bool:
    """Whether text2num reads spoken numbers in `code`."""
    return _reads(code)


class Numbers:
    """Spoken numbers in one language: a regex for a run of them, reading and saying."""

    def __init__(self, language: Language) -> None:
        self.language = language
        self.code = language.code
        if self.code == "en":
            self.words = NUMBER_WORDS
            self.pattern = NUMBER_PATTERN
            self.starts = NUMBER_WORDS | frozenset(language.sign_words) | {"a"}
            return
        words = {w for n in range(NUMBER_LIMIT) for w in self._said(n).split()}
        words |= set(language.one) | set(language.decimal_words)
        self.words = frozenset(words)
        self.starts = self.words | frozenset(language.sign_words)
        listed = self._listed(words)
        joints = "|".join(map(re.escape, (*language.conjunctions, *language.decimal_words)))
        signs = "|".join(map(re.escape, language.sign_words)) or "(?!)"
        self.pattern = (
            rf"(?:(?:{signs})\s+|-)?"
            r"(?:\d+(?:\.\d+)?"
            rf"|(?:{listed})(?:\s+(?:(?:{joints})\s+)?(?:{listed}))*)"
        )

    def _said(self, value: float) -> str:
        return _spelled(self.code, value)

    def _listed(self, words: set[str]) -> str:
        """A regex matching exactly `words`, one number word each. German writes every
        number below a thousand as one word ("dreihundertfünfundvierzig"): their trie
        took 0.8 s of the converter's start to compile into every slot's pattern, while
        written as a hundred ("dreihundert") and what may follow it, it says the same words
        in a twentieth of the text. Where the words do not compose so, the trie."""
        below = {self._said(n) for n in range(1, 100)}
        hundreds = {self._said(100 * h) for h in range(1, 10)}
        composed = {h + b for h in hundreds for b in below | {""}}
        if not (below <= words and composed <= words):
            return _trie(words)
        return f"(?:{_trie(hundreds)}(?:{_trie(below)})?|{_trie(words - composed)})"

    def read(self, text: str) -> float | None:
        """The number a run of words or digits says, or None if it is not one number."""
        if self.code == "en":
            return read_number(text)
        words = text.lower().split()
        sign = 1.0
        if words and words[0] in self.language.sign_words:
            sign, words = -1.0, words[1:]
        one = self._said(1)
        words = [one if w in self.language.one else w for w in words]
        if not words:
            return None
        digits = alpha2digit(" ".join(words), self.code, threshold=0)
        digits = re.sub(r"(?<=\d),(?=\d)", ".", digits)  # "2,5": a decimal comma
        if not re.fullmatch(r"-?\d+(?:\.\d+)?", digits):
            return None
        return sign * float(digits)

    def say(self, value: float) -> str:
        """Words for `value` that `read` reads back ("zwei komma fünf")."""
        if self.code == "en":
            return say_number(value)
        if abs(value) > MAX_SPOKEN:
            raise ValueError(f"{value:g} is too large to say (at most {MAX_SPOKEN})")
        exact = Decimal(repr(value)).normalize()
        number: float = int(exact) if exact == exact.to_integral_value() else float(exact)
        return self._said(number)


@functools.lru_cache(maxsize=16384, typed=True)
def _spelled(code: str, value: float) -> str:
    """num2words' words for `value` in `code` (typed: 1 is "uno", 1.0 "uno coma cero").
    Every slot, file and grammar of a language asks again for the same values, and
    num2words took most of the converter's start in three languages (1.2 of 1.6 s)."""
    from num2words import num2words  # type: ignore[import-untyped]

    return " ".join(str(num2words(value, lang=code)).lower().replace("-", " ").split())


def _trie(words: set[str]) -> str:
    """One regex matching exactly `words`, as a trie: German writes each number up to 999
    as one word ("fünfundvierzig"), and a thousand alternatives tried one by one at every
    position of every sentence cost the parser's time."""
    tree: dict[str, dict] = {}  # type: ignore[type-arg]
    for word in words:
        node = tree
        for character in word:
            node = node.setdefault(character, {})
        node[""] = {}

    def walk(node: dict[str, dict]) -> str:  # type: ignore[type-arg]
        ends = "" in node
        branches = [re.escape(c) + walk(child) for c, child in sorted(node.items()) if c]
        if not branches:
            return ""
        body = branches[0] if len(branches) == 1 else f"(?:{'|'.join(branches)})"
        return f"(?:{body})?" if ends else body

    return f"(?:{walk(tree)})"


@functools.cache
def numbers_of(code: str) -> Numbers:
    return Numbers(language_of(code))


def unreadable(code: str, values: list[float]) -> list[tuple[float, str]]:
    """The values whose words in `code` text2num does not read back as themselves."""
    wrong = []
    for value in values:
        said = _misread(code, value)
        if said is not None:
            wrong.append((value, said))
    return wrong


@functools.lru_cache(maxsize=16384, typed=True)
def _misread(code: str, value: float) -> str | None:
    """`value`'s words in `code` when text2num does not read them back as `value`, else
    None: the slots of every file in a language share most of their values."""
    numbers = numbers_of(code)
    said = numbers.say(value)
    return None if numbers.read(said) == value else said


def markers_in(words: set[str]) -> dict[str, list[str]]:
    """The marker words (`Language.markers`) of each shipped language found in `words`,
    counting only words no other shipped language marks."""
    found: dict[str, list[str]] = {}
    for code, language in LANGUAGES.items():
        others = set().union(*(o.markers for c, o in LANGUAGES.items() if c != code))
        found[code] = sorted((words & language.markers) - others)
    return found
