"""Executors shipped with voicectl, bound by default."""

from pathlib import Path

from ..framework import Executor
from .mbgoal import NavigateToPose
from .motion import Drive, Rotate
from .mul import Multiply
from .pic import TakePhoto
from .wait import Wait


def builtin_executors(photo_directory: Path) -> list[Executor]:
    return [
        NavigateToPose(),
        Drive(),
        Rotate(),
        Multiply(),
        TakePhoto(photo_directory),
        Wait(),
    ]
