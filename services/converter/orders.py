"""Orders files: YAML in, a validated `OrderSet` out, or errors that each fit on a line.

The shape (the ``orders_list`` wrapper is optional)::

    orders_list:
      separator: "then"            # regex between the orders of one utterance
      skip_words: [the, please]    # small words people add; default DEFAULT_SKIP_WORDS
      orders:
        rotation:                  # order name
          voice_alias: "turn"      # regex, mandatory
          label: "mbgoal"          # executor label, mandatory
          frame: "base_link"       # frame/x/y/yaw make the target pose
          cases:
            left: {voice_alias: "left", yaw: 1.57}
            by:                    # a typed slot: "turn by 45 degrees"
              voice_alias: "by {angle} degrees?"
              slots: {angle: {type: number, unit: deg, min: 1, max: 180, to: yaw}}

Any other key of an order or case is a parameter of the order: unknown keys are
meaningful here, so they are kept rather than refused.

This module joins files into one `OrderSet`; orders_file.py reads and checks one file,
model.py holds what a file says (orders, cases, commands), patterns.py its regexes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from voicectl.shared.errors import OrdersFileError

from .expand import Expansion, expand
from .language import DEFAULT, Language, Numbers, language_of, numbers_of
from .model import Command, OrderSpec
from .orders_file import (
    DEFAULT_SEPARATOR,
    DEFAULT_SKIP_WORDS,
    OrdersInvalid,
    Problem,
    check_file,
    read_yaml,
)
from .refer import names_of, spelled

__all__ = ["DEFAULT_SKIP_WORDS", "OrderSet", "OrdersInvalid", "load_languages", "orders_files"]


def orders_files(path: Path) -> list[Path]:
    """The files an orders path stands for: itself, or the *.yaml/*.yml in a directory."""
    if path.is_dir():
        return sorted([*path.glob("*.yaml"), *path.glob("*.yml")])
    return [path]


@dataclass(frozen=True)
class OrderSet:
    """Every order the converter knows, and how utterances are split."""

    orders: tuple[OrderSpec, ...]
    separator: str = DEFAULT_SEPARATOR
    declared_skip_words: tuple[str, ...] | None = None
    """The files' `skip_words`; None when no file says, and `DEFAULT_SKIP_WORDS` apply."""
    sources: tuple[str, ...] = field(default=())
    commands: tuple[Command, ...] = ()
    """Every whole command, in file order."""
    prefixes: tuple[Command, ...] = ()
    """The aliases of orders with cases, alone."""
    separator_expansion: Expansion = field(default_factory=Expansion)
    language: str = DEFAULT
    """The language every file of the set is written in."""
    templates: tuple[Command, ...] = ()
    """Commands that name a queued order (`{order}`), as written: `commands` holds what
    they make with each name of these orders (refer.py)..."""
    spelt: int = 0
    """...at its end, this many: made again whenever files are joined."""

    @property
    def written(self) -> tuple[Command, ...]:
        """The whole commands as the files write them, without those templates made."""
        return self.commands[: len(self.commands) - self.spelt]

    @property
    def skip_words(self) -> tuple[str, ...]:
        """The small words the parser ignores between and around a command's words."""
        if self.declared_skip_words is None:
            return language_of(self.language).skip_words or DEFAULT_SKIP_WORDS
        return self.declared_skip_words

    @property
    def spoken(self) -> Language:
        """What is known of the set's language: its "and", unit words, numbers."""
        return language_of(self.language)

    @property
    def numbers(self) -> Numbers:
        return numbers_of(self.language)

    @staticmethod
    def load(path: Path, language: str = DEFAULT) -> OrderSet:
        """Load one YAML file, or the ``*.yaml``/``*.yml`` of a directory written in
        `language` (every file is read and checked; `load_languages` keeps them all)."""
        if path.is_dir():
            sets = load_languages(path)
            if language not in sets:
                raise OrdersFileError(
                    f"{path}: no orders in language {language!r}; "
                    f"its files are in {', '.join(sorted(sets))}"
                )
            return sets[language]
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise OrdersFileError(f"{path}: cannot read orders file: {exc}") from exc
        return OrderSet.from_yaml(text, str(path))

    @staticmethod
    def from_yaml(text: str, source: str = "<text>") -> OrderSet:
        return OrderSet.from_dict(read_yaml(text, source), source)

    @staticmethod
    def from_dict(data: Any, source: str = "<dict>") -> OrderSet:
        checked = check_file(data, source)
        return OrderSet.build(
            checked.orders,
            checked.commands,
            checked.separator,
            checked.skip_words,
            (source,),
            checked.language,
        )

    @staticmethod
    def build(
        orders: tuple[OrderSpec, ...],
        commands: list[Command],
        separator: str,
        skip_words: tuple[str, ...] | None,
        sources: tuple[str, ...],
        language: str = DEFAULT,
    ) -> OrderSet:
        templates = tuple(c for c in commands if c.refs)
        plain = [c for c in commands if not c.refs]
        whole = [c for c in plain if c.case or not c.order.cases]
        try:
            named = spelled(templates, names_of(whole))
        except ValueError as exc:
            raise OrdersInvalid([(f"{', '.join(sources)}: {exc}", None)]) from exc
        return OrderSet(
            language=language,
            orders=orders,
            separator=separator,
            declared_skip_words=skip_words,
            sources=sources,
            commands=(*whole, *named),
            prefixes=tuple(c for c in plain if c.order.cases and not c.case),
            separator_expansion=expand(separator),
            templates=templates,
            spelt=len(named),
        )

    @staticmethod
    def merge(sets: list[OrderSet]) -> OrderSet:
        """Join several files; the same order name twice is an error naming both files."""
        seen: dict[str, str] = {}
        problems: list[Problem] = []
        for order_set in sets:
            for order in order_set.orders:
                if order.name in seen:
                    problems.append(
                        (
                            f"{order.source}: order '{order.name}' is already defined in "
                            f"{seen[order.name]}",
                            order.line,
                        )
                    )
                else:
                    seen[order.name] = order.source
        if problems:
            raise OrdersInvalid(problems)
        separators = {s.separator for s in sets}
        if len(separators) > 1:
            raise OrdersFileError(
                "orders files disagree on the separator: " + ", ".join(sorted(separators))
            )
        declared = {s.declared_skip_words for s in sets} - {None}
        if len(declared) > 1:
            raise OrdersFileError(
                "orders files disagree on skip_words: "
                + "; ".join(
                    f"{', '.join(s.sources)}: {list(s.declared_skip_words)}"
                    for s in sets
                    if s.declared_skip_words is not None
                )
            )
        return OrderSet.build(
            tuple(o for s in sets for o in s.orders),
            [c for s in sets for c in (*s.prefixes, *s.written, *s.templates)],
            separators.pop(),
            declared.pop() if declared else None,
            tuple(src for s in sets for src in s.sources),
            sets[0].language,
        )


def load_languages(path: Path) -> dict[str, OrderSet]:
    """Every orders file at `path` (a file, or a directory's ``*.yaml``), read, checked
    and joined per language: the same orders may come in several languages, each file
    saying its own (`language: es`). OrdersInvalid lists every problem of every file."""
    if not path.is_dir():
        single = OrderSet.load(path)
        return {single.language: single}
    files = orders_files(path)
    if not files:
        raise OrdersFileError(f"{path}: no *.yaml orders files in this directory")
    by_language: dict[str, list[OrderSet]] = {}
    problems: list[Problem] = []
    for file in files:
        try:
            one = OrderSet.load(file)
        except OrdersInvalid as exc:
            problems.extend(exc.problems)
        except OrdersFileError as exc:
            problems.append((str(exc), None))
        else:
            by_language.setdefault(one.language, []).append(one)
    merged: dict[str, OrderSet] = {}
    for language, sets in by_language.items():
        try:
            merged[language] = OrderSet.merge(sets)
        except OrdersInvalid as exc:
            problems.extend(exc.problems)
        except OrdersFileError as exc:
            problems.append((f"language {language}: {exc}", None))
    if problems:
        raise OrdersInvalid(problems)
    return merged


def check_heard(sets: dict[str, OrderSet], heard: frozenset[str]) -> None:
    """Orders in a language no installed ear hears are refused: nobody could say them.
    One line naming the first file and the language."""
    for language, orders in sets.items():
        if language not in heard:
            raise OrdersFileError(
                f"{orders.sources[0]}: language {language}: no installed speech engine "
                f"hears it (installed: {', '.join(sorted(heard)) or 'none'}); "
                "pip install 'voicectl[stt]' brings Whisper, which hears 99 languages"
            )
