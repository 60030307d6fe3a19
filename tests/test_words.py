"""Every word for a person from one catalogue per language (shared/words.py): a missing
translation falls back to English, never to a key; the panel's words and the spoken
answers in Spanish and German; the browser's language chosen from Accept-Language."""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from pathlib import Path

import pytest

from voicectl.services.web.hub import PARTS
from voicectl.shared import words
from voicectl.shared.answers import outcome_words, proposal_words, stopped_words
from voicectl.shared.messages import Doubt, Order, OrderRecord, OrderStatus, Proposal, Stopped

from .conftest import REPO

STATIC = REPO / "services" / "web" / "static"
GIVEN = {"heard.rejected": {"text"}}
"""Values the panel gives a sentence that English does not show: English shows the
converter's reason for refused speech, the others the words heard."""


def order(description: str) -> Order:
    return Order(order="o", label="mbgoal", description=description)


def test_every_language_has_every_word() -> None:
    english = json.loads((words.FOLDER / "en.json").read_text(encoding="utf-8"))
    for language in ("es", "de"):
        own = json.loads((words.FOLDER / f"{language}.json").read_text(encoding="utf-8"))
        assert set(own) == set(english), language
        for key, entry in own.items():
            assert type(entry) is type(english[key]), (language, key)
            if isinstance(entry, str):  # values in braces the code gives the sentence
                given = set(re.findall(r"\{(\w+)\}", english[key])) | GIVEN.get(key, set())
                assert set(re.findall(r"\{(\w+)\}", entry)) <= given, (language, key)


@pytest.fixture
def lacking(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """A Spanish catalogue that lacks "answer.stopped"."""
    spanish = json.loads((words.FOLDER / "es.json").read_text(encoding="utf-8"))
    del spanish["answer.stopped"]
    (tmp_path / "es.json").write_text(json.dumps(spanish), encoding="utf-8")
    (tmp_path / "en.json").write_text((words.FOLDER / "en.json").read_text(encoding="utf-8"))
    monkeypatch.setattr(words, "FOLDER", tmp_path)
    words.catalogue.cache_clear()
    words._file.cache_clear()
    yield
    words.catalogue.cache_clear()
    words._file.cache_clear()


@pytest.mark.usefixtures("lacking")
def test_a_missing_translation_is_english_never_its_key() -> None:
    assert words.word("es", "answer.stopped") == "stopped"
    assert words.catalogue("es")["answer.stopped"] == "stopped"
    assert stopped_words(Stopped(confirmed=True, detail=""), "es") == "stopped"
    assert words.word("es", "answer.stopUnconfirmed") == "parada enviada, sin confirmar"
    assert words.word("fr", "answer.stopped") == "stopped"  # no catalogue at all: English


@pytest.mark.parametrize(
    ("header", "language"),
    [
        ("es-ES,es;q=0.9,en;q=0.8", "es"),
        ("de-DE", "de"),
        ("fr-FR,de;q=0.5,es;q=0.7", "es"),
        ("fr-FR,it;q=0.9", "en"),
        ("", "en"),
        ("*", "en"),
        ("es;q=0, de;q=0.1", "de"),
    ],
)
def test_the_browsers_language_is_chosen_from_its_header(header: str, language: str) -> None:
    assert words.from_header(header) == language


def test_answers_are_said_in_the_proposals_language() -> None:
    spanish = Proposal(
        transcript="gira a la izquierda y luego ve a la cocina",
        orders=[order("gira a la izquierda"), order("ve a la cocina")],
        language="es",
    )
    assert proposal_words(spanish) == "gira a la izquierda, luego ve a la cocina"
    german = Proposal(
        transcript="fahre zwei meter vorwärts dann dreh dich nach links",
        orders=[order("fahre 2 m vorwärts"), order("dreh dich nach links")],
        language="de",
    )
    assert proposal_words(german) == "fahre 2 Meter vorwärts, dann dreh dich nach links"
    assert proposal_words(Proposal(transcript="", rejected=True, language="de")) == (
        "Das habe ich nicht verstanden"
    )
    asked = Proposal(
        transcript="espera diez segundos",
        orders=[order("espera 10 s")],
        doubts=[Doubt(position=1, words="diez", alternatives=["dos"])],
        language="es",
    )
    assert proposal_words(asked) == "diez o dos segundos?"


@pytest.mark.parametrize(
    ("language", "description", "status", "message", "said"),
    [
        ("es", "gira a la izquierda", OrderStatus.SUCCEEDED, "", "he girado a la izquierda"),
        ("es", "muévete 1 m hacia atrás", OrderStatus.SUCCEEDED, "",
         "me he movido 1 metro hacia atrás"),
        ("es", "espera 10 s", OrderStatus.SUCCEEDED, "", "he esperado 10 segundos"),
        ("es", "ve a la cocina", OrderStatus.FAILED, "navigation unavailable (no server)",
         "ve a la cocina: falló: navigation unavailable"),
        ("de", "fahre zur küche", OrderStatus.SUCCEEDED, "", "erledigt: fahre zur küche"),
        ("de", "warte 1 s", OrderStatus.CANCELLED, "", "warte 1 Sekunde: abgebrochen"),
        ("de", "dreh dich 30 grad nach links", OrderStatus.RUNNING, "", None),
    ],
)  # fmt: skip
def test_outcomes_are_said_in_the_language(
    language: str, description: str, status: OrderStatus, message: str, said: str | None
) -> None:
    record = OrderRecord(id="1", order=order(description), status=status, message=message)
    assert outcome_words(record, language) == said


def test_every_word_the_panel_writes_is_in_the_english_catalogue() -> None:
    english = words.catalogue("en")
    html = (STATIC / "index.html").read_text(encoding="utf-8")
    scripts = "".join((STATIC / name).read_text(encoding="utf-8") for name in STATIC.glob("*.js"))
    used = set(re.findall(r'data-words(?:-[a-z]+)?="([\w.]+)"', html))
    used |= set(re.findall(r'\bt\("([\w.]+)"', scripts))
    used |= set(re.findall(r'voicectlWords\.t\("([\w.]+)"', scripts))
    used |= set(re.findall(r'"(answer\.[\w.]+)"', scripts))
    # Keys made from a name: a part, an ended status, a broken order, a goal's trouble.
    used |= {f"{kind}.{part}" for kind in ("part", "partDown") for part in PARTS}
    used |= {f"status.{s.value}" for s in OrderStatus}
    used |= {f"broke.{s}" for s in ("failed", "rejected", "interrupted")}
    used |= {f"trouble.{t}{m}" for t in ("outside", "unseen", "obstacle") for m in ("", ".many")}
    assert len(used) > 150
    assert sorted(used - set(english)) == []


def test_the_panel_page_marks_its_words() -> None:
    """No word of the page is left for a browser to show in English only: every element
    with text of its own names its word."""
    html = (STATIC / "index.html").read_text(encoding="utf-8")
    body = html.split("<body>", 1)[1].split("<script", 1)[0]
    body = re.sub(r"<svg.*?</svg>", "", body, flags=re.S)
    body = re.sub(r'<span data-words-html="[^"]+">.*?</span>', "", body, flags=re.S)
    for element in re.finditer(r"<(\w+)([^>]*)>([^<]*[A-Za-z][^<]*)<", body):
        tag, attributes, text = element.groups()
        if tag in ("h1", "code"):  # the product's name; a command stays a command
            continue
        assert "data-words=" in attributes, (tag, text.strip())
