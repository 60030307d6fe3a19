"""Text to orders: whole words, most specific match, ties and misses as errors."""

from __future__ import annotations

import math
import time
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from voicectl.services.converter.orders import OrderSet
from voicectl.services.converter.parser import MAX_TEXT_CHARS, Parser, normalise
from voicectl.shared.errors import OrdersFileError
from voicectl.shared.messages import ParseProblem

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
    # 'then' inside a word does not split: the word is left over, and refused
    error = DEMO.parse("turn left thenceforth").errors[0]
    assert error.reason == "words not understood: 'thenceforth'; did you mean: turn left?"
    assert error.candidates == ["turn left"]


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


# --- spoken numbers ---------------------------------------------------------------------------

ALL = Parser(OrderSet.load(Path(__file__).resolve().parents[1] / "orders"))
"""Every shipped file: demo, tutorial and the spoken-number orders together."""


@pytest.mark.parametrize(
    ("text", "order", "case", "pose", "description"),
    [
        ("move forward 2.5 meters", "drive", "forward", (2.5, 0.0), "move forward 2.5 m"),
        ("go forward two point five meters", "drive", "forward", (2.5, 0.0), "move forward 2.5 m"),
        ("Go ahead zero point five metres.", "drive", "forward", (0.5, 0.0), "move forward 0.5 m"),
        ("drive back a hundred and one meters", None, None, None, None),
        ("move back 1 meter", "drive", "back", (-1.0, 0.0), "move back 1 m"),
        ("turn left 45 degrees", "turn_by", "left", (0.0, math.pi / 4), "turn left 45 degrees"),
        ("turn left forty-five degrees", "turn_by", "left", (0.0, math.pi / 4), None),
        ("rotate right ninety degrees", "turn_by", "right", (0.0, -math.pi / 2), None),
    ],
)
def test_spoken_numbers_fill_the_target_pose_in_base_units(
    text: str,
    order: str | None,
    case: str | None,
    pose: tuple[float, float] | None,
    description: str | None,
) -> None:
    result = ALL.parse(text)
    if order is None:
        assert result.orders == []
        return
    assert result.errors == []
    (made,) = result.orders
    assert (made.order, made.case) == (order, case)
    assert made.target_pose is not None
    assert made.target_pose.frame == "base_link"
    assert (made.target_pose.x, made.target_pose.yaw) == pytest.approx(pose)
    if description:
        assert made.description == description


def test_wait_ten_seconds_is_a_parameter_in_seconds() -> None:
    (made,) = ALL.parse("wait ten seconds").orders
    assert (made.order, made.label, made.params, made.target_pose) == (
        "wait",
        "wait",
        {"seconds": 10.0},
        None,
    )
    assert made.description == "wait 10 s"


def test_out_of_range_and_non_numbers_are_errors_naming_the_range() -> None:
    result = ALL.parse("move forward 12 meters then turn left 45 degrees then wait one two seconds")
    assert [(o.order, o.case) for o in result.orders] == [("turn_by", "left")]
    assert [(e.text, e.reason) for e in result.errors] == [
        ("move forward 12 meters", "distance 12 is out of range: 0.1 to 10 m"),
        ("wait one two seconds", "duration: 'one two' is not one number"),
    ]
    assert ALL.parse("wait -3 seconds").errors[0].reason == (
        "duration -3 is out of range: 0.5 to 60 s"
    )


def test_a_number_makes_the_order_more_specific_than_the_demo_one() -> None:
    assert names("move forward", ALL) == [("local_goal", "forward")]
    assert names("move forward 2 meters", ALL) == [("drive", "forward")]
    assert names("turn left then turn left 90 degrees", ALL) == [
        ("rotation", "left"),
        ("turn_by", "left"),
    ]
    # Out of range is an error, never the less specific "move forward" (1 m).
    assert ALL.parse("move forward 12 meters").orders == []


def test_and_joins_commands_as_the_separator_does() -> None:
    assert names("turn right and move forward one meter", ALL) == [
        ("rotation", "right"),
        ("drive", "forward"),
    ]
    assert names("Turn left, and then reach the kitchen.", ALL) == [
        ("rotation", "left"),
        ("goal", "kitchen"),
    ]
    assert names("turn left and reach the kitchen and take a picture", ALL) == [
        ("rotation", "left"),
        ("goal", "kitchen"),
        ("take_photo", None),
    ]


def test_and_inside_a_number_stays_in_the_number() -> None:
    result = ALL.parse("move forward one hundred and five meters")
    assert result.orders == []
    assert [e.reason for e in result.errors] == ["distance 105 is out of range: 0.1 to 10 m"]


def test_a_last_and_says_more_was_to_come_and_stays_an_error() -> None:
    result = ALL.parse("turn left and")
    assert result.orders == []
    assert "'and'" in result.errors[0].reason


