"""The recogniser's grammar: every phrase the orders can produce, as JSGF and as lists.

The JSGF is exact for every expandable alias: slots become rules listing their values as
words ("two point five"), so a 180-value angle costs one rule, not 180 phrases per alias.
The phrase list spells everything out, up to `MAX_PHRASES` per command; a command with
more, or whose alias cannot be expanded at all, is listed in `unexpandable` and gives its
words instead. In the JSGF such an alias becomes "one or more of its words".

Skip words stand where people put them, which is narrower than where the parser lets them
(the parser reads typed text; the grammar constrains a search that will explain any sound
as some phrase it allows). Between two words of a command at most one (`<skip>`: "reach
the kitchen"), never inside a spoken number; before and after a whole command only the
courtesy words of `EDGE_WORDS` (`<edge>`: "please turn left now"). With two skip words
anywhere, the search explained "can you hear me" as "turn the the right" and "turn on the
lights" as "to turn back" (bench/stt.py, dev split).

Edits of the queue (orders of label `queue`) may also stand next to an order without the
separator, one before it and one after ("after that go to base", "go forward two meters
no three"), as the parser reads them; without such orders the grammar is as before.
"""

from __future__ import annotations

import hashlib
import itertools
import math
from collections.abc import Callable, Iterable

from voicectl.shared.edits import QUEUE_LABEL
from voicectl.shared.messages import Grammar

from .expand import SlotRef, Template
from .model import Command
from .orders import OrderSet
from .text import normalise

EDGE_WORDS = ("please", "now")
"""Skip words that may also open or close a command; the others stand only inside one."""
MAX_PHRASES = 5000
"""Per command; beyond this the phrase list gives the command's words instead."""
GRAMMAR_NAME = "voicectl"


def build_grammar(orders: OrderSet) -> Grammar:
    """The grammar of `orders`; a pure function of them (its version is a digest)."""
    builder = _Builder(orders.skip_words, orders.numbers.say)
    for command in orders.commands:
        builder.add(command)
    separator = orders.separator_expansion
    separator_phrases = [" ".join(str(w) for w in t) for t in separator.templates]
    builder.words.update(w for t in separator_phrases for w in t.split())
    if separator.finite:
        separator_rule = " | ".join(separator_phrases)
    else:
        builder.unexpandable.append(f"separator {orders.separator!r}: {separator.problem}")
        separator_rule = _word_loop(separator.words) or "<VOID>"
        builder.words.update(_clean(separator.words))
    jsgf = builder.jsgf(separator_rule)
    phrases = list(dict.fromkeys(builder.phrases))
    digest = hashlib.sha256("\n".join([jsgf, *phrases]).encode()).hexdigest()
    return Grammar(
        jsgf=jsgf,
        phrases=phrases,
        words=sorted(builder.words),
        separator_phrases=separator_phrases,
        skip_words=list(orders.skip_words),
        language=orders.language,
        number_words=sorted(builder.number_words),
        leading=sorted(builder.leading),
        unexpandable=builder.unexpandable,
        version=digest[:16],
    )


