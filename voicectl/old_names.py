"""The import names voicectl had in 0.1, `shared` and `services`: kept in 0.2, gone in 0.3.

Installing voicectl puts one name into site-packages, `voicectl`; its parts are
`voicectl.shared` and `voicectl.services`. An executor written as `from services.executor
import Executor`, or an executors file naming `services.executor.builtin.pic:TakePhoto`,
keeps working in any process that has imported voicectl (the executor service always has),
with one FutureWarning per old name: shown by default, because the person who must change
the import runs voicectl rather than develops it.

The old name is an alias, not a second copy: `shared.messages.Order` *is*
`voicectl.shared.messages.Order`, so isinstance checks and msgspec's tagged unions agree.

It is an alias only where nothing else answers to the name: a package or module of the
user's own called `shared` or `services`, anywhere Python would import it from, is imported
as theirs and never hidden. (Aliasing only while the executor loads user executors would
still hide theirs from those executors, and break an old name imported later, inside a
function.) A checkout's own `shared/` folder is not another package: it is the folder
`voicectl/shared` links to, and is aliased, so that it is never imported twice.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType

OLD = ("shared", "services")
GOES_IN = "0.3"
"""The release without the old names (docs/executors.md says so too)."""


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
        top = fullname.partition(".")[0]
        if top not in OLD:
            return None
        if top != fullname:
            # Under the alias only: a submodule of the user's own package is theirs.
            if sys.modules.get(top) is not importlib.import_module(f"voicectl.{top}"):
                return None
        elif self._taken(top):
            return None
        new = f"voicectl.{fullname}"
        if importlib.util.find_spec(new) is None:
            return None
        warnings.warn(
            f"'{fullname}' is now '{new}'; the old name goes in voicectl {GOES_IN}",
            FutureWarning,
            stacklevel=2,
        )
        return importlib.util.spec_from_loader(fullname, _Alias(importlib.import_module(new)))

    def _taken(self, name: str) -> bool:
        """Whether the first other finder that finds a top-level `name` finds something
        other than voicectl's own folder of that name (a checkout's `shared/` is that
        folder, through the link `voicectl/shared`)."""
        own = importlib.util.find_spec(f"voicectl.{name}")
        mine = {Path(p).resolve() for p in (own.submodule_search_locations or ())} if own else set()
        for finder in sys.meta_path:
            find = getattr(finder, "find_spec", None)
            if finder is self or find is None:
                continue
            spec = find(name, None)
            if spec is None:
                continue
            places = spec.submodule_search_locations or ([spec.origin] if spec.origin else [])
            return not places or not {Path(p).resolve() for p in places} <= mine
        return False


def install() -> None:
    """First in line, so that a checkout's own `shared/` folder is never imported twice."""
    if not any(isinstance(finder, OldNames) for finder in sys.meta_path):
        sys.meta_path.insert(0, OldNames())
