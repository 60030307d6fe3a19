"""The layout the code promises in docs/architecture.md: one import name, imports that run
downward, and the old names still answering for a release."""

from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from .conftest import REPO

TREE = ("shared", "services", "voicectl", "harness", "bench", "tests")


def module_of(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    if parts[0] in ("shared", "services"):
        parts.insert(0, "voicectl")
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports_of(path: Path) -> list[tuple[int, str]]:
    """Every module `path` imports, relative imports made absolute."""
    module = module_of(path)
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(path.read_bytes(), str(path))):
        match node:
            case ast.Import(names=names):
                found += [(node.lineno, alias.name) for alias in names]
            case ast.ImportFrom(module=name, level=level, names=names):
                if level == 0:
                    base = name or ""
                else:
                    base = package.rsplit(".", level - 1)[0] if level > 1 else package
                    base = f"{base}.{name}" if name else base
                # `from voicectl.shared import bus` imports a module; `from .bus import Bus`
                # a name: both are recorded, and only the modules count (target)
                found += [(node.lineno, base), *((node.lineno, f"{base}.{a.name}") for a in names)]
    return found


def sources() -> list[Path]:
    return sorted(
        p for top in TREE for p in (REPO / top).rglob("*.py") if "__pycache__" not in p.parts
    )


def test_the_tree_imports_its_parts_only_as_voicectl() -> None:
    old = [
        f"{path.relative_to(REPO)}:{line}: {name}"
        for path in sources()
        if path.name != "test_structure.py"
        for line, name in imports_of(path)
        if name.partition(".")[0] in ("shared", "services")
    ]
    assert old == []


def layer(module: str) -> int:
    """Where a module sits: the voice bus, the robot side, the client of both, the services,
    the command; `voicectl` itself only installs the old names, so it sits below them all."""
    if module in ("voicectl", "voicectl.old_names"):
        return -1
    if module == "voicectl.shared.client":
        return 2
    if module.startswith("voicectl.shared.robot"):
        return 1
    if module.startswith("voicectl.shared"):
        return 0
    if module.startswith("voicectl.services"):
        return 3
    return 4


def voicectl_imports() -> dict[str, list[tuple[int, str]]]:
    return {
        module_of(path): [
            (line, name) for line, name in imports_of(path) if name.startswith("voicectl")
        ]
        for path in sources()
        if module_of(path).startswith("voicectl")
    }


def test_every_import_runs_downward() -> None:
    upward = [
        f"{module}:{line}: {name}"
        for module, names in voicectl_imports().items()
        for line, name in names
        if layer(name) > layer(module)
    ]
    assert upward == []


def test_the_wire_knows_no_message() -> None:
    """shared/wire.py carries bytes; voicectl's messages are spoken on top of it (bus.py)."""
    above = ("voicectl.shared.messages", "voicectl.shared.bus")
    imported = [name for _, name in voicectl_imports()["voicectl.shared.wire"]]
    assert [name for name in imported if name.startswith(above)] == []
    assert "voicectl.shared.errors" in imported  # the wire is read at all


def test_no_import_circle() -> None:
    graph = voicectl_imports()
    known = set(graph)

    def target(name: str) -> str:
        # `from voicectl.shared import bus` names a module; `from .bus import Bus` its parent
        while name not in known and "." in name:
            name = name.rpartition(".")[0]
        return name

    edges = {m: {target(n) for _, n in names} - {m, "voicectl"} for m, names in graph.items()}
    circles = []
    state: dict[str, int] = {}

    def visit(module: str, path: list[str]) -> None:
        state[module] = 1
        for nxt in sorted(edges.get(module, ())):
            if state.get(nxt) == 1:
                circles.append(" -> ".join([*path[path.index(nxt) :], nxt]))
            elif nxt not in state:
                visit(nxt, [*path, nxt])
        state[module] = 2

    for module in sorted(edges):
        if module not in state:
            visit(module, [module])
    assert circles == []


def test_no_service_imports_another() -> None:
    crossing = []
    for path in (REPO / "services").glob("*/**/*.py"):
        own = module_of(path).split(".")[2]
        for line, name in imports_of(path):
            parts = name.split(".")
            if parts[:2] == ["voicectl", "services"] and len(parts) > 2 and parts[2] != own:
                crossing.append(f"{path.relative_to(REPO)}:{line}: {name}")
    assert crossing == []


def test_nothing_imports_a_main() -> None:
    mains = [
        f"{path.relative_to(REPO)}:{line}: {name}"
        for path in sources()
        if path.name not in ("test_images.py", "test_structure.py")
        for line, name in imports_of(path)
        if name.endswith(".__main__")
    ]
    assert mains == []