class _Builder:
    def __init__(self, skip_words: tuple[str, ...], say: Callable[[float], str]) -> None:
        self.skip_words = skip_words
        self.say = say
        """The orders' language's words for a number."""
        self.gap = " <skip> " if skip_words else " "
        """What stands between two words of a command in the JSGF."""
        self.rules: list[tuple[str, str, str]] = []
        """(rule name, body, command name)."""
        self.edits: set[str] = set()
        """The rules of edits of the queue."""
        self.number_rules: dict[tuple[str, ...], str] = {}
        self.number_words: set[str] = set()
        self.leading: set[str] = set()
        """The phrases of edits that bring the orders said after them."""
        self.phrases: list[str] = []
        self.words: set[str] = set(skip_words)
        self.unexpandable: list[str] = []

    def add(self, command: Command) -> None:
        rule = f"c{len(self.rules)}"
        if command.order.label == QUEUE_LABEL:
            self.edits.add(rule)
        expansion = command.expansion
        if not expansion.finite:
            self.unexpandable.append(f"{command.name}: {expansion.problem}")
            self.words.update(_clean(expansion.words))
            loop = _word_loop(expansion.words)
            if loop:
                self.rules.append((rule, loop, command.name))
            return
        values = {name: [self.say(v) for v in s.heard()] for name, s in command.slots.items()}
        alternatives = [self._jsgf_template(t, values) for t in expansion.templates]
        self.rules.append((rule, " | ".join(alternatives), command.name))
        for template in expansion.templates:
            self.words.update(w for w in template if isinstance(w, str))
        for spoken in values.values():
            self.words.update(w for value in spoken for w in value.split())
            self.number_words.update(w for value in spoken for w in value.split())
        count = sum(_count(t, values) for t in expansion.templates)
        if count > MAX_PHRASES:
            self.unexpandable.append(
                f"{command.name}: {count} phrases, more than {MAX_PHRASES}; "
                "its words are listed instead"
            )
            return
        for template in expansion.templates:
            self.phrases.extend(_phrases(template, values))
        if command.order.label == QUEUE_LABEL and command.order.values.get("edit") == "after":
            for template in expansion.templates:
                self.leading.update(_phrases(template, values))

    def _jsgf_template(self, template: Template, values: dict[str, list[str]]) -> str:
        words = []
        for word in template:
            if isinstance(word, SlotRef):
                spoken = tuple(values[word.name])
                name = self.number_rules.setdefault(spoken, f"n{len(self.number_rules)}")
                words.append(f"<{name}>")
            else:
                words.append(word)
        return self.gap.join(words)

    def jsgf(self, separator_rule: str) -> str:
        edges = [w for w in self.skip_words if w in EDGE_WORDS]
        edge = "<edge> " if edges else ""
        tasks = [name for name, _, _ in self.rules if name not in self.edits]
        edits = [name for name, _, _ in self.rules if name in self.edits]
        if edits and tasks:
            # An edit may stand next to an order, without the separator.
            part = "<part>"
            beside = f"[ <edit> {edge}]"
            alone = f"{edge}<edit> {edge}".rstrip()
            parts = [f"<part> = {edge}{beside} <task> {edge}{beside} | {alone};"]
        else:
            part = f"{edge}<order> {edge}".strip()
            parts = []
        lines = [
            "#JSGF V1.0;",
            f"grammar {GRAMMAR_NAME};",
            f"public <command> = {part} ( <separator> {part} )*;",
            f"<separator> = {separator_rule};",
            *parts,
        ]
        if edges:
            lines.append(f"<edge> = [ {' | '.join(edges)} ];")
        if self.skip_words:
            lines.append(f"<skip> = [ {' | '.join(self.skip_words)} ];")
        if parts:
            lines.append(f"<task> = {' | '.join(f'<{name}>' for name in tasks)};")
            lines.append(f"<edit> = {' | '.join(f'<{name}>' for name in edits)};")
        else:
            names = " | ".join(f"<{name}>" for name, _, _ in self.rules)
            lines.append(f"<order> = {names or '<VOID>'};")
        lines.extend(f"<{name}> = {body}; // {command}" for name, body, command in self.rules)
        for spoken, name in self.number_rules.items():
            lines.append(f"<{name}> = {' | '.join(spoken)};")
        return "\n".join(lines) + "\n"


def _count(template: Template, values: dict[str, list[str]]) -> int:
    return math.prod(len(values[w.name]) for w in template if isinstance(w, SlotRef))


def _phrases(template: Template, values: dict[str, list[str]]) -> Iterable[str]:
    choices = [values[w.name] if isinstance(w, SlotRef) else [w] for w in template]
    return (" ".join(words) for words in itertools.product(*choices))


def _clean(words: Iterable[str]) -> list[str]:
    """The words a recogniser could say: those already in normal form."""
    return [w for w in words if w and normalise(w) == w]


def _word_loop(words: Iterable[str]) -> str:
    clean = _clean(words)
    return f"( {' | '.join(clean)} )+" if clean else ""
