"""The Zenoh flags every voicectl process takes, as zenohd names them (--mode, --connect,
--listen, --config FILE, --cfg KEY:VALUE), their environment variables, which wins, and
the one-line error for each kind of mistake."""

from __future__ import annotations

import argparse
import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from voicectl.shared.bus import DEFAULT_ROUTER, BusOptions
from voicectl.shared.process import add_bus_arguments, bus_options

from .conftest import REPO, voicectl

SERVICES = ("converter", "stt", "supervisor", "executor", "sim", "web")


def parsed(*argv: str, router: bool = False) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="voicectl test")
    add_bus_arguments(parser, router=router)
    return parser.parse_args(argv)


def setting(options: BusOptions, key: str) -> object:
    return json.loads(options.zenoh_config().get_json(key))


@pytest.fixture
def config_file(tmp_path: Path) -> Path:
    path = tmp_path / "zenoh.json5"
    path.write_text(
        "// a user's file\n"
        '{ mode: "peer", connect: { endpoints: ["tcp/10.0.0.1:7447"] },\n'
        "  transport: { link: { tx: { lease: 5000 } } } }\n"
    )
    return path


@pytest.mark.parametrize("service", SERVICES)
def test_every_service_takes_the_zenoh_flags(service: str, config_file: Path) -> None:
    module = importlib.import_module(f"voicectl.services.{service}.__main__")
    args = module.parse_args(
        [
            "--mode",
            "peer",
            "--connect",
            "tcp/127.0.0.1:1",
            "--listen",
            "tcp/127.0.0.1:0",
            "--config",
            str(config_file),
            "--cfg",
            "transport/link/tx/lease:2000",
        ]
    )
    options = bus_options(args, environ={})
    assert (options.mode, options.connect, options.listen) == (
        "peer",
        ["tcp/127.0.0.1:1"],
        ["tcp/127.0.0.1:0"],
    )
    assert setting(options, "transport/link/tx/lease") == 2000


def test_defaults_are_a_client_of_the_local_router() -> None:
    options = bus_options(parsed(), environ={})
    assert (options.mode, options.connect, options.listen) == ("client", [DEFAULT_ROUTER], [])
    assert setting(options, "scouting/multicast/enabled") is False
    # No shared-memory pools mapped between every process of the host (docs/benchmarks.md).
    assert setting(options, "transport/shared_memory/enabled") is False
    shared = parsed("--cfg", "transport/shared_memory/enabled:true")
    assert setting(bus_options(shared, environ={}), "transport/shared_memory/enabled") is True
    router = bus_options(parsed(router=True), router=True, environ={})
    assert (router.mode, router.connect, router.listen) == ("router", [], [DEFAULT_ROUTER])


def test_the_file_is_the_base_and_flags_and_settings_win(config_file: Path) -> None:
    from_file = bus_options(parsed("--config", str(config_file)), environ={})
    assert setting(from_file, "mode") == "peer"
    assert setting(from_file, "connect/endpoints") == ["tcp/10.0.0.1:7447"]
    assert setting(from_file, "transport/link/tx/lease") == 5000
    assert from_file.where == "tcp/10.0.0.1:7447"
    overridden = bus_options(
        parsed(
            "--config",
            str(config_file),
            "--mode",
            "client",
            "--connect",
            "tcp/127.0.0.1:9",
            "--cfg",
            "transport/link/tx/lease:2000",
        ),
        environ={},
    )
    assert setting(overridden, "mode") == "client"
    assert setting(overridden, "connect/endpoints") == ["tcp/127.0.0.1:9"]
    assert setting(overridden, "transport/link/tx/lease") == 2000


def test_environment_variables_stand_in_for_flags(config_file: Path) -> None:
    environ = {
        "ZENOH_MODE": "peer",
        "ZENOH_CONNECT": "tcp/127.0.0.1:1, tcp/127.0.0.1:2",
        "ZENOH_LISTEN": "tcp/127.0.0.1:0",
        "ZENOH_CONFIG": str(config_file),
        "ZENOH_CFG": "transport/link/tx/lease:3000; timestamping/enabled:true",
    }
    options = bus_options(parsed(), environ=environ)
    assert options.connect == ["tcp/127.0.0.1:1", "tcp/127.0.0.1:2"]
    assert (options.mode, options.listen, options.config_file) == (
        "peer",
        ["tcp/127.0.0.1:0"],
        config_file,
    )
    assert setting(options, "transport/link/tx/lease") == 3000
    flags_win = bus_options(
        parsed("--connect", "tcp/127.0.0.1:5", "--mode", "client"), environ=environ
    )
    assert (flags_win.mode, flags_win.connect) == ("client", ["tcp/127.0.0.1:5"])


@pytest.mark.parametrize(
    ("argv", "environ", "message"),
    [
        (
            ("--cfg", "transport/link/tx/lease"),
            {},
            "--cfg 'transport/link/tx/lease': expected KEY:VALUE, VALUE in JSON5",
        ),
        (("--cfg", "no/such/key:1"), {}, "--cfg no/such/key: unknown key"),
        (
            ("--cfg", "transport/auth/usrpwd/password:hunter2"),
            {},
            "--cfg transport/auth/usrpwd/password: expected array, boolean, null, number, "
            "object, or string (line 1, column 1)",
        ),
        (
            (),
            {"ZENOH_MODE": "router-ish"},
            "ZENOH_MODE 'router-ish': expected one of client, peer, router",
        ),
    ],
)
def test_mistakes_end_the_process_in_one_line_that_keeps_values_secret(
    argv: tuple[str, ...],
    environ: dict[str, str],
    message: str,
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pytest.raises(SystemExit) as ended:
        bus_options(parsed(*argv), environ=environ)
    assert ended.value.code == 2
    assert capsys.readouterr().err == f"voicectl test: {message}\n"


def test_a_broken_config_file_is_named_with_its_line(tmp_path: Path) -> None:
    broken = tmp_path / "broken.json5"
    broken.write_text('{\n  mode: "client",\n  connect: { endpoints: [tcp/x] },\n}\n')
    done = voicectl("executor", "--config", str(broken), timeout=60)
    assert done.returncode == 2
    assert done.stderr == (
        f"voicectl executor: --config {broken}: expected array, boolean, null, number, "
        "object, or string (line 3, column 26)\n"
    )


def test_a_command_finds_the_router_through_the_environment(router: str) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "voicectl", "state", "--robot", "nobody"],
        capture_output=True,
        text=True,
        cwd=REPO,
        env={**os.environ, "ZENOH_CONNECT": router},
        timeout=60,
        check=False,
    )
    # Connected (no supervisor serves 'nobody'); without the variable it could not be.
    assert done.returncode == 3
    assert "no service answered" in done.stderr, done.stderr
