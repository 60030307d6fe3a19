"""The docs' examples, run as written."""

from __future__ import annotations

import contextlib
import importlib
import json
import re
import signal
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import zenoh

from harness.ports import free_port
from harness.wait import wait_until
from voicectl.cli import build_parser
from voicectl.services.executor.builtin.pic import TakePhoto
from voicectl.services.executor.framework import load_bindings_file
from voicectl.shared.keys import ConverterKeys, RobotKeys
from voicectl.shared.process import bus_options

from .conftest import REPO

DOCS = REPO / "docs"


def block_after(doc: Path, marker: str, language: str) -> str:
    """The first fenced block of `language` after the text `marker` in `doc`."""
    text = doc.read_text()
    start = text.index(marker)
    found = re.compile(rf"```{language}\n(.*?)```", re.DOTALL).search(text, start)
    assert found is not None, f"no {language} block after {marker!r} in {doc.name}"
    return found.group(1)


def test_orders_doc_parse_example_prints_what_it_shows() -> None:
    doc = DOCS / "orders.md"
    command = block_after(doc, "`voicectl parse` needs no running service", "sh").strip()
    shown = json.loads(block_after(doc, "prints", "json"))
    assert command.startswith(".venv/bin/voicectl parse ")
    text = json.loads(command.removeprefix(".venv/bin/voicectl parse "))
    done = subprocess.run(
        [sys.executable, "-m", "voicectl", "parse", text],
        capture_output=True,
        text=True,
        check=False,
        cwd=REPO,
    )
    assert json.loads(done.stdout) == shown
    assert done.returncode == (1 if shown["errors"] else 0)


Voicectl = Callable[..., subprocess.CompletedProcess[str]]


@contextlib.contextmanager
def documented_stack(up_args: list[str], cwd: Path, data: Path) -> Iterator[Voicectl]:
    """`voicectl up` with a documented command line (plus a private router, no panel);
    yields a function that runs other voicectl commands against it. Stops it with Ctrl-C
    and checks it stopped cleanly."""
    router = f"tcp/127.0.0.1:{free_port()}"
    env = {"VOICECTL_DATA": str(data), "PATH": "/usr/bin:/bin", "PYTHONUNBUFFERED": "1"}
    stack = subprocess.Popen(
        [sys.executable, "-m", "voicectl", *up_args, "--router", router, "--no-web"],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
        start_new_session=True,
    )

    def voicectl(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-m", "voicectl", *args, "--connect", router],
            capture_output=True,
            text=True,
            cwd=cwd,
            env=env,
            timeout=30,
            check=False,
        )

    try:
        # The converter too: `say` asks it, and under load it can come up last.
        wait_until(
            lambda: (
                '"executor_online": true' in voicectl("state").stdout
                and voicectl("health", "converter").returncode == 0
            ),
            60.0,
            "stack",
        )
        yield voicectl
    finally:
        stack.send_signal(signal.SIGINT)
        output, _ = stack.communicate(timeout=30)
        assert stack.returncode == 0, output


@pytest.mark.e2e
def test_executors_doc_user_executor_runs_as_written(tmp_path: Path) -> None:
    doc = DOCS / "executors.md"
    (tmp_path / "my_executors.py").write_text(
        block_after(doc, "Save this as `my_executors.py`", "python")
    )
    (tmp_path / "my_orders.yaml").write_text(block_after(doc, "this as `my_orders.yaml`", "yaml"))
    up_line = block_after(doc, "Start the stack with both", "sh").strip()
    up_args = up_line.removeprefix(".venv/bin/voicectl ").split()
    with documented_stack(up_args, tmp_path, tmp_path / "data") as voicectl:
        said = voicectl("say", "pause")
        assert said.returncode == 0, said.stderr

        def waited() -> bool:
            history = json.loads(voicectl("state").stdout)["history"]
            return any(h["message"] == "waited 3 s" for h in history)

        wait_until(waited, 30.0, "the documented Wait executor to finish")
        # The history names it in words, not by its alias' regex.
        [record] = json.loads(voicectl("state").stdout)["history"]
        assert record["order"]["description"] == "pause"


def test_executors_doc_tutorial_orders_show_a_name_not_a_regex(tmp_path: Path) -> None:
    """What the state, history and panel show for the tutorial's order is its description:
    the same words whichever alias was said."""
    orders = tmp_path / "my_orders.yaml"
    orders.write_text(block_after(DOCS / "executors.md", "this as `my_orders.yaml`", "yaml"))
    for said in ("pause", "wait"):
        done = subprocess.run(
            [sys.executable, "-m", "voicectl", "parse", "--orders", str(orders), said],
            capture_output=True,
            text=True,
            check=False,
            cwd=REPO,
        )
        assert done.returncode == 0, done.stderr
        [order] = json.loads(done.stdout)["orders"]
        assert (order["order"], order["description"]) == ("pause", "pause")


