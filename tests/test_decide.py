"""The two ears' decision (services/converter/decide.py), on the shipped orders' parser and
transcripts as the recogniser sends them."""

from __future__ import annotations

from dataclasses import replace

import msgspec
import pytest
from hypothesis import given
from hypothesis import strategies as st

from voicectl.services.converter.decide import (
    GRAMMAR,
    HYPOTHESIS,
    SNAPPED,
    Evidence,
    Reading,
    Rule,
    decide,
    numbers,
    once,
    readings,
)
from voicectl.services.converter.decide import (
    SHIPPED as SHIPPED_RULE,
)
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
    whisper: Transcription | None = None,
) -> Transcript:
    """A final transcript: the grammar's words and verdict, Moonshine's words with how
    likely it found the grammar's (`support`, nats a token below its own), and perhaps
    Whisper's."""
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
        third=whisper,
    )


def whispered(text: str, support: float | None = None) -> Transcription:
    """Whisper's transcript, with how likely it found the grammar's words."""
    return Transcription(engine="whisper", text=text, support=support)


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


def asked(transcript: Transcript, rule: Rule | None = None) -> list[list[str]]:
    """The choices a decision asks between, as order descriptions; [] if it asks none."""
    decision = decide(*readings(transcript, PARSER), rule or Rule())
    assert not decision.rejected
    [question] = decision.doubts  # asked, never sent by itself
    assert (question.position, question.words) == (0, decision.text)
    return [
        [o.description for o in PARSER.parse(text).orders]
        for text in [question.words, *question.alternatives]
    ]


def test_ears_making_different_orders_are_asked_which() -> None:
    assert asked(heard("turn left", "Turn right.")) == [["turn right"], ["turn left"]]
    orders, rejected, why = decided(heard("turn left", "Turn right."), Rule(ask=False))
    assert (orders, rejected) == ([], True)
    assert "disagree" in why


def test_moonshine_alone_is_taken_when_the_grammar_heard_no_command() -> None:
    said = "Turn right and move forward 1 meter."
    orders, rejected, _ = decided(heard("", said, rejected="no command heard"))
    assert (orders, rejected) == (["turn right", "move forward 1 m"], False)


def test_a_rejected_grammar_reading_and_other_moonshine_orders_take_neither() -> None:
    """A hole of the two-ear decision: the grammar's judge rejected "turn left 15
    degrees", Moonshine heard "turn right 15 degrees", and Moonshine's orders were sent. Two
    ears that heard different things are a question, never a pick."""
    transcript = heard(
        "turn left fifteen degrees",
        "Turn right 15 degrees.",
        rejected="not sure I heard 'left'",
        support=-2.0,
    )
    assert asked(transcript) == [["turn right 15 degrees"], ["turn left 15 degrees"]]
    half = heard("turn right", "Turn right and move forward 1 meter.", rejected="not sure")
    assert asked(half) == [["turn right", "move forward 1 m"], ["turn right"]]


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
    assert why.startswith("grammar and moonshine heard")
    assert decided(transcript, Rule(support=-0.3))[:2] == ([], True)
    assert decided(heard("turn left", "Turn less than we.", support=-1.49))[:2] == ([], True)


def test_an_ear_that_heard_nothing_backs_nothing() -> None:
    """A hole of the two-ear decision: a grammar reading its own judge rejected, with an
    empty Moonshine transcript and a support of -1.0 or more, was sent as "both heard"."""
    judged_out = heard("turn back", "", rejected="not sure I heard 'back'", support=-0.2)
    orders, rejected, why = decided(judged_out)
    assert (orders, rejected) == ([], True)
    assert "moonshine heard nothing" in why
    assert "both heard" not in why
    assert decided(heard("turn back", "", support=1.9))[:2] == ([], True)
    # A third ear that heard the same words is what takes them.
    third = heard("turn back", "", support=1.9, whisper=whispered("Turn back.", support=-0.1))
    orders, rejected, why = decided(third)
    assert (orders, rejected) == (["turn back"], False)
    assert why == "grammar and whisper heard 'turn back'"


