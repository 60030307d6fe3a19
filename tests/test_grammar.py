"""The recogniser's grammar: regex expansion, JSGF that pocketsphinx loads, phrase lists."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from voicectl.services.converter.expand import MAX_PHRASES, SlotRef, expand
from voicectl.services.converter.grammar import build_grammar
from voicectl.services.converter.orders import DEFAULT_SKIP_WORDS, OrderSet
from voicectl.services.converter.parser import Parser
from voicectl.shared.messages import Grammar

ORDERS = Path(__file__).resolve().parents[1] / "orders"


def phrases(pattern: str) -> set[str]:
    expansion = expand(pattern)
    assert expansion.finite, expansion.problem
    return {" ".join(str(w) for w in t) for t in expansion.templates}


@pytest.mark.parametrize(
    ("pattern", "expected"),
    [
        ("turn", {"turn"}),
        ("Turn LEFT", {"turn left"}),
        ("back(ward)?", {"back", "backward"}),
        ("forward|straight", {"forward", "straight"}),
        (
            "take (a )?(picture|photo)",
            {"take picture", "take photo", "take a picture", "take a photo"},
        ),
        (r"go\s+home", {"go home"}),
        (r"go\s*home", {"go home", "gohome"}),
        ("[ck]olou?r", {"color", "colour", "kolor", "kolour"}),
        ("(very ){1,2}fast", {"very fast", "very very fast"}),
        (r"(?:stop|halt)\b", {"stop", "halt"}),
        ("(?i)STOP", {"stop"}),
        ("(?P<name>one|two) three", {"one three", "two three"}),
        ("x{2}", {"xx"}),
    ],
)
def test_finite_aliases_expand_to_every_phrase(pattern: str, expected: set[str]) -> None:
    assert phrases(pattern) == expected


@pytest.mark.parametrize(
    ("pattern", "problem", "words"),
    [
        ("go to .*", "matches any character (. or [^...]); repeats without", ("go", "to")),
        ("go to [a-z]+", "repeats without a small bound", ("go", "to")),
        (r"(very )+fast", "repeats without a small bound", ("fast", "very")),
        ("x{2,}", "repeats without a small bound", ()),
        (r"go to \w", "character class with more than 8 members", ("go", "to")),
        ("take (?=photo)photo", "lookahead or lookbehind", ("photo", "take")),
        (r"(go) \1", "refers back to a group", ("go",)),
        ("(a|b|c|d|e|f|g|h|i|j)(a|b|c|d|e|f|g|h|i|j)(a|b|c|d|e|f|g|h|i|j)x", "more than", ()),
    ],
)
def test_infinite_or_unlistable_aliases_say_why_and_keep_their_words(
    pattern: str, problem: str, words: tuple[str, ...]
) -> None:
    expansion = expand(pattern)
    assert not expansion.finite
    assert problem in expansion.problem
    assert expansion.words == words


def test_slots_stay_open_in_templates() -> None:
    expansion = expand(r"wait (?P<slot_d>#) seconds?", {"slot_d": "d"})
    assert set(expansion.templates) == {
        ("wait", SlotRef("d"), "second"),
        ("wait", SlotRef("d"), "seconds"),
    }


_WORDS = st.sampled_from(
    ["go", "stop", "(a|b)", "(left|right)", "[ck]at", "(very ){0,2}fast", "(the )?box", "x?y"]
)


@given(st.lists(_WORDS, min_size=1, max_size=5), st.sampled_from([" ", r"\s+", r" +"]))
def test_every_expanded_phrase_matches_the_regex(words: list[str], space: str) -> None:
    pattern = space.join(words)
    compiled = re.compile(pattern, re.IGNORECASE)
    expansion = expand(pattern)
    assert expansion.finite
    for template in expansion.templates:
        phrase = " ".join(str(w) for w in template)
        assert compiled.fullmatch(phrase), phrase


# --- the grammar of the shipped orders ---------------------------------------------------------

SHIPPED = OrderSet.load(ORDERS)
GRAMMAR = build_grammar(SHIPPED)


def test_phrases_spell_out_numbers_as_words() -> None:
    for phrase in [
        "turn left",
        "reach kitchen",
        "take a photo",
        "move forward two point five meters",
        "go ahead zero point five metres",
        "turn left forty five degrees",
        "rotate right one hundred eighty degrees",
        "wait ten seconds",
    ]:
        assert phrase in GRAMMAR.phrases
    assert GRAMMAR.separator_phrases == ["then"]
    assert GRAMMAR.unexpandable == []
    assert GRAMMAR.words == sorted(set(GRAMMAR.words))
    assert {"forty", "five", "point", "then", "dumpster"} <= set(GRAMMAR.words)


def test_every_phrase_of_the_grammar_parses_to_one_order_or_names_the_range() -> None:
    """The grammar listens for numbers beyond a slot's bounds, so that "ten metres" is heard
    as ten and refused with the range, never forced onto an allowed "two"."""
    parser = Parser(SHIPPED)
    refused = 0
    for phrase in GRAMMAR.phrases:
        result = parser.parse(phrase)
        if result.errors:
            [error] = result.errors
            assert "out of range" in error.reason, (phrase, result)
            refused += 1
        else:
            assert len(result.orders) == 1, (phrase, result)
    assert 0 < refused < len(GRAMMAR.phrases)
    assert parser.parse("go forward ten meters").orders[0].target_pose.x == 10.0  # type: ignore[union-attr]
    assert "out of range: 0.1 to 10 m" in parser.parse("go forward twenty meters").errors[0].reason


def test_jsgf_has_one_rule_per_command_and_shared_number_rules() -> None:
    jsgf = GRAMMAR.jsgf
    assert jsgf.startswith("#JSGF V1.0;\ngrammar voicectl;\n")
    # orders/queue.yaml's edits may stand next to an order without the separator
    assert "public <command> = <part> ( <separator> <part> )*;" in jsgf
    assert (
        "<part> = <edge> [ <edit> <edge> ] <task> <edge> [ <edit> <edge> ] | <edge> <edit> <edge>;"
        in jsgf
    )
    assert "<edge> = [ please | now ];" in jsgf
    assert "<skip> = [ a | the | to | please | now ];" in jsgf
    assert "<separator> = then;" in jsgf
    assert "// turn_by/left" in jsgf
    # left and right turns share the same values; a correction's number has its own
    assert jsgf.count("one hundred seventy nine |") == 2
    without_edits = build_grammar(OrderSet.load(ORDERS / "spoken.yaml")).jsgf
    assert (
        "public <command> = <edge> <order> <edge> ( <separator> <edge> <order> <edge> )*;"
        in without_edits
    )


def test_version_follows_the_orders() -> None:
    assert build_grammar(OrderSet.load(ORDERS)).version == GRAMMAR.version
    changed = OrderSet.from_yaml("orders:\n  stop: {voice_alias: 'stop|halt', label: x}\n")
    other = build_grammar(changed)
    assert other.version != GRAMMAR.version
    assert other.phrases == ["stop", "halt"]


def test_unexpandable_aliases_are_reported_and_give_words() -> None:
    orders = OrderSet.from_yaml(
        "orders:\n"
        "  say: {voice_alias: 'say .+', label: x}\n"
        "  count: {voice_alias: 'count (to )?\\d+', label: x}\n"
        "  stop: {voice_alias: stop, label: x}\n"
    )
    grammar = build_grammar(orders)
    assert grammar.phrases == ["stop"]
    assert grammar.unexpandable == [
        "say: matches any character (. or [^...]); repeats without a small bound "
        "(*, +, {n,} or more than 4 times)",
        "count: has a character class with more than 8 members; repeats without a small "
        "bound (*, +, {n,} or more than 4 times)",
    ]
    assert set(grammar.words) == {"count", "say", "stop", "then", "to", *DEFAULT_SKIP_WORDS}
    assert "<c0> = ( say )+; // say" in grammar.jsgf


def test_too_many_phrases_fall_back_to_words() -> None:
    orders = OrderSet.from_yaml(
        "orders:\n"
        "  go:\n"
        "    voice_alias: '(go|walk|run|drive|roll|move) {a} (by|to) {b}'\n"
        "    label: x\n"
        "    slots:\n"
        "      a: {type: integer, min: 1, max: 100}\n"
        "      b: {type: integer, min: 1, max: 100}\n"
    )
    grammar = build_grammar(orders)
    assert grammar.phrases == []
    assert grammar.unexpandable == [
        "go: 484812 phrases, more than 5000; its words are listed instead"
    ]
    assert {"walk", "ninety", "by"} <= set(grammar.words)
    assert "<c0> = go <skip> <n0> <skip> by <skip> <n0>" in grammar.jsgf


def test_expansion_is_bounded() -> None:
    assert not expand("(a|b|c|d|e|f|g|h)" * 4).finite
    assert MAX_PHRASES == 1000


# --- pocketsphinx reads it ------------------------------------------------------------------


@pytest.fixture(scope="module")
def decoder() -> object:
    pocketsphinx = pytest.importorskip("pocketsphinx")
    return pocketsphinx.Decoder(lm=None, logfn="/dev/null")


def test_pocketsphinx_loads_the_shipped_grammar_and_knows_every_word(decoder: object) -> None:
    ps = decoder
    ps.add_jsgf_string("voicectl", GRAMMAR.jsgf)  # type: ignore[attr-defined]
    ps.activate_search("voicectl")  # type: ignore[attr-defined]
    assert ps.current_search() == "voicectl"  # type: ignore[attr-defined]
    missing = [w for w in GRAMMAR.words if ps.lookup_word(w) is None]  # type: ignore[attr-defined]
    assert missing == []
    # It decodes with it: a second of near-silence yields no command, and no error.
    ps.start_utt()  # type: ignore[attr-defined]
    ps.process_raw(bytes(32_000), full_utt=True)  # type: ignore[attr-defined]
    ps.end_utt()  # type: ignore[attr-defined]


def test_pocketsphinx_loads_word_loops_and_refuses_unknown_words(decoder: object) -> None:
    ps = decoder
    loops = build_grammar(
        OrderSet.from_yaml("orders:\n  say: {voice_alias: 'say (hello|goodbye) .*', label: x}\n")
    )
    ps.add_jsgf_string("loops", loops.jsgf)  # type: ignore[attr-defined]
    unknown = build_grammar(OrderSet.from_yaml("orders:\n  z: {voice_alias: zqxjv, label: x}\n"))
    with pytest.raises(ValueError, match="JSGF"):
        ps.add_jsgf_string("unknown", unknown.jsgf)  # type: ignore[attr-defined]


def test_grammar_is_a_message_that_round_trips() -> None:
    import msgspec

    raw = msgspec.json.encode(GRAMMAR)
    assert msgspec.json.decode(raw, type=Grammar) == GRAMMAR
