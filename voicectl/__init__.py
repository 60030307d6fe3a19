"""voicectl: voice control for robots. Its parts are `voicectl.shared` (the bus, messages and
robot transports) and `voicectl.services` (one package per service); `voicectl.executor` is
what a behaviour imports; the `voicectl` command is `voicectl.cli`."""

import os

# numpy's OpenBLAS starts a thread per core at import, which costs every voicectl process
# more CPU than the import itself (0.3 s against 0.15 s, measured on 2 cores) and is never
# used: voicectl's arrays are audio frames and message fields, with no linear algebra.
# Set before anything imports numpy; a user's own setting wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from voicectl import old_names

old_names.install()