@pytest.mark.parametrize(
    ("old", "new", "name"),
    [
        ("services.executor", "voicectl.services.executor", "Executor"),
        ("shared.messages", "voicectl.shared.messages", "Order"),
    ],
)
def test_an_old_import_name_is_the_same_module_with_a_warning(
    old: str, new: str, name: str
) -> None:
    code = f"""
import importlib, warnings
import voicectl
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    old = importlib.import_module("{old}")
new = importlib.import_module("{new}")
print(old is new, old.{name} is new.{name})
print(old.__spec__.name)
print(*sorted({{f"{{w.category.__name__}}: {{w.message}}" for w in caught}}), sep="\\n")
"""
    done = subprocess.run(
        [sys.executable, "-c", code], cwd="/", capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[:2] == ["True True", new]
    top = old.partition(".")[0]
    assert (
        f"FutureWarning: '{top}' is now 'voicectl.{top}'; the old name goes in voicectl 0.3"
        in lines
    )
    assert f"FutureWarning: '{old}' is now '{new}'; the old name goes in voicectl 0.3" in lines


def test_an_old_name_that_never_existed_is_still_not_found() -> None:
    code = (
        "import voicectl\ntry:\n    import services.nonexistent\n"
        "except ModuleNotFoundError as e:\n    print(e.name)"
    )
    done = subprocess.run(
        [sys.executable, "-W", "ignore", "-c", code],
        cwd="/",
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "services.nonexistent"


def test_a_package_of_the_users_own_called_shared_is_never_hidden(tmp_path: Path) -> None:
    """Theirs on sys.path, found before or after voicectl was imported: theirs, with its
    own submodules, and no warning; voicectl's old name `services` still aliases."""
    mine = tmp_path / "shared"
    mine.mkdir()
    (mine / "__init__.py").write_text("OWNER = 'user'\n")
    (mine / "messages.py").write_text("ORDER = 'mine'\n")
    code = """
import warnings
warnings.simplefilter("error")
import voicectl
import shared, shared.messages
print(shared.OWNER, shared.messages.ORDER, shared.messages.__file__)
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    import services.executor
print(services.executor is voicectl.services.executor, len(caught))
"""
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == [
        f"user mine {mine / 'messages.py'}",
        "True 2",
    ]


def test_a_module_of_the_users_own_called_services_is_never_hidden(tmp_path: Path) -> None:
    (tmp_path / "lib").mkdir()
    (tmp_path / "lib" / "services.py").write_text("OWNER = 'user'\n")
    code = "import voicectl, services\nprint(services.OWNER)"
    done = subprocess.run(
        [sys.executable, "-W", "error", "-c", code],
        cwd="/",
        env={**os.environ, "PYTHONPATH": str(tmp_path / "lib")},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "user"


def test_in_a_checkout_the_old_name_is_the_same_module_not_a_second_copy() -> None:
    """The checkout's `shared/` is the folder `voicectl/shared` links to: aliased, never
    imported twice (two sets of message classes)."""
    code = (
        "import voicectl, voicectl.shared.messages, shared.messages\n"
        "print(shared.messages is voicectl.shared.messages)"
    )
    done = subprocess.run(
        [sys.executable, "-W", "ignore", "-c", code],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "True"


def test_an_executor_written_for_the_old_names_still_loads(tmp_path: Path) -> None:
    (tmp_path / "old_style.py").write_text(
        "from services.executor import ExecutionContext, Executor\n"
        "from shared.messages import Order\n\n\n"
        "class Hello(Executor):\n"
        "    labels = ('hello',)\n\n"
        "    async def execute(self, order: Order, ctx: ExecutionContext) -> str:\n"
        "        return 'hello'\n"
    )
    code = """
import sys, warnings
from voicectl.services.executor.framework import load_executor
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    mine, labels = load_executor("old_style:Hello")
    shipped, _ = load_executor("services.executor.builtin.pic:TakePhoto", (), {"directory": "."})
print(labels, type(shipped).__module__)
print(sorted({str(w.category.__name__) for w in caught}))
"""
    done = subprocess.run(
        [sys.executable, "-c", code],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == [
        "('hello',) voicectl.services.executor.builtin.pic",
        "['FutureWarning']",
    ]


def test_every_error_is_in_the_one_tree() -> None:
    """Every exception class voicectl defines derives from shared/errors.py's VoicectlError,
    so that a caller can catch what voicectl raises on purpose, and nothing else."""
    import importlib
    import inspect

    from voicectl.shared.errors import VoicectlError

    outside = []
    for path in sorted([*REPO.glob("services/**/*.py"), *REPO.glob("shared/**/*.py")]):
        text = path.read_text()
        if not re.search(r"^class \w+\(", text, re.MULTILINE):
            continue
        module = "voicectl." + ".".join(path.relative_to(REPO).with_suffix("").parts)
        try:
            loaded = importlib.import_module(module.removesuffix(".__init__"))
        except ImportError:  # an optional backend not installed here (rclpy)
            continue
        for name, value in vars(loaded).items():
            if (
                inspect.isclass(value)
                and issubclass(value, BaseException)
                and value.__module__ == loaded.__name__
                and not issubclass(value, VoicectlError)
            ):
                outside.append(f"{loaded.__name__}.{name}")
    assert outside == []
