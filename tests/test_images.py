"""Images by role: the robot runs on voicectl's core dependencies alone, and an installed
(non-editable) voicectl finds the orders it ships.

A robot installs `voicectl` without extras. Here, a child Python refuses to import any
module of a distribution that only an extra brings (an import hook, so that the test
needs no second environment), then runs what a robot runs.
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import re
import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

import pytest

from voicectl.services.converter.shipped import shipped_orders

from .conftest import REPO

PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())
PROJECT = PYPROJECT["project"]


def _distribution(requirement: str) -> str:
    """The normalised distribution name of a requirement ('text2num>=3.0' -> 'text2num')."""
    found = re.match(r"[A-Za-z0-9._-]+", requirement)
    assert found is not None, requirement
    return re.sub(r"[-_.]+", "-", found.group()).lower()


def extras_only() -> set[str]:
    """Distributions that some extra names and the core does not."""
    core = {_distribution(r) for r in PROJECT["dependencies"]}
    named = {_distribution(r) for rs in PROJECT["optional-dependencies"].values() for r in rs}
    return named - core - {"voicectl"}


def refused_modules() -> set[str]:
    """Top-level modules that only extras install."""
    extra = extras_only()
    return {
        module
        for module, distributions in importlib.metadata.packages_distributions().items()
        if {_distribution(d) for d in distributions} <= extra
    }


def test_the_refused_modules_are_the_hosts() -> None:
    refused = refused_modules()
    host_only = {"starlette", "uvicorn", "websockets", "cryptography", "rapidfuzz", "regex"}
    host_only |= {"text_to_num", "pocketsphinx", "soundfile", "vosk", "webrtc_noise_gain"}
    assert host_only <= refused
    assert not refused & {"zenoh", "msgspec", "numpy", "PIL", "yaml", "rosbags"}


HOOK = textwrap.dedent(
    """
    import importlib.abc
    import sys

    REFUSED = frozenset(sys.argv.pop(1).split(","))

    class NotOnTheRobot(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name.partition(".")[0] in REFUSED:
                raise ModuleNotFoundError(f"No module named {name!r} (not on a robot)", name=name)
            return None

    sys.meta_path.insert(0, NotOnTheRobot())
    """
)


def on_robot(code: str, *args: str) -> subprocess.CompletedProcess[str]:
    """Run `code` in a Python that cannot import what only the extras install."""
    return refusing(refused_modules(), code, *args)


def refusing(modules: set[str], code: str, *args: str) -> subprocess.CompletedProcess[str]:
    """Run `code` in a Python that cannot import `modules`."""
    return subprocess.run(
        [sys.executable, "-c", HOOK + textwrap.dedent(code), ",".join(modules), *args],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=60,
        check=False,
    )


def test_the_hook_refuses_the_hosts_packages() -> None:
    done = on_robot("from voicectl.cli import main; sys.exit(main(['parse', 'turn left']))")
    assert done.returncode == 2, done.stderr
    [line] = done.stderr.strip().splitlines()
    assert line.startswith(
        "voicectl parse: No module named 'text_to_num' (not on a robot); this installation "
        "lacks voicectl's [converter] extra ("
    ), line
    assert re.search(r"pip install (-e '[^']*|'voicectl)\[converter\]'\)$", line), line


@pytest.mark.parametrize(
    ("missing", "argv", "extra"),
    [
        ("soxr", ["listen", "--list-devices"], "listen"),
        ("sounddevice", ["listen", "--list-devices"], "mic"),
        ("pocketsphinx", ["listen", "--list-devices"], "listen"),
        ("pocketsphinx", ["wake", "train", "hey robot"], "listen"),
        ("pocketsphinx", ["transcribe", "README.md"], "stt"),
        ("starlette", ["up", "--port", "1"], "host"),
        ("cryptography", ["cert", "localhost"], "web"),
    ],
)
def test_a_missing_extra_is_the_one_named(missing: str, argv: list[str], extra: str) -> None:
    """Where one extra is missing (a host installed with [host] alone, and listen run
    there), the command names that extra, not another that happens to be installed."""
    done = refusing({missing}, f"from voicectl.cli import main; sys.exit(main({argv!r}))")
    assert done.returncode == 2, done.stderr
    [line] = done.stderr.strip().splitlines()
    assert re.search(rf"pip install (-e '[^']*|'voicectl)\[{extra}\]'", line), line
    assert f"[{extra}] extra" in line or "not installed" in line, line


def test_what_a_robot_runs_imports_without_the_extras() -> None:
    done = on_robot(
        """
        import voicectl.services.executor.__main__
        import voicectl.services.executor.config as executor
        import voicectl.services.router.__main__
        import voicectl.services.sim.__main__
        import voicectl.services.supervisor.__main__
        import voicectl.cli
        import voicectl.health

        args = executor.parse_args(["--robot", "r1", "--namespace", "bot1"])
        assert (args.robot, args.namespace) == ("r1", "bot1")
        print("imported")
        """
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "imported"


@pytest.mark.parametrize(
    "code",
    [
        "from voicectl.cli import main; sys.exit(main(['executor', '--help']))",
        "from voicectl.cli import main; sys.exit(main(['health', '--help']))",
        "from voicectl.cli import main; sys.exit(main(['--help']))",
        "import runpy; sys.argv[1:] = ['--help']; runpy.run_module('voicectl.services.executor', "
        "run_name='__main__')",
    ],
    ids=[
        "voicectl executor",
        "voicectl health",
        "voicectl",
        "python -m voicectl.services.executor",
    ],
)
def test_a_robots_commands_answer_help(code: str) -> None:
    done = on_robot(code)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("usage: "), done.stdout


def test_voicectl_health_checks_on_a_robot(router: str) -> None:
    up = on_robot(
        "from voicectl.cli import main; sys.exit(main(sys.argv[1:]))",
        *("health", "router", "--connect", router),
    )
    assert (up.returncode, up.stdout.strip()) == (0, f"router at {router} is up"), up.stderr
    down = on_robot(
        "from voicectl.cli import main; sys.exit(main(sys.argv[1:]))",
        *("health", "executor", "--robot", "r1", "--connect", router),
    )
    assert down.returncode == 1, down.stderr
    assert "executor of robot 'r1' is not up" in down.stderr


def test_the_web_extra_serves_websockets() -> None:
    """uvicorn has no WebSocket support of its own: the panel's microphone needs one."""
    web = {_distribution(r) for r in PROJECT["optional-dependencies"]["web"]}
    assert {"starlette", "uvicorn"} <= web
    assert web & {"websockets", "wsproto"}


def test_host_and_test_extras_carry_every_role() -> None:
    extras = PROJECT["optional-dependencies"]
    assert "voicectl[converter,stt,web]" in extras["host"]
    assert any(r.startswith("voicectl[") and "host" in r for r in extras["test"])


# --- packaging ------------------------------------------------------------------------------


def test_every_package_is_listed() -> None:
    listed = set(PYPROJECT["tool"]["setuptools"]["packages"])
    # voicectl/shared and voicectl/services are links to the top-level folders
    found = {
        ".".join(("voicectl", *init.parent.relative_to(REPO).parts)).replace(
            "voicectl.voicectl", "voicectl"
        )
        for top in ("shared", "services", "voicectl")
        for init in (REPO / top).rglob("__init__.py")
        if "__pycache__" not in init.parts
    }
    data = {
        "voicectl.services.web.static",
        "voicectl.services.converter.shipped_orders",
        "voicectl.shared.words",
    }
    assert listed == found | data


def test_the_shipped_orders_are_package_data() -> None:
    setuptools = PYPROJECT["tool"]["setuptools"]
    assert setuptools["package-dir"] == {"voicectl.services.converter.shipped_orders": "orders"}
    assert setuptools["package-data"]["voicectl.services.converter.shipped_orders"] == ["*.yaml"]
    assert {p.suffix for p in (REPO / "orders").iterdir()} == {".yaml"}


def test_a_checkout_uses_its_orders_directory() -> None:
    assert shipped_orders() == REPO / "orders"


def test_an_installed_voicectl_uses_its_packaged_orders(tmp_path: Path) -> None:
    """The layout a wheel installs: services/converter/shipped_orders beside the code."""
    converter = tmp_path / "site-packages" / "services" / "converter"
    (converter / "shipped_orders").mkdir(parents=True)
    (converter / "shipped_orders" / "demo.yaml").write_text("orders: []\n")
    source = REPO / "services" / "converter" / "shipped.py"
    (converter / "shipped.py").write_text(source.read_text())
    spec = importlib.util.spec_from_file_location("installed_shipped", converter / "shipped.py")
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.shipped_orders() == converter / "shipped_orders"
