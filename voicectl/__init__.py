"""voicectl: voice control for robots. Its parts are `voicectl.shared` (the bus, messages and
robot transports) and `voicectl.services` (one package per service); `voicectl.executor` is
what a behaviour imports; the `voicectl` command is `voicectl.cli`."""

from voicectl import old_names

old_names.install()
