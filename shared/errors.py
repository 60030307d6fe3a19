"""The small error hierarchy every voicectl component raises."""


class VoicectlError(Exception):
    """Base of every error voicectl raises on purpose; its text is one line for a person."""


class OrdersFileError(VoicectlError):
    """An orders file that cannot be used: unreadable, malformed, or missing a mandatory key."""


class BusError(VoicectlError):
    """The bus did not deliver: no reply, a timeout, or a reply that does not decode."""


class OrderFailed(VoicectlError):
    """Raised by an executor to end its order as failed with this message."""


class UnsafeCommand(OrderFailed):
    """A command that would move the robot by a value that is not a finite number (a NaN
    or infinite speed, goal, distance or angle): never sent; zero velocity went out
    instead, and the order that asked fails."""


class ServiceError(VoicectlError):
    """A service that cannot start, or must stop: its text is the process's last line
    (`run_service`), and the process exits with code 2."""


class StoreError(VoicectlError):
    """The supervisor's order store cannot do what was asked: its disk is full, its file
    is damaged or was emptied, or another supervisor holds it."""


class AudioError(VoicectlError):
    """Audio that cannot be used, or a sound device that cannot be opened; the text says
    what and where ("microphone 'USB Audio' is busy")."""


class TtsError(VoicectlError):
    """Speech could not be made: the engine is not installed, failed, or took too long."""


class Cancelled(VoicectlError):
    """Work stopped before its end because nobody waits for its result any more (a
    transcription of speech that went on, a check whose caller has gone)."""
