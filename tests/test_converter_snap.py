"""A lone ear's near-miss words snapped to the orders' words (services/converter/snap.py),
on what Whisper base wrote for harness/speech_languages.py's dev voices."""

from __future__ import annotations

from voicectl.services.converter.orders import OrderSet
from voicectl.services.converter.parser import Parser
from voicectl.services.converter.snap import snapped

from .conftest import REPO

SPANISH = Parser(OrderSet.load(REPO / "orders", "es"))


def test_near_misses_become_the_orders_words() -> None:
    vocabulary = SPANISH.vocabulary
    assert snapped("Kira a la derecha.", vocabulary) == "gira a la derecha"
    assert snapped("Abanza 2 metros.", vocabulary) == "avanza 2 metros"
    assert snapped("toman, foto,", vocabulary) == "toma foto"


def test_numbers_and_unlike_words_stay() -> None:
    vocabulary = SPANISH.vocabulary
    # "venta" is near "treinta", but no number word is ever a target: a misheard number
    # is not guessed.
    assert "treinta" not in vocabulary
    guess = snapped("gira a la izquierda venta grados", vocabulary)
    assert "treinta" not in guess
    assert not SPANISH.parse(guess).orders
    assert snapped("Gira a la derecha 90 grados.", vocabulary) == ""  # nothing to change
    # Chatter Whisper heard well stays chatter.
    for chatter in ("La puerta de la izquierda esta rota.", "la menecha en la silla"):
        assert not SPANISH.parse(snapped(chatter, vocabulary) or chatter).orders
