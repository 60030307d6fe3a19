"""Text to orders: whole words, most specific match, ties and misses as errors."""

from __future__ import annotations

from pathlib import Path

from hypothesis import given
from hypothesis import strategies as st

from services.converter.orders import OrderSet
from services.converter.parser import MAX_TEXT_CHARS, Parser, normalise

DEMO = Parser(OrderSet.load(Path(__file__).resolve().parents[1] / "orders" / "demo.yaml"))


def names(text: str, parser: Parser = DEMO) -> list[tuple[str, str | None]]:
    return [(o.order, o.case) for o in parser.parse(text).orders]


def test_sequence_in_spoken_order() -> None:
    result = DEMO.parse("turn left then reach kitchen")
    assert [(o.order, o.case) for o in result.orders] == [("rotation", "left"), ("goal", "kitchen")]
    assert result.errors == []
    assert result.orders[0].description == "turn left"
    assert result.orders[1].target_pose is not None
    assert result.orders[1].target_pose.yaw == 1.0


def test_case_punctuation_and_spacing_do_not_matter() -> None:
    assert names("  Turn LEFT,   THEN reach   Kitchen! ") == [
        ("rotation", "left"),
        ("goal", "kitchen"),
    ]


def test_aliases_match_whole_words_only() -> None:
    result = DEMO.parse("return left")
    assert result.orders == []
    assert result.errors[0].reason == "no order matches"
    assert names("turn leftover") == []
    # 'then' inside a word does not split
    assert names("turn left thenceforth") == [("rotation", "left")]


def test_regex_alternatives_and_optionals() -> None:
    assert names("move straight") == [("local_goal", "forward")]
    assert names("move backward") == [("local_goal", "back")]
    assert names("turn back") == [("rotation", "back")]


def test_unknown_segment_is_an_error_that_keeps_the_other_orders() -> None:
    result = DEMO.parse("turn left then dance then reach base")
    assert [(o.order, o.case) for o in result.orders] == [("rotation", "left"), ("goal", "base")]
    assert [(e.text, e.reason) for e in result.errors] == [("dance", "no order matches")]


def test_order_without_its_case_names_the_cases() -> None:
    result = DEMO.parse("turn")
    assert result.orders == []
    assert "left, right, back" in result.errors[0].reason
    assert result.errors[0].candidates == ["rotation/left", "rotation/right", "rotation/back"]


def test_most_specific_match_wins_and_ties_are_errors() -> None:
    parser = Parser(
        OrderSet.from_yaml(
            """
orders:
  go: {voice_alias: "go", label: a}
  go_home: {voice_alias: "go home", label: b}
  stop: {voice_alias: "stop", label: c}
  halt: {voice_alias: "stop", label: d}
"""
        )
    )
    assert names("please go home now", parser) == [("go_home", None)]
    assert names("go", parser) == [("go", None)]
    result = parser.parse("stop")
    assert result.orders == []
    assert result.errors[0].reason == "ambiguous: matches stop, halt"
    assert result.errors[0].candidates == ["stop", "halt"]


def test_empty_and_oversized_text() -> None:
    assert DEMO.parse("").errors[0].reason == "empty text"
    assert DEMO.parse(" ,.; ").errors[0].reason == "empty text"
    huge = DEMO.parse("turn left " * 10_000)
    assert huge.orders == []
    assert huge.errors[0].reason.startswith("text too long")
    assert str(MAX_TEXT_CHARS) in huge.errors[0].reason


def test_empty_segments_are_ignored() -> None:
    assert names("then turn left then then") == [("rotation", "left")]


def test_normalise_keeps_decimal_points() -> None:
    assert normalise("Move 2.5 m. Then, stop!") == "move 2.5 m then stop"


@given(st.text(max_size=300))
def test_parser_never_raises_and_accounts_for_every_segment(text: str) -> None:
    result = DEMO.parse(text)
    for error in result.errors:
        assert error.reason


@given(st.binary(max_size=300))
def test_binary_junk_decoded_loosely_never_raises(junk: bytes) -> None:
    DEMO.parse(junk.decode("utf-8", "replace"))
