"""Near-misses: suggestions offered as error candidates, never dispatched; unrelated speech
gets none. The two lists below are the ones the threshold was chosen on."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from voicectl.services.converter.orders import OrderSet
from voicectl.services.converter.parser import Parser
from voicectl.services.converter.suggest import MAX_QUERY_CHARS, MAX_SUGGESTIONS

ALL = Parser(OrderSet.load(Path(__file__).resolve().parents[1] / "orders"))

NEAR_MISSES = [
    ("reach kitchn", "reach kitchen"),
    ("teach kitchen", "reach kitchen"),
    ("rich kitchen", "reach kitchen"),
    ("kitchen reach", "reach kitchen"),
    ("reach dumpsters", "reach dumpster"),
    ("return left", "turn left"),
    ("turn lift", "turn left"),
    ("burn left", "turn left"),
    ("left turn", "turn left"),
    ("turn write", "turn right"),
    ("move strait", "move straight"),
    ("take a pictures", "take a picture"),
    ("take photograph", "take photo"),
    ("multiply prime", "multiply primes"),
    ("weight ten seconds", "wait ten seconds"),
    ("move forwad 2 meters", "move forward 2 meters"),
    ("go forwards two point five meters", "go forward two point five meters"),
    ("rotate left 45 degreez", "rotate left 45 degree"),
    # Two misspelt words and the skip words the parser ignores anyway.
    ("raech the kichen", "reach kitchen"),
    ("please raech the kichen now", "reach kitchen"),
]

UNRELATED = [
    "what is the weather today",
    "what time is it",
    "hello there",
    "thank you",
    "play some music",
    "turn on the lights",
    "turn it off",
    "stop",
    "yes please",
    "tell me a joke",
    "set an alarm for seven",
    "open the door",
    "i want to go home",
    "the kitchen is dirty",
    "take it easy",
    "good morning",
    "move on",
    "go away",
    "wait a minute",
    "reach for the stars",
    "multiply by two",
    "turn",
    "kitchen",
    "the",
    # With the skip words ("the", "a", "to", "please", "now") that suggestions look past.
    "put the kettle on now",
    "the dog wants to go out",
    "reach the top shelf",
    "the kitchen smells nice",
    "wait for the bus",
    "take a break now",
    "the dumpster is full",
    "go back to the start",
    "reach out to the team",
]


@pytest.mark.parametrize(("heard", "meant"), NEAR_MISSES)
def test_a_near_miss_is_an_error_whose_first_candidate_is_the_command(
    heard: str, meant: str
) -> None:
    result = ALL.parse(heard)
    assert result.orders == []  # never dispatched
    (error,) = result.errors
    assert error.candidates[0] == meant
    assert error.reason == "no order matches" or error.reason.endswith(
        f"did you mean: {' or '.join(error.candidates)}?"
    )


@pytest.mark.parametrize("heard", [*UNRELATED, *(f"please {text} now" for text in UNRELATED)])
def test_unrelated_speech_gets_no_suggestion(heard: str) -> None:
    result = ALL.parse(heard)
    assert result.orders == []
    (error,) = result.errors
    assert "did you mean" not in error.reason
    # Errors that name the missing cases keep order names, not phrases.
    assert all("/" in c for c in error.candidates), error.candidates


def test_every_suggestion_parses_to_exactly_one_order_alone() -> None:
    for heard, _ in NEAR_MISSES:
        for candidate in ALL.parse(heard).errors[0].candidates:
            result = ALL.parse(candidate)
            assert len(result.orders) == 1, candidate
            assert result.errors == []


def test_suggestions_keep_the_spoken_number_and_never_invent_one() -> None:
    assert ALL.parse("move forwad 2 meters").errors[0].candidates == ["move forward 2 meters"]
    # 12 m is out of range: "move forward 12 meters" would not parse, so it is not offered.
    assert "did you mean" not in ALL.parse("move forwad 12 meters").errors[0].reason
    # Without a number there is nothing to fill the slot with.
    assert ALL.parse("weight seconds").errors[0].candidates == []


def test_at_most_a_few_suggestions_each_making_a_different_order() -> None:
    for heard, _ in NEAR_MISSES:
        candidates = ALL.parse(heard).errors[0].candidates
        assert len(candidates) <= MAX_SUGGESTIONS
        made = [ALL.parse(c).orders[0] for c in candidates]
        assert len({(o.order, o.case, o.description) for o in made}) == len(made)


def test_suggestions_per_segment_do_not_hide_other_orders() -> None:
    result = ALL.parse("turn lift then reach kitchen")
    assert [(o.order, o.case) for o in result.orders] == [("goal", "kitchen")]
    assert result.errors[0].candidates == ["turn left"]


def test_long_segments_get_no_suggestions() -> None:
    text = "please " * (MAX_QUERY_CHARS // 7) + "teach kitchen"
    assert ALL.parse(text).errors[0].candidates == []


@given(st.text(alphabet="abcdefghiklmnoprstuvwy 0123456789.", max_size=60))
def test_any_suggestion_for_any_text_is_a_whole_command(text: str) -> None:
    for error in ALL.parse(text).errors:
        if error.reason == "no order matches" or "did you mean" in error.reason:
            for candidate in error.candidates:
                assert len(ALL.parse(candidate).orders) == 1
