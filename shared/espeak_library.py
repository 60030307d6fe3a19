"""espeak-ng from PyPI's `espeakng-loader` wheel (its libespeak-ng and data), for machines
without Debian's `espeak-ng` binary: run as a child process by shared/tts.py, so that the
library's global state, a crash or a hang never touches the process that asked.

``python -m voicectl.shared.espeak_library [--voice NAME] [--rate WPM]`` reads UTF-8 text on stdin
and writes a WAV on stdout, as ``espeak-ng --stdout`` does.
"""

from __future__ import annotations

import argparse
import ctypes
import sys

from voicectl.shared.tts import Speech, to_wav

SYNCHRONOUS = 2
"""espeak_AUDIO_OUTPUT: synthesis returns when done, handing samples to the callback."""
RATE = 1
"""espeak_PARAMETER: words per minute."""
CHARS_UTF8 = 1
"""espeak_Synth flags: the text is UTF-8."""
OK = 0


class _VoiceSpec(ctypes.Structure):
    """espeak_VOICE, to choose a voice by language ('en-gb') as the espeak-ng command does."""

    _fields_ = [
        ("name", ctypes.c_char_p),
        ("languages", ctypes.c_char_p),
        ("identifier", ctypes.c_char_p),
        ("gender", ctypes.c_ubyte),
        ("age", ctypes.c_ubyte),
        ("variant", ctypes.c_ubyte),
        ("xx1", ctypes.c_ubyte),
        ("score", ctypes.c_int),
        ("spare", ctypes.c_void_p),
    ]


# int callback(short *wav, int numsamples, espeak_EVENT *events); non-zero aborts.
_Callback = ctypes.CFUNCTYPE(
    ctypes.c_int, ctypes.POINTER(ctypes.c_short), ctypes.c_int, ctypes.c_void_p
)


def synthesize(text: str, voice: str | None, rate: int | None) -> Speech:
    """`text` spoken by the wheel's library."""
    import espeakng_loader

    lib = ctypes.CDLL(espeakng_loader.get_library_path())
    lib.espeak_Initialize.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_char_p, ctypes.c_int]
    lib.espeak_SetVoiceByName.argtypes = [ctypes.c_char_p]
    lib.espeak_Synth.argtypes = [
        ctypes.c_char_p,
        ctypes.c_size_t,
        ctypes.c_uint,
        ctypes.c_int,
        ctypes.c_uint,
        ctypes.c_uint,
        ctypes.c_void_p,
        ctypes.c_void_p,
    ]
    data = espeakng_loader.get_data_path().encode()
    sample_rate = int(lib.espeak_Initialize(SYNCHRONOUS, 0, data, 0))
    if sample_rate <= 0:
        raise RuntimeError(f"libespeak-ng did not start (data in {data.decode()})")
    if voice and not _set_voice(lib, voice):
        raise RuntimeError(f"espeak-ng has no voice {voice!r}")
    if rate is not None:
        lib.espeak_SetParameter(RATE, rate, 0)
    pcm = bytearray()

    def collect(wav: ctypes._Pointer[ctypes.c_short], count: int, _events: int) -> int:
        if count > 0:
            pcm.extend(ctypes.string_at(wav, count * 2))
        return 0

    callback = _Callback(collect)  # kept referenced until synthesis is over
    lib.espeak_SetSynthCallback(callback)
    encoded = text.encode() + b"\0"
    if lib.espeak_Synth(encoded, len(encoded), 0, 0, 0, CHARS_UTF8, None, None) != OK:
        raise RuntimeError("libespeak-ng refused the text")
    lib.espeak_Synchronize()
    lib.espeak_Terminate()
    return Speech(bytes(pcm), sample_rate)


def _set_voice(lib: ctypes.CDLL, voice: str) -> bool:
    """By name or file ('en-us', 'gmw/en'), else by language ('en-gb')."""
    lib.espeak_SetVoiceByProperties.argtypes = [ctypes.POINTER(_VoiceSpec)]
    if lib.espeak_SetVoiceByName(voice.encode()) == OK:
        return True
    return bool(lib.espeak_SetVoiceByProperties(_VoiceSpec(languages=voice.encode())) == OK)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m voicectl.shared.espeak_library", description=__doc__
    )
    parser.add_argument("--voice", default=None)
    parser.add_argument("--rate", type=int, default=None)
    args = parser.parse_args(argv)
    try:
        speech = synthesize(sys.stdin.read(), args.voice, args.rate)
    except (OSError, RuntimeError) as exc:
        print(f"espeak-ng library: {exc}", file=sys.stderr)
        return 1
    sys.stdout.buffer.write(to_wav(speech))
    return 0


if __name__ == "__main__":
    sys.exit(main())
