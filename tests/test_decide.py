"""The two ears' decision (services/converter/decide.py), on the shipped orders' parser and
transcripts as the recogniser sends them."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from voicectl.services.converter.decide import Rule, decide, numbers, once, readings
from voicectl.services.converter.orders import OrderSet
from voicectl.services.converter.parser import Parser
from voicectl.shared.messages import Doubt, Transcript, Transcription

from .conftest import REPO

PARSER = Parser(OrderSet.load(REPO / "orders"))


def heard(
    grammar: str,
    moonshine: str | None,
    *,
    rejected: str = "",
    doubts: list[Doubt] | None = None,
    support: float | None = -9.0,
) -> Transcript:
    """A final transcript: the grammar's words and verdict, and Moonshine's words with how
    likely it found the grammar's (`support`, nats a token below its own)."""
    second = (
        None
        if moonshine is None
        else Transcription(engine="moonshine", text=moonshine, support=support)
    )
    return Transcript(
        text=grammar,
        confidence=0.9,
        rejected=bool(rejected),
        reason=rejected,
        doubts=doubts or [],
        transcription=second,
    )


def decided(transcript: Transcript, rule: Rule | None = None) -> tuple[list[str], bool, str]:
    decision = decide(*readings(transcript, PARSER), rule or Rule())
    return [o.description for o in decision.orders], decision.rejected, decision.reason


def test_both_ears_making_the_same_orders_take_them_and_settle_a_doubt() -> None:
    doubt = Doubt(position=2, words="ten", alternatives=["two"], confidence=0.6)
    transcript = heard("go forward ten meters", "Go forward 10 metres.", doubts=[doubt])
    decision = decide(*readings(transcript, PARSER))
    assert [o.description for o in decision.orders] == ["move forward 10 m"]
    assert decision.doubts == []
    assert not decision.rejected
    assert [h.ear for h in decision.hearings] == ["grammar", "moonshine"]
    assert all(h.accepted for h in decision.hearings)


def test_ears_making_different_orders_take_neither() -> None:
    orders, rejected, why = decided(heard("turn left", "Turn right."))
    assert (orders, rejected) == ([], True)
    assert "disagree" in why


def test_moonshine_alone_is_taken_when_the_grammar_heard_no_command() -> None:
    said = "Turn right and move forward 1 meter."
    orders, rejected, _ = decided(heard("turn right", said, rejected="not sure I heard 'right'"))
    assert (orders, rejected) == (["turn right", "move forward 1 m"], False)
    orders, rejected, _ = decided(heard("", said, rejected="no command heard"))
    assert (orders, rejected) == (["turn right", "move forward 1 m"], False)


def test_moonshine_finding_the_grammars_words_unlikely_rejects_them() -> None:
    """alsa-utils' person saying "front left" in a reverberant room (dev split): the
    grammar heard "turn to left"."""
    orders, rejected, why = decided(heard("turn to left", "Front left.", support=-4.48))
    assert (orders, rejected) == ([], True)
    assert "front left" in why


def test_moonshine_finding_the_grammars_words_likely_backs_them() -> None:
    transcript = heard("reach the kitchen", "Breach the kitchen.", support=-0.4)
    orders, rejected, why = decided(transcript)
    assert (orders, rejected) == (["reach kitchen"], False)
    assert why.startswith("both heard")
    assert decided(transcript, Rule(support=-0.3))[:2] == ([], True)
    assert decided(heard("turn left", "Turn less than we.", support=-1.49))[:2] == ([], True)
    unheard = heard("turn back", "", support=1.9)  # Moonshine's silence was the unsure one
    assert decided(unheard)[:2] == (["turn back"], False)
    assert decided(heard("turn back", "", support=-3.0))[:2] == ([], True)


def test_backed_orders_with_other_numbers_than_moonshine_heard_take_nothing() -> None:
    transcript = heard("go forward two meters", "Go forward, 10 meeters.", support=-0.2)
    orders, rejected, why = decided(transcript)
    assert (orders, rejected) == ([], True)
    assert "numbers" in why
    unnumbered = heard("go forward two meters", "Go forward to me.", support=-0.2)
    assert decided(unnumbered)[:2] == (["move forward 2 m"], False)


def test_support_overrules_the_grammars_judge_only_if_the_rule_says_so() -> None:
    transcript = heard("turn back", "Turn black.", rejected="not sure I heard 'back'", support=-0.5)
    assert decided(transcript)[:2] == (["turn back"], False)
    assert decided(transcript, Rule(overrule=False))[:2] == ([], True)