def test_a_doubt_is_never_cleared_by_an_ear_that_heard_no_number() -> None:
    """A hole of the two-ear decision: the grammar's "fifteen or fifty?" was cleared when
    Moonshine heard no number, or nothing; hands-free listening and the panel's "send at
    once" then sent it unasked."""
    doubt = Doubt(position=2, words="fifteen", alternatives=["fifty"], confidence=0.6)
    said = "turn left fifteen degrees"
    no_number = decide(
        *readings(heard(said, "Turn left degrees.", doubts=[doubt], support=-0.3), PARSER)
    )
    assert [o.description for o in no_number.orders] == ["turn left 15 degrees"]
    assert no_number.doubts == [doubt]
    nothing = decide(*readings(heard(said, "", doubts=[doubt], support=0.5), PARSER))
    assert nothing.rejected or nothing.doubts == [doubt]
    same = decide(
        *readings(heard(said, "Turn left 15 degrees.", doubts=[doubt], support=-0.3), PARSER)
    )
    assert (same.rejected, same.doubts) == (False, [])


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


def test_every_teen_or_ty_only_moonshine_heard_is_asked_as_well_as_a_two() -> None:
    """A hole of the two-ear decision: only the first -teen/-ty number Moonshine alone heard
    was asked, and a "to -> two" doubt switched the check off."""
    said = "Turn left 50 degrees then turn right 50 degrees."
    decision = decide(*readings(heard("", said, rejected="no command heard"), PARSER))
    words = decision.text.split()
    assert [(words[d.position], d.alternatives) for d in decision.doubts] == [
        ("50", ["15"]),
        ("50", ["15"]),
    ]
    both = decide(
        *readings(
            heard("", "Turn left 50 degrees then drive back to meters.", rejected="no"), PARSER
        )
    )
    assert sorted(d.words for d in both.doubts) == ["50", "two"]


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


# --- the written invariants (docs/speech.md, "How the ears decide"), over every kind of
# reading each ear can give: nothing, words that are no command, orders (vouched for or,
# for the grammar, rejected by its judge), doubtful orders, and other orders.

SAID = [
    "turn left",
    "turn right",
    "turn left fifteen degrees",
    "turn left fifty degrees",
    "go forward two meters",
]
ORDERS = {said: PARSER.parse(said).orders for said in SAID}


@st.composite
def a_reading(draw: st.DrawFn, ear: str) -> Reading:
    kind = draw(st.sampled_from(["nothing", "words", "orders", "rejected"]))
    if kind == "rejected" and ear != GRAMMAR:
        kind = "orders"
    support = draw(st.sampled_from([None, -3.0, -1.0, -0.2, 1.5]))
    if kind == "nothing":
        return Reading(ear, "", reason="heard nothing", support=support)
    if kind == "words":
        return Reading(ear, "could you pass the salt", reason="not a command", support=support)
    said = draw(st.sampled_from(SAID))
    numbered = [i for i, word in enumerate(said.split()) if word in ("fifteen", "fifty", "two")]
    doubts = []
    if numbered and draw(st.booleans()):
        position = numbered[0]
        doubts = [Doubt(position=position, words=said.split()[position], alternatives=["ten"])]
    return Reading(
        ear, said, ORDERS[said], accepted=kind == "orders", doubts=doubts, support=support
    )


@given(
    a_reading(GRAMMAR),
    a_reading("moonshine"),
    st.one_of(st.none(), a_reading("whisper")),
    st.sampled_from(
        [SHIPPED_RULE, Rule(majority=False), Rule(lone="unheard"), Rule(overrule=False)]
    ),
)
def test_the_decision_keeps_its_written_invariants(
    grammar: Reading, moonshine: Reading, whisper: Reading | None, rule: Rule
) -> None:
    free = [moonshine] if whisper is None else [moonshine, whisper]
    decision = decide(grammar, free, rule)
    ears = [grammar, *free]
    claims = [r for r in ears if r.orders and (r.accepted or r.ear == GRAMMAR)]
    if decision.rejected:
        assert decision.orders == []
        assert decision.doubts == []
        return
    # 1. Orders are only ever one ear's claim, exactly.
    takers = [r for r in claims if r.orders == decision.orders]
    assert takers
    # 2. Against other claims, a question offering each of them, or (only against the
    #    grammar's rejected words) two free ears' claim.
    others = [r for r in claims if r.orders != decision.orders]
    question = [d for d in decision.doubts if d.position == 0 and d.words == decision.text]
    if others and question:  # asked which, never sent by itself: nothing more to hold
        assert rule.ask
        assert {r.text for r in claims} <= {question[0].words, *question[0].alternatives}
        return
    if others:
        assert rule.majority
        assert all(not r.accepted for r in others)
        assert len([r for r in takers if r.ear != GRAMMAR]) >= 2
    # 3. One claim alone: the grammar backed by a free ear that heard words, every free ear
    #    that heard words backing it; or a free ear whose words are all its own, no other
    #    free ear having heard words. An ear that heard nothing backs nothing.
    if len(takers) == 1:
        (taker,) = takers
        heard = [r for r in free if r.text]
        if taker is grammar:
            assert rule.overrule or grammar.accepted
            assert heard
            assert all(r.support is not None and r.support >= rule.support for r in heard)
        else:
            assert rule.lone != "never"
            assert not [r for r in claims if r is not taker]
            if rule.lone == "unheard":
                assert not [r for r in free if r is not taker and r.heard]
    # 4. Absence of evidence never clears a doubt: a value every claimer doubted is asked.
    for reading in takers:
        for doubt in reading.doubts:
            if all(
                any(d.words == doubt.words for d in r.doubts) for r in takers if r is not reading
            ):
                assert doubt.words in [d.words for d in decision.doubts]
    # 5. A -teen/-ty number the grammar did not claim too is asked.
    if grammar not in takers or others:
        for word in decision.text.split():
            if word in ("fifteen", "fifty"):
                assert word in [d.words for d in decision.doubts]


