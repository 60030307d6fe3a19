"""The executor framework: user executors bound to order labels, and the built-in ones."""

from .framework import ExecutionContext, Executor

__all__ = ["ExecutionContext", "Executor"]
