"""Commands named in hints, as the person reading them runs them where this process runs.

From a clone, `scripts/up` installs voicectl into `.venv/` and puts nothing on PATH: there
the command is `.venv/bin/voicectl token`, not `voicectl token`, and an extra is installed
with `.venv/bin/pip install -e '.[listen]'`. A container's voicectl is on PATH and its
image has no pip. Each function names what works in the installation this process runs
from, seen from its working directory (a service of `voicectl up` inherits the one `up`
was started in).
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import os
import re
import shutil
import sys
from pathlib import Path

DISTRIBUTION = "voicectl"
UNLISTED = frozenset({"test", "bench"})
"""Extras for developing voicectl, never the one a hint names."""
MODULE_DISTRIBUTIONS = {"text_to_num": "text2num"}
"""Modules whose distribution is not named after them (the others: '_' read as '-')."""


def _shown(path: Path) -> str:
    """`path` as typed from the working directory: relative under it, absolute elsewhere."""
    try:
        relative = path.relative_to(Path.cwd())
    except ValueError:
        return str(path)
    if len(relative.parts) == 1:
        return f"./{relative}"  # a bare name would be looked up on PATH
    return str(relative)


def _program(name: str) -> str | None:
    """How a person runs this installation's `name` (its bin/ folder): the bare name if
    PATH finds this very file, else its path; None when the installation has none."""
    path = Path(sys.prefix) / "bin" / name
    if not path.is_file():
        return None
    found = shutil.which(name)
    if found is not None and os.path.samefile(found, path):
        return name
    return _shown(path)


def _python() -> str:
    return _program(Path(sys.executable).name) or _shown(Path(sys.executable))


def voicectl_command(*words: str) -> str:
    """`voicectl WORDS...` as it runs here ('.venv/bin/voicectl token' from a clone)."""
    program = _program("voicectl") or f"{_python()} -m voicectl"
    return " ".join([program, *words])


def _checkout() -> Path | None:
    """The checkout this code runs from (an editable install of a clone too), or None in
    an installed copy: a checkout has pyproject.toml beside shared/."""
    root = Path(__file__).resolve().parents[1]
    return root if (root / "pyproject.toml").is_file() else None


def pip_install(extras: str) -> str:
    """What installs voicectl's `extras` ("listen,mic") here: a pip command, or, in an
    installation without pip (the images), a sentence saying where they come from."""
    if importlib.util.find_spec("pip") is None:
        return f"this installation has no pip: install voicectl[{extras}] where it is built"
    pip = _program("pip") or f"{_python()} -m pip"
    source = _checkout()
    if source is None:
        return f"{pip} install '{DISTRIBUTION}[{extras}]'"
    where = "." if source.resolve() == Path.cwd().resolve() else _shown(source)
    return f"{pip} install -e '{where}[{extras}]'"


def apt_get_install(*packages: str) -> str:
    """The Debian command that installs `packages`, with sudo unless this is root."""
    return ("" if os.geteuid() == 0 else "sudo ") + "apt-get install " + " ".join(packages)


def _normalized(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _extras() -> dict[str, set[str]]:
    """Each extra of the installed voicectl and the distributions it brings, those of the
    extras it names included (`host` is `voicectl[converter,stt,web]`)."""
    direct: dict[str, set[str]] = {}
    named: dict[str, set[str]] = {}
    try:
        requirements = importlib.metadata.requires(DISTRIBUTION) or []
    except importlib.metadata.PackageNotFoundError:  # run from a checkout never installed
        requirements = []
    for requirement in requirements:
        found = re.match(
            r"\s*([A-Za-z0-9._-]+)(?:\[([^\]]*)\])?[^;]*;\s*extra\s*==\s*\"([^\"]+)\"",
            requirement,
        )
        if found is None:
            continue  # a core dependency
        name, inner, extra = found.groups()
        if _normalized(name) == DISTRIBUTION:
            named.setdefault(extra, set()).update(e.strip() for e in (inner or "").split(","))
        else:
            direct.setdefault(extra, set()).add(_normalized(name))

    def brings(extra: str, seen: frozenset[str]) -> set[str]:
        found = set(direct.get(extra, ()))
        for inner in named.get(extra, ()):
            if inner not in seen:
                found |= brings(inner, seen | {inner})
        return found

    return {extra: brings(extra, frozenset({extra})) for extra in {*direct, *named}}


def extra_for(module: str, preferred: str = "") -> str:
    """The extra that brings the missing top-level `module`: `preferred` (the command's own)
    when it does, else the smallest that does; `preferred`, or 'host', when none names it
    (a dependency of a dependency)."""
    wanted = _normalized(MODULE_DISTRIBUTIONS.get(module, module))
    extras = _extras()
    bringing = [name for name, brought in extras.items() if wanted in brought]
    bringing = [name for name in bringing if name not in UNLISTED]
    if preferred in bringing or not bringing:
        return preferred or "host"
    return min(bringing, key=lambda name: (len(extras[name]), name))
