"""Orders in several languages (services/converter/language.py, orders_file.py): each
file says its language, numbers are read in it, a file in the wrong language or one that
nobody could say is refused in one line, and the shipped orders are the same orders in
English, Spanish and German."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import regex

from harness.wait import async_wait_until, wait_until
from voicectl.services.converter.language import numbers_of, unreadable
from voicectl.services.converter.orders import (
    OrderSet,
    OrdersInvalid,
    check_heard,
    load_languages,
)
from voicectl.services.converter.parser import Parser
from voicectl.services.converter.service import load
from voicectl.services.converter.watch import signature
from voicectl.shared.bus import json_decoder
from voicectl.shared.edits import QUEUE_LABEL
from voicectl.shared.errors import OrdersFileError
from voicectl.shared.keys import ConverterKeys, RobotKeys
from voicectl.shared.messages import (
    ConverterReply,
    Grammar,
    OrdersStatus,
    ParseReply,
    ParseRequest,
    Proposal,
    Transcript,
    Transcription,
)

from .conftest import Processes
from .support import joined, until_heard
from .test_converter_service import WAIT, scenario

ORDERS = Path(__file__).resolve().parents[1] / "orders"
SETS = load_languages(ORDERS)


def said(parser: Parser, text: str) -> list[tuple[str, str | None, float | None]]:
    result = parser.parse(text)
    assert result.errors == [], result.errors
    return [
        (
            order.order,
            order.case,
            None
            if order.target_pose is None
            else round(order.target_pose.x or math.degrees(order.target_pose.yaw), 3),
        )
        for order in result.orders
    ]


# --- numbers -------------------------------------------------------------------------------


@pytest.mark.parametrize("language", ["es", "de"])
def test_text2num_reads_every_value_the_grammar_says(language: str) -> None:
    # What text2num actually reads, measured: every whole number and half to 500 that
    # num2words writes, read back as itself (German's "Komma" through the decimal comma).
    assert unreadable(language, [n / 2 for n in range(0, 1001)]) == []


@pytest.mark.parametrize("language", ["es", "de"])
def test_the_number_pattern_says_exactly_the_numbers(language: str) -> None:
    """Every number below a thousand as num2words writes it is one run of the pattern, and
    a word that is no number is none. German's thousand one-word numbers are written as
    hundreds and what may follow (the converter compiles this pattern into every slot's:
    its trie of the thousand took 0.8 s of the converter's start)."""
    numbers = numbers_of(language)
    whole = regex.compile(rf"(?:{numbers.pattern})\Z", regex.IGNORECASE)
    said = [numbers.say(float(n)) for n in range(1000)]
    assert [text for text in said if not whole.match(text)] == []
    words = {word for text in said for word in text.split()}
    near = {word[:-1] for word in words} | {word + "s" for word in words}
    assert [word for word in sorted(near - numbers.words) if whole.match(word)] == []
    assert len(numbers.pattern) < 5000


@pytest.mark.parametrize(
    ("language", "words", "value"),
    [
        ("es", "cuarenta y cinco", 45.0),
        ("es", "dos coma cinco", 2.5),
        ("es", "dos punto cinco", 2.5),
        ("es", "un", 1.0),
        ("es", "una", 1.0),
        ("es", "ciento ochenta", 180.0),
        ("es", "menos dos", -2.0),
        ("es", "2.5", 2.5),
        ("de", "fünfundvierzig", 45.0),
        ("de", "zwei komma fünf", 2.5),
        ("de", "einen", 1.0),  # "fahre einen Meter": text2num reads no "einen"
        ("de", "eine", 1.0),
        ("de", "einhundertachtzig", 180.0),
        ("de", "dreißig", 30.0),
        ("de", "minus drei", -3.0),
        ("es", "izquierda", None),
        ("de", "zwei drei", None),
    ],
)
def test_numbers_are_read_in_their_language(language: str, words: str, value: float | None) -> None:
    assert numbers_of(language).read(words) == value


# --- the shipped orders ----------------------------------------------------------------------


def test_the_shipped_orders_are_the_same_in_every_language() -> None:
    """The same orders, cases and goals in each language; the queue's edits and questions
    (orders/queue.yaml) are English only, as the supervisor's answers to them are."""
    assert sorted(SETS) == ["de", "en", "es"]

    def shape(orders: OrderSet) -> set[tuple[str, str | None, str, object]]:
        return {
            (
                command.order.name,
                command.case.name if command.case else None,
                command.order.label,
                command.to_order(dict.fromkeys(command.slots)).target_pose,
            )
            for command in orders.commands
            if command.order.label != QUEUE_LABEL
        }

    english = shape(SETS["en"])
    assert shape(SETS["es"]) == english
    assert shape(SETS["de"]) == english


@pytest.mark.parametrize(
    ("language", "text", "orders"),
    [
        ("es", "gira a la izquierda y luego ve a la cocina", [
            ("rotation", "left", 89.954), ("goal", "kitchen", 3.0)]),
        ("es", "Gira a la izquierda treinta grados.", [("turn_by", "left", 30.0)]),
        ("es", "Date la vuelta.", [("rotation", "back", 179.909)]),
        ("es", "avanza 2,5 metros", [("drive", "forward", 2.5)]),
        ("es", "muévete un metro hacia atrás", [("drive", "back", -1.0)]),
        ("es", "ve al baño y toma una foto", [
            ("goal", "bathroom", 5.0), ("take_photo", None, None)]),
        ("es", "gira a la derecha 45° y luego espera diez segundos", [
            ("turn_by", "right", -45.0), ("wait", None, None)]),
        ("de", "fahre zwei Meter vorwärts, dann dreh dich nach links", [
            ("drive", "forward", 2.0), ("rotation", "left", 89.954)]),
        ("de", "Dreh dich um.", [("rotation", "back", 179.909)]),
        ("de", "fahre einen Meter zurück", [("drive", "back", -1.0)]),
        ("de", "dreh dich dreißig Grad nach links", [("turn_by", "left", 30.0)]),
        ("de", "Fahr zur Küche und mach ein Foto", [
            ("goal", "kitchen", 3.0), ("take_photo", None, None)]),
        ("de", "warte 2,5 Sekunden", [("wait", None, None)]),
    ],
)  # fmt: skip
def test_native_sentences_become_the_orders(
    language: str, text: str, orders: list[tuple[str, str | None, float | None]]
) -> None:
    assert said(Parser(SETS[language]), text) == orders


def test_each_language_reads_only_its_own_words() -> None:
    # A Spanish sentence is no German order, and English is read as before.
    assert Parser(SETS["de"]).parse("gira a la izquierda").orders == []
    assert said(Parser(SETS["en"]), "turn left and reach the kitchen") == [
        ("rotation", "left", 89.954),
        ("goal", "kitchen", 3.0),
    ]
    assert Parser(SETS["es"]).parse("cuarenta y cinco").orders == []  # a number, no "and"


# --- bad files -------------------------------------------------------------------------------


def write(directory: Path, name: str, text: str) -> Path:
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / name
    path.write_text(text, encoding="utf-8")
    return path


def test_a_file_in_another_language_than_it_says_is_refused_with_its_line(
    tmp_path: Path,
) -> None:
    # Spanish aliases under `language: de`.
    text = (
        (ORDERS / "demo.es.yaml")
        .read_text(encoding="utf-8")
        .replace("language: es", "language: de")
    )
    path = write(tmp_path, "mixed.yaml", text)
    with pytest.raises(OrdersInvalid) as caught:
        load_languages(tmp_path)
    line = 1 + text.splitlines().index("  language: de")
    assert caught.value.errors == (
        f"{path}: says language: de, but its aliases are Spanish ('adelante', 'atrás', "
        f"'avanza', 'baño', 'cocina'): write language: es, or the aliases in German "
        f"(line {line})",
    )


def test_a_file_in_a_language_nobody_hears_is_refused_at_start(tmp_path: Path) -> None:
    write(
        tmp_path,
        "fr.yaml",
        "orders_list:\n  language: fr\n  separator: puis\n  orders:\n"
        "    wait:\n      voice_alias: attends\n      label: wait\n",
    )
    with pytest.raises(OrdersFileError) as caught:
        load(tmp_path, signature(tmp_path), heard=frozenset({"en"}))
    assert str(caught.value) == (
        f"{tmp_path / 'fr.yaml'}: language fr: no installed speech engine hears it "
        "(installed: en); pip install 'voicectl[stt]' brings Whisper, which hears 99 languages"
    )
    # With Whisper installed (this machine's stt extra), French is heard.
    assert sorted(load(tmp_path, signature(tmp_path), heard=frozenset({"en", "fr"})).books) == [
        "fr"
    ]


def test_numbers_that_text2num_cannot_read_are_refused(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        "sw.yaml",
        "orders_list:\n  language: sw\n  separator: kisha\n  orders:\n    wait:\n"
        "      voice_alias: 'subiri {d} sekunde'\n      label: wait\n"
        "      slots: {d: {min: 1, max: 5, to: seconds, unit: s}}\n",
    )
    with pytest.raises(OrdersInvalid) as caught:
        load_languages(tmp_path)
    assert caught.value.errors == (
        f"{path}: language sw: text2num cannot read numbers in it, and order 'wait' has "
        "the number slot 'd' (line 2)",
    )


@pytest.mark.parametrize(
    ("language", "why"),
    [
        ("'Spanish'", "'language' must be a two-letter code (en, es, de...), got 'Spanish'"),
        ("es-ES", "'language' must be a two-letter code (en, es, de...), got 'es-ES'"),
    ],
)
def test_a_language_is_a_two_letter_code(tmp_path: Path, language: str, why: str) -> None:
    path = write(
        tmp_path,
        "x.yaml",
        f"orders_list:\n  language: {language}\n  orders:\n"
        "    wait:\n      voice_alias: wait\n      label: wait\n",
    )
    with pytest.raises(OrdersInvalid) as caught:
        load_languages(tmp_path)
    assert caught.value.errors == (f"{path}: {why} (line 2)",)


def test_a_language_without_defaults_must_say_its_separator(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        "it.yaml",
        "orders_list:\n  language: it\n  orders:\n"
        "    wait:\n      voice_alias: aspetta\n      label: wait\n",
    )
    with pytest.raises(OrdersInvalid) as caught:
        load_languages(tmp_path)
    assert caught.value.errors == (
        f"{path}: language it: say how its commands are joined ('separator', a regex: "
        '"then" in English) (line 2)',
    )


def test_check_heard_names_the_first_file(tmp_path: Path) -> None:
    sets = load_languages(ORDERS)
    with pytest.raises(OrdersFileError, match=r"demo\.de\.yaml: language de: no installed"):
        check_heard(sets, frozenset({"en", "es"}))
    check_heard(sets, frozenset({"en", "es", "de"}))


# --- on the bus --------------------------------------------------------------------------------


async def test_the_converter_reads_each_language_with_its_orders(
    router: str, processes: Processes
) -> None:
    async with scenario(router, processes, ORDERS) as converter:
        keys = ConverterKeys()
        with joined(router) as bus:
            reply = await bus.request(
                keys.parse,
                ParseRequest(text="gira a la izquierda y luego ve a la cocina", language="es"),
                json_decoder(ConverterReply),
                timeout=10.0,
            )
            assert isinstance(reply, ParseReply)
            assert [(o.order, o.case) for o in reply.result.orders] == [
                ("rotation", "left"),
                ("goal", "kitchen"),
            ]
            assert [o.description for o in reply.result.orders] == [
                "gira a la izquierda",
                "ve a la cocina",
            ]
        # Speech heard in German by its one ear becomes German orders.
        proposals: list[Proposal] = []
        robot = RobotKeys("r1")
        converter.bus.subscribe(
            robot.proposal, json_decoder(Proposal), lambda _k, p: proposals.append(p)
        )
        await until_heard(converter.bus, robot.transcript)
        heard = "Fahre zwei Meter vorwärts, dann dreh dich nach links."
        converter.bus.publish(
            robot.transcript,
            Transcript(
                text="",
                language="de",
                alone=True,
                transcription=Transcription(
                    engine="whisper", text=heard, confidence=0.9, no_speech=0.01, second=heard
                ),
            ),
        )
        await async_wait_until(lambda: proposals, WAIT, "a proposal")
        [proposal] = proposals
        assert proposal.language == "de"
        assert [(o.order, o.case) for o in proposal.orders] == [
            ("drive", "forward"),
            ("rotation", "left"),
        ]
        # One ear is not two: read back, sent only on a yes (docs/speech.md).
        assert proposal.confirm
        assert [(d.position, d.words, d.alternatives) for d in proposal.doubts] == [
            (0, proposal.transcript, [])
        ]
        assert proposal.transcript == "fahre zwei meter vorwärts dann dreh dich nach links"


def test_a_mixed_up_file_stops_the_converter_at_start_in_one_line(
    router: str, processes: Processes, tmp_path: Path
) -> None:
    text = (ORDERS / "demo.es.yaml").read_text(encoding="utf-8")
    path = write(tmp_path, "demo.yaml", text.replace("language: es", "language: de"))
    process = processes.start(
        "voicectl.services.converter", "--connect", router, "--orders", str(tmp_path)
    )
    wait_until(lambda: process.poll() is not None, WAIT, "the converter to refuse the file")
    assert process.returncode == 2
    last = processes.log(process).strip().splitlines()[-1]
    assert last.startswith(f"voicectl converter: {path}: says language: de, but its aliases")


async def test_a_recogniser_that_starts_late_gets_every_languages_grammar(
    router: str, processes: Processes
) -> None:
    async with scenario(router, processes, ORDERS) as converter:
        await async_wait_until(
            lambda: {g.language for g in converter.grammars} == {"de", "en", "es"},
            WAIT,
            "the converter's grammars",
        )
        with joined(router) as late:
            # As a recogniser does (services/stt/service.py): the languages from the
            # status, then each language's grammar on its own key, both with history.
            got: dict[str, str] = {}

            def follow(_key: str, status: OrdersStatus) -> None:
                for language in status.languages:
                    late.subscribe(
                        ConverterKeys().grammar(language),
                        json_decoder(Grammar),
                        lambda _k, grammar: got.setdefault(grammar.language, grammar.version),
                        history=True,
                    )

            late.subscribe(ConverterKeys().status, json_decoder(OrdersStatus), follow, history=True)
            await async_wait_until(
                lambda: set(got) == {"de", "en", "es"}, WAIT, f"every grammar (got {got})"
            )
