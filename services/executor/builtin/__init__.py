"""Executors shipped with voicectl, bound by default."""

from ..framework import Executor
from .mbgoal import NavigateToPose
from .mul import Multiply


def builtin_executors() -> list[Executor]:
    return [NavigateToPose(), Multiply()]