@given(
    a_reading(GRAMMAR),
    a_reading("moonshine"),
    st.sampled_from([SHIPPED_RULE, Rule(lone="unheard")]),
)
def test_an_ear_that_heard_nothing_changes_nothing(
    grammar: Reading, moonshine: Reading, rule: Rule
) -> None:
    silent = Reading("whisper", "", reason="heard nothing")
    with_it, without = (
        decide(grammar, [moonshine, silent], rule),
        decide(grammar, [moonshine], rule),
    )
    assert (with_it.rejected, with_it.orders) == (without.rejected, without.orders)


# --- one ear is not two (docs/speech.md, "One ear is not two"): in a language one ear hears
# alone, its orders are sent by themselves only on its own evidence, under a rule that allows
# it; otherwise they are a confirmation, with a question that is never sent by itself.


@st.composite
def an_alone_reading(draw: st.DrawFn) -> Reading:
    reading = draw(a_reading("whisper"))
    evidence = Evidence(
        confidence=draw(st.sampled_from([0.3, 0.85, 0.99])),
        no_speech=draw(st.sampled_from([None, 0.01, 0.5])),
        second=draw(st.sampled_from([None, False, True])),
        prompted=draw(st.booleans()),
        guess=draw(st.sampled_from(["", HYPOTHESIS, SNAPPED])),
    )
    return replace(reading, evidence=evidence)


@given(an_alone_reading(), st.sampled_from([SHIPPED_RULE, Rule(alone="evidence")]))
def test_one_ear_alone_is_sent_only_on_its_own_evidence(reading: Reading, rule: Rule) -> None:
    nobody = Reading(GRAMMAR, "", reason="no grammar's ear in this language")
    decision = decide(nobody, [reading], rule)
    if decision.rejected:
        assert decision.orders == []
        assert not decision.confirm
        return
    assert reading.claims
    assert decision.orders == reading.orders
    assert reading.evidence is not None
    if not decision.confirm and not decision.doubts:  # sent by itself
        assert rule.alone == "evidence"
        assert reading.evidence.passes(rule)
        assert not reading.evidence.prompted  # a prompted decode's orders need a yes
        assert not reading.evidence.guess  # and so do guesses
    if decision.confirm:  # read back: a question, never sent by itself
        assert decision.doubts
    if rule.alone == "confirm":
        assert decision.confirm