def test_to_before_a_unit_is_two_asked_unless_the_grammar_heard_two() -> None:
    alone = decide(*readings(heard("", "Drive back to meters.", rejected="no"), PARSER))
    assert [o.description for o in alone.orders] == ["move back 2 m"]
    [doubt] = alone.doubts
    assert alone.text.split()[doubt.position] == "two"
    both = decide(*readings(heard("drive back two meters", "Drive back too meters."), PARSER))
    assert ([o.description for o in both.orders], both.doubts) == (["move back 2 m"], [])


def test_a_phrase_repeated_by_the_model_counts_once() -> None:
    def once_(text: str) -> str:
        return " ".join(once(text.split(" ")))

    assert once_("turn right turn right turn right") == "turn right"
    assert once_("rotate right 90 degrees rotate right 90") == "rotate right 90 degrees"
    assert once_("turn left then turn right") == "turn left then turn right"
    assert once_("go to the bathroom please go to the bath") == "go to the bathroom please"
    assert once_("move ahead six meter and move ahead six") == "move ahead six meter"
    assert once_("wait 10 seconds wait") == "wait 10 seconds"
    assert once_("turn left and turn right") == "turn left and turn right"
    orders, rejected, _ = decided(heard("turn right", "Turn right turn right turn right"))
    assert (orders, rejected) == (["turn right"], False)


def test_a_teen_or_ty_only_moonshine_heard_is_asked_with_its_twin() -> None:
    """Kokoro's af_bella said "turn left fifteen degrees" in babble (test split); Moonshine
    wrote 50 and the grammar heard nothing."""
    said = "Turn left 50 degrees. Turn left 50 degrees. Turn left"
    decision = decide(*readings(heard("", said, rejected="no command heard"), PARSER))
    assert [o.description for o in decision.orders] == ["turn left 50 degrees"]
    [doubt] = decision.doubts
    assert (doubt.words, doubt.alternatives) == ("50", ["15"])
    assert decision.text.split()[doubt.position] == "50"
    both = decide(*readings(heard("turn left fifty degrees", "Turn left 50 degrees."), PARSER))
    assert both.doubts == []
    plain = decide(*readings(heard("", "Turn left 45 degrees.", rejected="no"), PARSER))
    assert plain.doubts == []


def test_a_list_number_the_model_writes_is_no_number_said() -> None:
    transcript = heard("rotate left ninety degrees", "1. Rotate left 90 degrees.")
    assert decided(transcript)[:2] == (["turn left 90 degrees"], False)


def test_speech_that_is_no_command_to_either_ear_is_refused_with_what_was_said() -> None:
    orders, rejected, why = decided(
        heard("turn left", "Could you pass the salt?", rejected="not a command: 'pass'")
    )
    assert (orders, rejected) == ([], True)
    assert "could you pass the salt" in why


def test_one_ear_only_decides_as_before() -> None:
    assert decided(heard("turn left", None)) == (["turn left"], False, "")
    assert decided(heard("turn lift", None))[1] is True


def test_numbers_are_read_in_digits_or_words() -> None:
    assert numbers("go forward 3.5 meters") == numbers("go forward three point five meters")
    assert numbers("turn left ninety degrees then wait 5 seconds") == [90.0, 5.0]


WORDS = ["turn", "left", "right", "go", "forward", "to", "two", "ten", "10", "meters", "and"]
WORDS += ["then", "reach", "the", "kitchen", "please", "front", "back", "2", "drive", "wait"]


@given(
    st.lists(st.sampled_from(WORDS), max_size=8),
    st.lists(st.sampled_from(WORDS), max_size=8),
    st.booleans(),
    st.floats(-5.0, 2.0),
)
def test_no_order_stands_on_words_neither_ear_heard(
    grammar: list[str], moonshine: list[str], judged_out: bool, support: float
) -> None:
    """Whatever the ears heard, the decision's orders are those of one ear's words (with
    "two" for a "to" before a unit, asked), never anything else."""
    transcript = heard(
        " ".join(grammar),
        " ".join(moonshine),
        rejected="no" if judged_out else "",
        support=support,
    )
    decision = decide(*readings(transcript, PARSER))
    if decision.rejected:
        assert decision.orders == []
        return
    made = [PARSER.parse(" ".join(grammar)).orders]
    spoken = " ".join(once(moonshine))
    made.append(PARSER.parse(spoken).orders)
    made.append(PARSER.parse(spoken.replace("to meters", "two meters")).orders)
    assert decision.orders in made
    assert decision.orders