@pytest.mark.parametrize(
    ("text", "description"),
    [
        ("Move forward 4.5 m", "move forward 4.5 m"),
        ("go forward 2.5m.", "move forward 2.5 m"),
        ("Turn left 90°.", "turn left 90 degrees"),
        ("turn right 45 deg", "turn right 45 degrees"),
        ("wait 10 s", "wait 10 s"),
        ("wait 10s", "wait 10 s"),
    ],
)
def test_unit_symbols_after_a_number_are_read_as_the_unit(text: str, description: str) -> None:
    assert [o.description for o in ALL.parse(text).orders] == [description]


def test_a_unit_symbol_that_an_alias_uses_is_left_as_it_is() -> None:
    orders = OrderSet.from_yaml(
        "orders:\n"
        "  hop:\n"
        "    voice_alias: 'hop {d} m'\n"
        "    label: x\n"
        "    slots: {d: {type: number, unit: m, min: 1, max: 5, to: x}}\n"
    )
    assert [o.order for o in Parser(orders).parse("hop 2 m").orders] == ["hop"]
    assert Parser(orders).parse("hop 2 meters").orders == []


def test_normalise_keeps_a_minus_sign_starting_a_number() -> None:
    assert normalise("Wait -3 seconds, x-ray") == "wait -3 seconds x ray"


# --- bad input -------------------------------------------------------------------------------


def test_bad_input_is_one_clear_error() -> None:
    assert ALL.parse("").errors == [ParseProblem(text="", reason="empty text")]
    huge = ALL.parse("x" * 100_000)
    assert huge.errors[0].reason == f"text too long: 100000 characters, at most {MAX_TEXT_CHARS}"
    assert len(huge.errors[0].text) <= 80
    junk = ALL.parse(bytes(range(256)).decode("latin-1"))
    assert junk.orders == []
    assert all(e.reason for e in junk.errors)
    assert names("\x00turn\x00left\ufeff", ALL) == [("rotation", "left")]


# --- the word index gives the same answers as trying every regex -----------------------------

BRUTE = Parser(ALL.orders, use_index=False)
_VOCABULARY = sorted(
    {w for c in ALL.orders.commands for t in c.expansion.templates for w in t if isinstance(w, str)}
    | {"then", "two", "point", "five", "forty", "a", "hundred", "minus", "2.5", "-3", "please"}
)


@settings(max_examples=300)
@given(st.lists(st.sampled_from(_VOCABULARY) | st.text(max_size=6), max_size=12))
def test_the_index_never_changes_a_result(words: list[str]) -> None:
    text = " ".join(words)
    assert ALL.parse(text) == BRUTE.parse(text)


@given(st.text(max_size=300))
def test_parser_with_slots_never_raises_on_any_text(text: str) -> None:
    result = ALL.parse(text)
    assert all(e.reason for e in result.errors)


@given(st.lists(st.sampled_from(_VOCABULARY), max_size=20))
def test_parser_with_slots_never_raises_on_command_words(words: list[str]) -> None:
    result = ALL.parse(" ".join(words))
    assert all(e.reason for e in result.errors)
    for order in result.orders:
        if order.target_pose is not None:
            assert math.isfinite(order.target_pose.x)
            assert math.isfinite(order.target_pose.yaw)


def test_a_slot_in_an_optional_part_may_go_unsaid() -> None:
    parser = Parser(
        OrderSet.from_yaml(
            """
orders:
  pause:
    voice_alias: "pause( for {n} seconds?)?"
    description: "pause {n}"
    label: wait
    seconds: 3
    slots:
      n: {min: 1, max: 60, unit: s, to: seconds}
"""
        )
    )
    (short,) = parser.parse("pause").orders
    assert (short.params, short.description) == ({"seconds": 3}, "pause")
    (longer,) = parser.parse("pause for twenty seconds").orders
    assert (longer.params, longer.description) == ({"seconds": 20.0}, "pause 20")


# --- skip words and leftover words ------------------------------------------------------------

ALL = Parser(OrderSet.load(Path(__file__).resolve().parents[1] / "orders"))


@pytest.mark.parametrize(
    ("said", "meant"),
    [
        ("reach the kitchen", [("goal", "kitchen")]),
        ("turn to the left", [("rotation", "left")]),
        (
            "please turn left then go to the kitchen now",
            [("rotation", "left"), ("goal", "kitchen")],
        ),
        ("take a picture", [("take_photo", None)]),
        ("now please move the forward", [("local_goal", "forward")]),
        ("turn left to forty five degrees", [("turn_by", "left")]),
    ],
)
def test_skip_words_may_stand_around_and_between_the_words_of_a_command(
    said: str, meant: list[tuple[str, str | None]]
) -> None:
    result = ALL.parse(said)
    assert [(o.order, o.case) for o in result.orders] == meant
    assert result.errors == []