def test_a_lone_transcript_is_confirmed_with_the_whole_sentence() -> None:
    parser = Parser(OrderSet.load(REPO / "orders", "es"))
    heard = "Gira a la izquierda y luego ve a la cocina."
    transcript = Transcript(
        text="",
        language="es",
        alone=True,
        transcription=Transcription(
            engine="whisper", text=heard, confidence=0.95, no_speech=0.01, second=heard
        ),
    )
    decision = decide(*readings(transcript, parser))
    assert [(o.order, o.case) for o in decision.orders] == [
        ("rotation", "left"),
        ("goal", "kitchen"),
    ]
    assert decision.confirm
    assert decision.doubts == [
        Doubt(position=0, words="gira a la izquierda y luego ve a la cocina", confidence=0.95)
    ]
    assert decision.reason == (
        "whisper alone heard 'gira a la izquierda; ve a la cocina': confirm it"
    )
    # Under the evidence rule its second decode's agreement sends it; a second decode that
    # made other orders does not.
    sent = decide(*readings(transcript, parser), rule=Rule(alone="evidence"))
    assert not sent.confirm
    assert sent.doubts == []
    other = msgspec.structs.replace(
        transcript,
        transcription=msgspec.structs.replace(
            transcript.transcription, second="Gira a la derecha y luego ve a la cocina."
        ),
    )
    assert decide(*readings(other, parser), rule=Rule(alone="evidence")).confirm
    # Orders only the prompted decode heard ("kira la izquierda" unprompted) are asked.
    rescued = msgspec.structs.replace(
        transcript,
        transcription=msgspec.structs.replace(
            transcript.transcription,
            text="Kira la izquierda y luego vea la cocina.",
            second="gira la izquierda y luego vea la cocina",
        ),
    )
    decision = decide(*readings(rescued, parser), rule=Rule(alone="evidence"))
    assert decision.confirm
    assert [(o.order, o.case) for o in decision.orders] == [
        ("rotation", "left"),
        ("goal", "kitchen"),
    ]
    assert decision.reason.endswith("(prompted with the orders' words): confirm it")


def lone(text: str, second: str | None = None, alternatives: tuple[str, ...] = ()) -> Transcript:
    """What the one ear of Spanish wrote for an utterance (harness/speech_languages.py's dev
    voices, Whisper base): first decode, prompted decode, its other hypotheses."""
    return Transcript(
        text="",
        language="es",
        alone=True,
        transcription=Transcription(
            engine="whisper",
            text=text,
            confidence=0.6,
            no_speech=0.02,
            second=second,
            alternatives=list(alternatives),
        ),
    )


SPANISH = Parser(OrderSet.load(REPO / "orders", "es"))


def test_a_lone_ear_s_other_hypotheses_and_near_misses_are_read_back() -> None:
    for transcript, said, how in [
        # Kokoro's "gira a la izquierda": only the beam's third hypothesis says "gira".
        (
            lone(
                "Pira a la izquierda.",
                "pira a la izquierda,",
                ("pira a la izquierda", "gira a la izquierda,", "pida a la izquierda,"),
            ),
            [("rotation", "left")],
            f"({HYPOTHESIS})",
        ),
        # Kokoro's "toma una foto" and espeak-ng's "vete a la base": no hypothesis says
        # them, each is a few letters off.
        (
            lone("Toma un nafoto.", "toman, a foto,", ("toman, ha, foto", "toman, foto,")),
            [("take_photo", None)],
            f"({SNAPPED})",
        ),
        (
            lone("Beite y alabase.", "bete y alabase,", ("bete, alabase,", "bate y alabase,")),
            [("goal", "base")],
            f"({SNAPPED})",
        ),
    ]:
        for rule in (SHIPPED_RULE, Rule(alone="evidence")):
            decision = decide(*readings(transcript, SPANISH), rule=rule)
            assert [(o.order, o.case) for o in decision.orders] == said
            assert decision.confirm  # a guess is never sent by itself
            assert decision.doubts
            assert decision.reason.endswith(f"{how}: confirm it"), decision.reason


def test_a_lone_ear_s_chatter_stays_chatter() -> None:
    for transcript in [
        lone("La puerta de la izquierda esta rota.", "la puerta, me la izquierda, esta rota"),
        lone("la menecha en la silla", "la menecha, inacía,", ("la menecha, en la silla",)),
        lone("Me voy a la tierra.", "me voy a la tienda,"),
        # A misheard number is never guessed ("treinta" heard as "venta").
        lone("Y ahora, siquiera la venta, la voz.", "gira, izquierda, venta, grados,"),
    ]:
        decision = decide(*readings(transcript, SPANISH))
        assert decision.rejected
        assert decision.orders == []


def test_a_transcription_carries_a_bounded_number_of_hypotheses() -> None:
    heard = msgspec.json.encode(lone("Y haranelecha.", "y la menecha", ("y la",) * 17))
    with pytest.raises(msgspec.ValidationError, match="alternatives"):
        msgspec.json.decode(heard, type=Transcript)
    fine = msgspec.json.encode(lone("Y haranelecha.", "y la menecha", ("y la",) * 16))
    assert len(msgspec.json.decode(fine, type=Transcript).transcription.alternatives) == 16
