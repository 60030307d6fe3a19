"""The regexes of an orders file: aliases with slots, checked and assembled.

An alias is a regex that may name slots (``by {angle} degrees``). Here it is checked
(it compiles, cannot match empty text, repeats no repetition) and joined with the
aliases it is said after, skip words allowed wherever it has a space.

Two regex dialects meet in the converter, and must: checks, assembly and the expansion
the recogniser's grammar is built from (expand.py) use Python's `re`, because `re`'s
parser is the one parser of this syntax Python has, so a pattern is checked by the same
reading that expands it. Matching uses the `regex` module (parser.py), because only it
can stop a search after a time limit. `regex` reads the constructs the checks here
admit as `re` does; where the two could still disagree, parser.py notices at load time
(an expanded phrase its compiled pattern does not match) and then tries that command on
every sentence rather than trust the expansion.
"""

from __future__ import annotations

import re

from .expand import nested_repeat
from .slots import NUMBER_PATTERN

PLACEHOLDER = re.compile(r"(?<!\\)\{([A-Za-z_]\w*)\}")
"""A slot inside an alias or description: ``{distance}`` (a quantifier has digits only)."""
QUANTIFIER = re.compile(r"[*+?]|\{\d*(?:,\d*)?\}")
SLOT_GROUP = "slot_"
"""Prefix of the named regex group a slot becomes."""
SLOT_STUB = "#"
"""Stands for a number when an alias is only checked or expanded."""


def check_regex(pattern: str) -> None:
    try:
        compiled = re.compile(pattern)
    except re.error as exc:
        raise ValueError(f"invalid regex {plain(pattern)!r}: {exc}") from exc
    if compiled.match(""):
        raise ValueError(f"regex {plain(pattern)!r} matches empty text")
    nested = nested_repeat(pattern)
    if nested:
        raise ValueError(
            f"regex {plain(pattern)!r} repeats a repetition ({nested}): it can take "
            "exponential time on text that almost matches; write it with one repetition"
        )


def plain(pattern: str) -> str:
    """The pattern as the user wrote it, slots back in braces."""
    return re.sub(rf"\(\?P<{SLOT_GROUP}(\w+)>{re.escape(SLOT_STUB)}\)", r"{\1}", pattern)


def with_slots(alias: str, body: str = NUMBER_PATTERN) -> str:
    """The alias with each ``{name}`` replaced by a named group matching one number.

    Checks and expansion use a one-character `body`: the number pattern is long, and
    parsing it for every alias made loading a 200-order file take a second.
    """
    return PLACEHOLDER.sub(lambda m: f"(?P<{SLOT_GROUP}{m[1]}>{body})", alias)


def combined(aliases: tuple[str, ...], slot_body: str, skip_words: tuple[str, ...]) -> str:
    """Aliases said one after the other, as one regex; `skip_words` may stand wherever
    there is a space between words (none for the recogniser's expansion)."""
    gap = r"\s+"
    if skip_words:
        gap += r"(?:(?:" + "|".join(map(re.escape, skip_words)) + r")\s+)*"
    return gap.join(f"(?:{with_slots(spaced(alias, gap), slot_body)})" for alias in aliases)


def spaced(alias: str, gap: str) -> str:
    """`alias` with each run of plain spaces between words replaced by the regex `gap`.

    Spaces inside a character class, escaped, or under a quantifier (" ?") stay as written.
    """
    if gap == r"\s+":
        return alias
    out: list[str] = []
    position = 0
    in_class = False
    while position < len(alias):
        char = alias[position]
        if char == "\\":
            out.append(alias[position : position + 2])
            position += 2
            continue
        if in_class:
            in_class = char != "]"
        elif char == "[":
            in_class = True
        elif char == " ":
            end = position
            while end < len(alias) and alias[end] == " ":
                end += 1
            if not QUANTIFIER.match(alias, end):
                out.append(gap)
                position = end
                continue
        out.append(char)
        position += 1
    return "".join(out)