def test_words_left_over_are_an_error_that_suggests_the_command_matched() -> None:
    result = DEMO.parse("move forward two point five meters then turn left 45 degrees")
    assert result.orders == []
    assert [(e.text, e.reason, e.candidates) for e in result.errors] == [
        (
            "move forward two point five meters",
            "words not understood: 'two point five meters'; did you mean: move forward?",
            ["move forward"],
        ),
        (
            "turn left 45 degrees",
            "words not understood: '45 degrees'; did you mean: turn left?",
            ["turn left"],
        ),
    ]
    # With the spoken orders loaded the numbers are part of the command.
    assert [o.description for o in ALL.parse("turn left 45 degrees").orders] == [
        "turn left 45 degrees"
    ]


def test_an_alias_that_names_a_skip_word_still_needs_it() -> None:
    assert names("go to the kitchen", ALL) == [("goal", "kitchen")]
    result = ALL.parse("go kitchen")
    assert result.orders == []
    assert result.errors[0].candidates == ["go to kitchen"]


def test_skip_words_can_be_changed_or_turned_off() -> None:
    yaml = (
        "orders_list:\n  skip_words: {words}\n  orders:\n"
        "    fetch: {{voice_alias: 'fetch box', label: x}}\n"
    )
    off = Parser(OrderSet.from_yaml(yaml.format(words="[]")))
    assert off.parse("fetch the box").orders == []
    assert [o.order for o in off.parse("fetch box").orders] == ["fetch"]
    own = Parser(OrderSet.from_yaml(yaml.format(words="[that, please]")))
    assert [o.order for o in own.parse("please fetch that box").orders] == ["fetch"]
    assert own.parse("fetch the box").orders == []


@pytest.mark.parametrize(
    ("words", "message"),
    [
        ("the", "<text>: 'skip_words' must be a list of words (line 2)"),
        (
            "[The]",
            "<text>: skip_words: 'The' must be one lower-case word without punctuation (line 2)",
        ),
        ("['two words']", "skip_words: 'two words' must be one lower-case word"),
        ("[3]", "skip_words: 3 must be one lower-case word"),
    ],
)
def test_bad_skip_words_are_one_line_errors_with_their_line(words: str, message: str) -> None:
    yaml = f"orders_list:\n  skip_words: {words}\n  orders:\n    a: {{voice_alias: a, label: x}}\n"
    with pytest.raises(OrdersFileError) as raised:
        OrderSet.from_yaml(yaml)
    assert message in "\n".join(getattr(raised.value, "errors", [str(raised.value)]))


def test_files_that_disagree_on_skip_words_are_an_error_naming_them(tmp_path: Path) -> None:
    for name, words in (("a.yaml", "[the]"), ("b.yaml", "[a]")):
        (tmp_path / name).write_text(
            f"skip_words: {words}\norders:\n  {name[0]}: {{voice_alias: {name[0]}, label: x}}\n"
        )
    (tmp_path / "c.yaml").write_text("orders:\n  c: {voice_alias: c, label: x}\n")
    with pytest.raises(OrdersFileError, match="disagree on skip_words") as raised:
        OrderSet.load(tmp_path)
    assert "a.yaml" in str(raised.value)
    assert "b.yaml" in str(raised.value)
    assert "c.yaml" not in str(raised.value)  # a file that says nothing agrees with any


@given(st.lists(st.sampled_from(["the", "please", "now", "to", "a"]), max_size=3))
def test_any_skip_words_around_a_command_leave_its_order(extra: list[str]) -> None:
    said = " ".join([*extra, "reach", *extra, "kitchen", *extra])
    assert names(said, ALL) == [("goal", "kitchen")]


def test_an_alias_that_backtracks_cannot_freeze_the_parser() -> None:
    slow = Parser(
        OrderSet.from_yaml(
            "orders:\n"
            "  echo: {voice_alias: '(a|aa)+\\\\1b', label: x}\n"
            "  turn: {voice_alias: 'turn', label: x}\n"
        )
    )
    # CPU time, not wall time: a frozen parser burns a core, a busy machine only waits.
    started = time.thread_time()
    result = slow.parse("a" * 60 + " then turn")
    assert time.thread_time() - started < 2.0
    [error] = result.errors
    assert error.reason.startswith("order 'echo' took over 250 ms to match")
    assert [o.order for o in result.orders] == ["turn"]
    # The classic trap is refused when the file loads, with what is wrong.
    with pytest.raises(OrdersFileError, match="repeats a repetition"):
        OrderSet.from_yaml("orders:\n  trap: {voice_alias: '(a+)+b', label: x}\n")
