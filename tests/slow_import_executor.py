"""An executor module that takes long to import: it holds `voicectl up` in its start-up,
for tests of what happens meanwhile. Not an executor anyone would bind on purpose."""

from __future__ import annotations

import time

from voicectl.services.executor.framework import Executor

time.sleep(60)


class Never(Executor):
    labels = ("never",)
