"""The order supervisor: per-robot queue, dispatch to the executor, history."""
