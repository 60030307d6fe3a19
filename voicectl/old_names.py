"""The import names voicectl had in 0.1, `shared` and `services`, kept for one release.

Installing voicectl puts one name into site-packages, `voicectl`; its parts are
`voicectl.shared` and `voicectl.services`. An executor written as `from services.executor
import Executor`, or an executors file naming `services.executor.builtin.pic:TakePhoto`,
keeps working in any process that has imported voicectl (the executor service always has),
with one FutureWarning per old name: shown by default, because the person who must change
the import runs voicectl rather than develops it.

The old name is an alias, not a second copy: `shared.messages.Order` *is*
`voicectl.shared.messages.Order`, so isinstance checks and msgspec's tagged unions agree.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
import warnings
from collections.abc import Sequence
from types import ModuleType

OLD = ("shared", "services")


class _Alias(importlib.abc.Loader):
    """Loads an old name as the module already imported under the new one."""

    def __init__(self, module: ModuleType) -> None:
        self.module = module
        self.spec = module.__spec__

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        return self.module

    def exec_module(self, module: ModuleType) -> None:
        # the import system gave the module the old name's spec; it keeps its own
        module.__spec__ = self.spec


class OldNames(importlib.abc.MetaPathFinder):
    """Finds `shared.*` and `services.*` as their `voicectl.*` modules, with a warning."""

    def find_spec(
        self,
        fullname: str,
        path: Sequence[str] | None = None,
        target: ModuleType | None = None,
    ) -> importlib.machinery.ModuleSpec | None:
        if fullname.partition(".")[0] not in OLD:
            return None
        new = f"voicectl.{fullname}"
        if importlib.util.find_spec(new) is None:
            return None
        warnings.warn(
            f"'{fullname}' is now '{new}'; the old name goes in the next release",
            FutureWarning,
            stacklevel=2,
        )
        return importlib.util.spec_from_loader(fullname, _Alias(importlib.import_module(new)))


def install() -> None:
    """First in line, so that a checkout's own `shared/` folder is never imported twice."""
    if not any(isinstance(finder, OldNames) for finder in sys.meta_path):
        sys.meta_path.insert(0, OldNames())
