"""`python -m tests.clock_a_day_behind MODULE ARGS...` runs `python -m MODULE ARGS...` with
Python's wall clock (`time.time`, `time.time_ns`) a day behind: a fake of a machine whose
clock is wrong, at a seam the tests cannot otherwise reach. Only for tests."""

from __future__ import annotations

import runpy
import sys
import time

DAY_NS = 86_400 * 10**9

_time_ns = time.time_ns
time.time_ns = lambda: _time_ns() - DAY_NS
time.time = lambda: time.time_ns() / 1e9

if __name__ == "__main__":
    module = sys.argv[1]
    sys.argv = [module, *sys.argv[2:]]
    runpy.run_module(module, run_name="__main__", alter_sys=True)