@pytest.mark.e2e
def test_executors_doc_tutorials_run_as_written(tmp_path: Path) -> None:
    doc = DOCS / "executors.md"
    up_args = block_after(doc, "Start the stack with them", "sh").strip().split()[1:]
    photo = block_after(doc, "**Take a photo.**", "sh").strip().split(" ", 2)[2]
    multiply = block_after(doc, "**Parameters and cases.**", "sh").strip().split(" ", 2)[2]
    with documented_stack(up_args, REPO, tmp_path / "data") as voicectl:

        def messages() -> list[str]:
            return [h["message"] for h in json.loads(voicectl("history").stdout)["records"]]

        for command in (photo, multiply):
            said = voicectl("say", json.loads(command))
            assert said.returncode == 0, said.stderr
        wait_until(lambda: len(messages()) == 2, 30.0, "both tutorial orders")
        product, saved = messages()  # most recent first
        assert product == "10 x 20 = 200"
        prefix = "took a 64x48 photo (kept on the robot as "
        assert saved.startswith(prefix), saved
        assert saved.endswith(")"), saved
        assert Path(saved.removeprefix(prefix)[:-1]).is_file()


def test_executors_doc_executors_file_binds_and_its_typo_fails_as_shown(tmp_path: Path) -> None:
    doc = DOCS / "executors.md"
    text = block_after(doc, "save this as `executors.yaml`", "yaml")
    (tmp_path / "executors.yaml").write_text(text)
    ((executor, labels),) = load_bindings_file(tmp_path / "executors.yaml")
    assert isinstance(executor, TakePhoto)
    assert (labels, executor.directory) == (("snapshot",), Path("~/snapshots").expanduser())

    up_line = block_after(doc, "`voicectl executor` or `voicectl up`", "sh").strip()
    args = build_parser().parse_args(up_line.removeprefix(".venv/bin/voicectl ").split())
    assert args.executors == ["executors.yaml"]

    (tmp_path / "executors.yaml").write_text(text.replace("directory", "directry"))
    shown = block_after(doc, "With `directry` for `directory`", "").strip()
    done = subprocess.run(
        [sys.executable, "-m", "voicectl.services.executor", "--executors", "executors.yaml"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"},
        timeout=60,
        check=False,
    )
    assert done.returncode == 2
    assert done.stderr.strip().splitlines()[-1] == shown


@pytest.mark.parametrize(
    ("make_after", "lines_after", "directory", "fleet"),
    [
        ("in a directory of your choice", "every process starts with its own file", "bus", False),
        ("Several robots on one router", "start with their robot's files", "fleet", True),
    ],
    ids=["one-robot", "fleet"],
)
def test_deploy_doc_secured_bus_commands_run_as_written(
    tmp_path: Path, make_after: str, lines_after: str, directory: str, fleet: bool
) -> None:
    """`voicectl bus-secrets` as documented (HOME moved to a temporary directory), and
    every documented service line parses with the files it made; in a fleet, each
    robot's executor and robot side start with that robot's own files."""
    doc = DOCS / "deploy.md"
    make = block_after(doc, make_after, "sh").strip()
    env = {"HOME": str(tmp_path), "PATH": "/usr/bin:/bin", "PYTHONPATH": str(REPO)}
    command = make.replace(".venv/bin/voicectl", f"{sys.executable} -m voicectl")
    done = subprocess.run(
        ["bash", "-c", command], capture_output=True, text=True, env=env, cwd=REPO, check=False
    )
    assert done.returncode == 0, done.stderr
    secrets = tmp_path / ".local/share/voicectl" / directory
    client = json.loads((secrets / "panel.json5").read_text())
    assert client["connect"]["endpoints"] == ["tls/robot-host.local:7447"]
    namespaces = re.findall(r"--namespace (\S+)", make)
    lines = block_after(doc, lines_after, "sh").strip().splitlines()
    variable, _, path = lines[0].partition("=")
    assert path == f"~/.local/share/voicectl/{directory}"
    for line in lines[1:]:
        words = line.replace(f"${variable}", str(secrets)).split()
        assert words[0] == ".venv/bin/voicectl"
        name, argv = words[1], words[2:]
        if name == "say":
            continue  # a command, not a service: its flags are the same bus flags
        module = importlib.import_module(f"voicectl.services.{name}.__main__")
        args = module.parse_args(argv)
        options = bus_options(args, router=name == "router", environ={})
        assert options.config_file is not None
        assert options.config_file.is_file()
        if name in ("executor", "sim") and fleet:
            # The robot's own credentials, and the namespace its rules were made with.
            user = json.loads(options.config_file.read_text())["transport"]["auth"]["usrpwd"]
            robot = user["user"].partition("-")[2]
            assert f"{robot}=/{args.namespace}" in namespaces
            if name == "executor":
                assert user["user"] == f"executor-{args.robot}"
    router = (secrets / "router.json5").read_text()
    for robot in re.findall(r"--robot (\w+)", make):
        assert f"voice/{robot}/alive/executor" in router


def documented_keys() -> list[tuple[str, str]]:
    """Every `voice/...` key the README and the docs name, with where."""
    found = []
    for doc in [REPO / "README.md", *sorted(DOCS.glob("*.md"))]:
        for key in re.findall(r"`(voice/[^`\s]*)`", doc.read_text()):
            found.append((doc.name, key))
    return found


def voicectl_keys() -> list[str]:
    """Every key expression shared/keys.py builds, for any robot, session or label."""
    robot, converter = RobotKeys.any_robot(), ConverterKeys()
    keys = [
        robot.stt_audio_any,
        robot.label("*"),
        robot.alive("*"),
        robot.stt_session("x").replace("/x", "/*"),
        robot.supervisor_owner("*"),
    ]
    for keyset in (robot, converter):
        for name in dir(type(keyset)):
            if isinstance(getattr(type(keyset), name), property):
                value = getattr(keyset, name)
                if isinstance(value, str) and value.startswith("voice/"):
                    keys.append(value)
    return keys


def test_every_key_the_docs_name_is_one_voicectl_uses() -> None:
    known = [zenoh.KeyExpr(key) for key in voicectl_keys()]
    documented = documented_keys()
    assert len(documented) >= 8
    for doc, key in documented:
        expression = re.sub(r"<[a-z]+>", "*", key).replace("...", "**").rstrip("/") + "/**"
        expression = expression.replace("/**/**", "/**")
        assert any(zenoh.KeyExpr(expression).intersects(k) for k in known), (
            f"{doc} names {key}, which no key in shared/keys.py matches"
        )


def test_speech_doc_transcribe_example_prints_what_it_shows(tmp_path: Path) -> None:
    """docs/speech.md's espeak-ng example, run line by line (its /tmp files in the test's own
    directory): the orders, the verdict and each ear's words are the ones shown."""
    doc = DOCS / "speech.md"
    commands = block_after(doc, "a recording is one command away", "sh").strip().splitlines()
    shown = json.loads(block_after(doc, "prints (on one line", "json"))
    done = None
    for line in commands:
        argv = line.replace("/tmp/", f"{tmp_path}/").split()
        if argv[0] == ".venv/bin/voicectl":
            argv = [sys.executable, "-m", "voicectl", *argv[1:]]
        elif argv[0] == "espeak-ng":  # the quoted sentence is one argument
            quoted = line.split('"')[1]
            argv = [*line.split('"')[0].replace("/tmp/", f"{tmp_path}/").split(), quoted]
        done = subprocess.run(argv, capture_output=True, text=True, cwd=REPO, check=False)
        assert done.returncode == 0, (line, done.stderr)
    assert done is not None
    printed = json.loads(done.stdout)
    assert printed["file"] == shown["file"].replace("/tmp/", f"{tmp_path}/")
    for key in ("transcript", "rejected", "reason", "errors", "hearings", "decision"):
        assert printed[key] == shown[key], key
    assert [(o["order"], o["case"]) for o in printed["orders"]] == [
        (o["order"], o["case"]) for o in shown["orders"]
    ]


def test_speech_doc_voice_command_and_table_are_what_the_panel_takes() -> None:
    from voicectl.services.web.config import parse_args
    from voicectl.shared.tts import VOICES

    doc = DOCS / "speech.md"
    command = block_after(doc, "## Spoken answers", "sh").strip()
    assert command.startswith(".venv/bin/voicectl web ")
    assert parse_args(command.removeprefix(".venv/bin/voicectl web ").split()).voice == "flite"
    table = doc.read_text().partition("## Spoken answers")[2]
    assert set(re.findall(r"^\| `([a-z][a-z-]*)`", table, re.MULTILINE)) == {*VOICES, "none"}
