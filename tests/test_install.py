"""An installed voicectl serves what a checkout serves.

The sdist and the wheel are built from a copy of the checkout's files with the build
backend pyproject.toml names (as `pip install .` and `python -m build` call it, offline),
the wheel from the sdist as pip builds one from PyPI's; the wheel goes into a fresh venv
outside the checkout, whose `voicectl up` is then asked for every file the panel
references and every route of docs/api.md.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import sysconfig
import tarfile
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest
from websockets.sync.client import connect
from websockets.typing import Origin

from .conftest import REPO, Stack, started_stack

pytestmark = [pytest.mark.e2e, pytest.mark.install]

STATIC = REPO / "services" / "web" / "static"
PACKAGES = ("voicectl", "services", "shared")
"""The checkout's folders whose files the wheel installs under `voicectl/`."""


@dataclass(frozen=True)
class Built:
    sdist: Path
    wheel: Path
    """Built from the sdist, as pip builds one."""
    wheel_from_checkout: Path
    """Built from the checkout's files, as `pip install .` builds one."""


def _backend(hook: str, source: Path, out: Path) -> Path:
    """Run the build backend's `hook` (build_sdist, build_wheel) in `source`."""
    code = f"import sys\nfrom setuptools import build_meta\nprint(build_meta.{hook}(sys.argv[1]))"
    done = subprocess.run(
        [sys.executable, "-c", code, str(out)],
        cwd=source,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    return out / done.stdout.strip().splitlines()[-1]


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> Built:
    """The sdist and wheels, from a copy of the checkout's files: a build writes `build/`
    and `*.egg-info` into its source, which the checkout's tests must not see."""
    base = tmp_path_factory.mktemp("build")
    source = base / "checkout"
    listed = subprocess.run(
        ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
        cwd=REPO,
        capture_output=True,
        check=True,
        timeout=60,
    ).stdout
    for name in filter(None, listed.decode().split("\0")):
        original = REPO / name
        if not original.is_symlink() and not original.is_file():
            continue  # deleted in the work tree, not yet in git
        copy = source / name
        copy.parent.mkdir(parents=True, exist_ok=True)
        if original.is_symlink():  # voicectl/shared and voicectl/services
            copy.symlink_to(original.readlink())
        else:
            copy.write_bytes(original.read_bytes())
    out = base / "dist"
    out.mkdir()
    sdist = _backend("build_sdist", source, out)
    with tarfile.open(sdist) as archive:
        archive.extractall(base / "unpacked", filter="data")
    (unpacked,) = (base / "unpacked").iterdir()
    from_sdist = base / "from-sdist"
    from_sdist.mkdir()
    return Built(
        sdist=sdist,
        wheel=_backend("build_wheel", unpacked, from_sdist),
        wheel_from_checkout=_backend("build_wheel", source, out),
    )


def _wheel_files(wheel: Path) -> set[str]:
    with zipfile.ZipFile(wheel) as archive:
        return {name for name in archive.namelist() if ".dist-info/" not in name}


def test_the_wheel_holds_every_file_of_the_checkouts_packages(built: Built) -> None:
    checkout = {
        str(path.relative_to(REPO)) if top == "voicectl" else f"voicectl/{path.relative_to(REPO)}"
        for top in PACKAGES
        for path in (REPO / top).rglob("*")
        if path.is_file() and "__pycache__" not in path.parts and not path.is_symlink()
    }
    checkout |= {
        f"voicectl/services/converter/shipped_orders/{path.name}"
        for path in (REPO / "orders").glob("*.yaml")
    }
    assert checkout - _wheel_files(built.wheel_from_checkout) == set()


def test_the_sdist_builds_the_wheel_the_checkout_builds(built: Built) -> None:
    assert _wheel_files(built.wheel) == _wheel_files(built.wheel_from_checkout)


def test_the_sdist_ships_no_tests(built: Built) -> None:
    """The tests need the whole checkout (docs, scripts, compose files, the harness, root,
    Chromium, Docker): they are run from the repository, and the sdist only builds the
    wheel. A test file alone would be one that cannot run."""
    with tarfile.open(built.sdist) as archive:
        names = [name.split("/", 1)[1] for name in archive.getnames() if "/" in name]
    assert [name for name in names if name.split("/")[0] in ("tests", "harness", "bench")] == []


@pytest.fixture(scope="module")
def installed(built: Built, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh venv outside the checkout with the wheel installed, offline: the wheel alone
    (`--no-deps`), its dependencies seen from this venv's site-packages (a path in a .pth
    file, so that this venv's own .pth files, its editable voicectl among them, are not
    run). Returns the venv's bin directory."""
    venv = tmp_path_factory.mktemp("installed") / "venv"
    subprocess.run(
        [sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120
    )
    python = venv / "bin" / "python"
    site = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        capture_output=True,
        text=True,
        check=True,
        timeout=60,
    ).stdout.strip()
    (Path(site) / "dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    done = subprocess.run(
        [
            *(sys.executable, "-m", "pip", "--python", str(python)),
            *("install", "--no-deps", "--no-index", "--disable-pip-version-check", "-q"),
            str(built.wheel),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    return venv / "bin"


def test_the_installed_copy_is_the_one_that_runs(installed: Path, tmp_path: Path) -> None:
    where = subprocess.run(
        [str(installed / "python"), "-c", "import voicectl; print(voicectl.__file__)"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        check=True,
        timeout=60,
    ).stdout.strip()
    assert Path(where).is_relative_to(installed.parent)


@pytest.fixture
def installed_stack(
    installed: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> Iterator[Stack]:
    """The installed copy's `voicectl up`, run outside the checkout, with the orders it
    ships; speech recognition left out (it is not what is checked, and loads models)."""
    monkeypatch.delenv("PYTHONPATH", raising=False)
    with started_stack(
        tmp_path / "data",
        orders=None,
        command=(str(installed / "voicectl"),),
        cwd=tmp_path,
        flags=("--no-stt",),
    ) as running:
        yield running


def referenced() -> set[str]:
    """Every file the panel's page, scripts and styles name under /static/, and every file
    of the checkout's static folder."""
    named = {
        found
        for path in STATIC.iterdir()
        for found in re.findall(r"/static/([\w.-]+)", path.read_text())
    }
    return named | {path.name for path in STATIC.iterdir()}


def documented_routes() -> list[tuple[str, str]]:
    """Every route docs/api.md describes, as (method, path)."""
    text = (REPO / "docs" / "api.md").read_text()
    return re.findall(r"^### (\S+) (/\S*)$", text, flags=re.MULTILINE)


def test_an_installed_copy_serves_every_file_and_route(
    installed: Path, installed_stack: Stack
) -> None:
    stack = installed_stack
    base = f"http://127.0.0.1:{stack.port}"
    token = subprocess.run(
        [str(installed / "voicectl"), "token"],
        capture_output=True,
        text=True,
        env=stack.env,
        check=True,
        timeout=60,
    ).stdout.strip()
    assert len(referenced()) > 5
    with httpx.Client(base_url=base, timeout=30.0) as http:
        page = http.get("/")
        assert page.status_code == 200
        assert page.content == (STATIC / "index.html").read_bytes()
        icon = http.get("/favicon.ico")
        assert icon.status_code == 200, icon.text
        assert icon.content == (STATIC / "icon.svg").read_bytes()
        for name in sorted(referenced()):
            served = http.get(f"/static/{name}")
            assert served.status_code == 200, (name, served.text)
            assert served.content == (STATIC / name).read_bytes(), name

        routes = documented_routes()
        pages = {("GET", "/"), ("GET", "/static/{name}"), ("GET", "/favicon.ico")}
        assert pages < set(routes)  # asked for above
        assert len(routes) > 15
        auth = {"Authorization": f"Bearer {token}"}
        assert http.get("/api/state", headers=auth).status_code == 200  # the token works
        answered = []
        for method, path in routes:
            if (method, path) in pages:
                continue
            if method == "WebSocket":
                _audio_socket(f"ws://127.0.0.1:{stack.port}{path}", base, token)
            elif path == "/api/events":  # a stream: its head and first event
                with http.stream("GET", path, headers=auth) as events:
                    assert events.status_code == 200
                    first = next(line for line in events.iter_lines() if line)
                    assert first.startswith(("data: ", ": ", "event: ")), first
            else:
                body = b"{}" if method == "POST" else None
                answer = http.request(method, path, headers=auth, content=body)
                where = f"{method} {path}: {answer.status_code} {answer.text[:200]}"
                answered.append(f"{method} {path} {answer.status_code}")
                # A route that needs a body or a parameter answers 4xx without one; a
                # missing route is 404 and a fault 500.
                assert answer.status_code < 500, where
                assert answer.headers["content-type"] == "application/json", where
                assert answer.status_code != 404 or "error" in answer.json(), where
        print("the installed panel answered:", ", ".join(answered))


def _audio_socket(url: str, origin: str, token: str) -> None:
    """The microphone's socket takes the greeting: a session, or (this stack has no
    recogniser) the one-line refusal that says so, never an internal error."""
    with connect(url, origin=Origin(origin), open_timeout=30) as socket:
        socket.send(json.dumps({"token": token, "robot": "robot"}))
        answer = json.loads(socket.recv(timeout=30))
        assert answer in (
            {"type": "error", "error": "speech recognition is not running"},
            {"type": "session", "session": answer.get("session")},
        ), answer
