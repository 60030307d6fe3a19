"""The secured bus, with real sessions: `voicectl bus-secrets` makes a CA, the router's
certificate, passwords and client configurations; the shipped router configuration
(TLS, user/password, access control) runs the stack end to end, and refuses whoever has
no credentials, the wrong certificate, or a role that does not allow what they try, one
robot's executor or robot side speaking for another robot among them."""

from __future__ import annotations

import asyncio
import json
import os
import shlex
import socket
import stat
import subprocess
import sys
from functools import partial
from pathlib import Path

import pytest
import zenoh

from harness.client import Client, client_wait_ready
from harness.ports import free_port
from harness.wait import async_wait_until, wait_until
from voicectl.bus_secrets import (
    ROUTER_TEMPLATE,
    BusRobot,
    SecretsExist,
    router_configuration,
    users,
    write_bus_secrets,
)
from voicectl.shared.bus import Bus, BusOptions, json_decoder
from voicectl.shared.errors import BusError
from voicectl.shared.keys import RobotKeys
from voicectl.shared.messages import (
    Done,
    EmergencyStop,
    Execute,
    ExecutorReply,
    Failed,
    GetRunning,
    GetState,
    Latch,
    Release,
    Stopped,
)
from voicectl.shared.robot.keys import BRIDGE_TOKENS, BridgeKind, BridgeToken, RobotNames
from voicectl.shared.ros2 import Odometry, Ros2Codec

from .conftest import REPO, Processes, voicectl
from .support import joined, order, until_heard
from .test_hints import hint

CODEC = Ros2Codec()


class SecureSite:
    """A secured router on a loopback TLS port, and the stack's services, each with its
    own credentials."""

    def __init__(self, processes: Processes, secrets: Path, port: int) -> None:
        self.processes = processes
        self.secrets = secrets
        self.endpoint = f"tls/127.0.0.1:{port}"

    def config(self, user: str) -> Path:
        return self.secrets / f"{user}.json5"

    def start(self, module: str, user: str, *args: str) -> subprocess.Popen[bytes]:
        return self.processes.start(module, "--config", str(self.config(user)), *args)

    def options(self, config: Path) -> BusOptions:
        return BusOptions(connect=[], mode=None, config_file=config, wait=False)

    def joined(self, user: str) -> Bus:
        return joined(self.options(self.config(user)))


ROBOTS = [BusRobot("r1"), BusRobot("r2")]
"""The robots of the secured site: r1 runs, r2 is the one an impostor would pose as."""
NAMESPACED = [BusRobot("r1", "bot1"), BusRobot("r2", "bot2")]


@pytest.fixture
def robots() -> list[BusRobot]:
    return ROBOTS


@pytest.fixture
def site(processes: Processes, tmp_path: Path, robots: list[BusRobot]) -> SecureSite:
    port = free_port()
    secrets = tmp_path / "bus"
    write_bus_secrets(secrets, ["127.0.0.1"], port, robots)
    site = SecureSite(processes, secrets, port)
    processes.start(
        "voicectl.services.router",
        "--config",
        str(secrets / "router.json5"),
        "--listen",
        site.endpoint,
    )
    # A client that finds no router gives up at once (Zenoh's CLI among them).
    wait_until(lambda: listening(port), 30.0, "the secured router to listen")
    return site


def listening(port: int) -> bool:
    try:
        socket.create_connection(("127.0.0.1", port), timeout=1.0).close()
    except OSError:
        return False
    return True


def start_robot(site: SecureSite) -> None:
    site.start("voicectl.services.supervisor", "supervisor", "--robot", "r1")
    site.start("voicectl.services.sim", "robot-r1")
    site.start("voicectl.services.executor", "executor-r1", "--robot", "r1")


def user_of(config: Path) -> str:
    user: str = json.loads(config.read_text())["transport"]["auth"]["usrpwd"]["user"]
    return user


def test_bus_secrets_are_private_and_never_overwritten(tmp_path: Path) -> None:
    written = write_bus_secrets(tmp_path / "bus", ["robot.local", "192.168.1.20"])
    names = {path.name for path in written}
    assert names >= {"ca.pem", "router.pem", "router.key", "passwords", "router.json5"}
    assert names >= {f"{user}.json5" for user in users([BusRobot("robot")])}
    public = {"ca.pem", "router.pem", "router.json5"}
    for path in written:
        mode = stat.S_IMODE(path.stat().st_mode)
        assert mode == (0o644 if path.name in public else 0o600), path.name
    client = json.loads((tmp_path / "bus" / "panel.json5").read_text())
    assert client["connect"]["endpoints"] == ["tls/robot.local:7447"]
    assert user_of(tmp_path / "bus" / "panel.json5") == "panel"
    # The router's configuration is the shipped one, paths aside, each robot's rules in.
    router = (tmp_path / "bus" / "router.json5").read_text()
    assert router == router_configuration((tmp_path / "bus").resolve(), [BusRobot("robot")])
    assert "/etc/voicectl/bus" not in router
    with pytest.raises(SecretsExist, match="already holds bus secrets"):
        write_bus_secrets(tmp_path / "bus", ["robot.local"])


def test_bus_secrets_has_users_per_robot_and_plain_names_for_the_default_robot(
    tmp_path: Path,
) -> None:
    """Issue 32: one executor user served every robot. Each robot now has its own
    executor and robot side; the robot every --robot defaults to keeps the plain file
    names, so that a deployment of one robot starts as it always did."""
    write_bus_secrets(tmp_path / "one", ["router"])
    assert user_of(tmp_path / "one" / "executor.json5") == "executor-robot"
    assert user_of(tmp_path / "one" / "robot.json5") == "robot-robot"
    assert user_of(tmp_path / "one" / "executor-robot.json5") == "executor-robot"

    write_bus_secrets(tmp_path / "two", ["router"], robots=NAMESPACED)
    made = {path.name for path in (tmp_path / "two").iterdir()}
    assert {"executor-r1.json5", "robot-r1.json5", "executor-r2.json5", "robot-r2.json5"} <= made
    assert not made & {"executor.json5", "robot.json5"}  # whose would they be?
    passwords = (tmp_path / "two" / "passwords").read_text().splitlines()
    assert [line.split(":")[0] for line in passwords] == users(NAMESPACED)
    assert len(set(passwords)) == len(passwords)
    # Every line of the template is in the router's configuration: only robots are added.
    router = (tmp_path / "two" / "router.json5").read_text().splitlines()
    template = ROUTER_TEMPLATE.read_text().replace("/etc/voicectl/bus", str(tmp_path / "two"))
    added = [line for line in router if line not in template.splitlines()]
    assert all(line.strip().startswith(("// robot 'r", '{"id": "')) for line in added)
    assert sum("bot1/**/cmd_vel" in line for line in added) == 1
    with pytest.raises(ValueError, match="robot name 'r 1' must be letters"):
        BusRobot("r 1")
    with pytest.raises(ValueError, match="robots must be named once each"):
        write_bus_secrets(tmp_path / "three", ["router"], robots=[BusRobot("a"), BusRobot("a")])


def test_the_bus_secrets_command_names_robots_and_their_namespaces(tmp_path: Path) -> None:
    done = voicectl(
        "bus-secrets", str(tmp_path / "bus"), "--robot", "r1", "--robot", "r2",
        "--namespace", "r1=/bot1",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[-2:] == [
        "robot r1: its executor may say voice/r1/... and the ROS keys under bot1",
        "robot r2: its executor may say voice/r2/... and any robot's ROS keys (no --namespace)",
    ]
    assert user_of(tmp_path / "bus" / "robot-r2.json5") == "robot-r2"
    stray = voicectl("bus-secrets", str(tmp_path / "other"), "--namespace", "r3=bot3")
    assert stray.returncode == 2
    assert stray.stderr.strip() == (
        "voicectl bus-secrets: --namespace names robot 'r3', which no --robot names (robots: robot)"
    )
    assert not (tmp_path / "other").exists()


async def test_the_stack_runs_end_to_end_on_the_secured_bus(site: SecureSite) -> None:
    converter = site.start("voicectl.services.converter", "converter")
    start_robot(site)
    operator = str(site.config("operator"))
    # Its three languages' grammars take a while on a loaded machine: `say` asks it.
    await async_wait_until(
        lambda: "converter ready" in site.processes.log(converter), 60.0, "the converter"
    )

    with site.joined("operator") as bus:
        client = Client(bus, "r1")
        await client_wait_ready(client)
        (product,) = await client.submit(order("mul", first=6, second=7))
        assert (await client.finished(product)).message == "6 x 7 = 42"
        said = await asyncio.to_thread(
            voicectl, "say", "--robot", "r1", "--config", operator, "multiply composites"
        )
        assert said.returncode == 0, said.stderr
        (composites,) = json.loads(said.stdout)["order_ids"]
        assert (await client.finished(composites)).message == "10 x 20 = 200"


async def test_the_panel_cannot_drive_the_robot_or_reach_the_executor(site: SecureSite) -> None:
    start_robot(site)

    with site.joined("panel") as bus:
        odometry: list[Odometry] = []
        bus.subscribe(RobotNames().odom, CODEC.read_odometry, lambda _k, o: odometry.append(o))
        client = Client(bus, "r1")
        await client_wait_ready(client)  # asking the supervisor is allowed
        for _ in range(20):
            bus.publish_bytes(RobotNames().cmd_vel, CODEC.twist(0.5, 0.0), urgent=True)
            await asyncio.sleep(0.05)
        await async_wait_until(lambda: len(odometry) > 30, 10.0, "odometry")
        assert all(o.linear_x == 0.0 for o in odometry)
        keys = RobotKeys("r1")
        decode = json_decoder(ExecutorReply)
        execute = Execute(order_id="sneaky", order=order("mul", first=1, second=1))
        for key, request in (
            (keys.executor_execute, execute),
            (keys.executor_control, GetRunning()),
        ):
            with pytest.raises(BusError) as refused:
                await bus.request(key, request, decode, timeout=2.0)
            assert str(refused.value) == (
                f"{key}: no service answered (none is up, or the router's access control "
                "refuses this user)"
            )


async def test_the_operator_releases_a_stop_only_through_the_supervisor(
    site: SecureSite,
) -> None:
    """Issue 32: the operator's credentials could release the executor's latch directly
    while the supervisor stayed stopped. A person may still latch the executor (STOP
    without the supervisor), but its release has a key of its own that only the
    supervisor may ask, and the latch key refuses a release."""
    start_robot(site)
    keys, decode = RobotKeys("r1"), json_decoder(Done | Failed)

    with site.joined("operator") as bus:
        client = Client(bus, "r1")
        await client_wait_ready(client)
        assert isinstance(await client.ask(EmergencyStop()), Stopped)
        latched = await bus.request(keys.executor_latch, Latch(on=True), decode, timeout=5.0)
        assert isinstance(latched, Done), latched  # latching is anyone's
        refused = await bus.request(keys.executor_latch, Latch(on=False), decode, timeout=5.0)
        assert isinstance(refused, Failed)
        assert refused.reason.startswith("the latch is released through the supervisor")
        with pytest.raises(BusError, match="access control refuses this user"):
            await bus.request(keys.executor_release, Latch(on=False), decode, timeout=2.0)
        refused_run = await client.ask_submit(order("mul", first=2, second=2))
        assert isinstance(refused_run, Failed)  # still stopped: the supervisor's latch holds

        released = await client.ask(Release())
        assert released == Done(detail="emergency stop released")  # the executor's too
        (product,) = await client.submit(order("mul", first=2, second=2))
        assert (await client.finished(product)).message == "2 x 2 = 4"


async def test_an_executor_cannot_speak_or_announce_for_another_robot(site: SecureSite) -> None:
    """Issue 32: the executor's credentials could publish events and hold liveliness
    tokens for any robot name, so that one robot's executor posed as another's (300 made
    up robots appeared). r1's executor now speaks for r1 alone: what it says as r2 never
    reaches the panel, and the supervisor never takes r2 on; as r1 it is heard and
    served. What it forges is said first, on the same link: once the genuine reaches the
    panel, the forged would have too."""
    site.start("voicectl.services.supervisor", "supervisor")  # serves whichever executor announces
    r1, r2 = RobotKeys("r1"), RobotKeys("r2")
    tokens: list[str] = []
    events: list[str] = []

    with site.joined("panel") as panel:
        panel.watch(RobotKeys.any_robot().alive("*"), lambda key, up: up and tokens.append(key))
        panel.subscribe(
            RobotKeys.any_robot().executor_events, bytes, lambda key, _: events.append(key)
        )
        with site.joined("executor-r1") as impostor:
            await until_heard(impostor, r1.executor_events)  # the panel's subscriptions are up
            impostor.announce(r2.alive("executor"))
            impostor.publish_bytes(r2.executor_events, b'{"type": "forged"}')
            impostor.announce(r1.alive("executor"))
            impostor.publish_bytes(r1.executor_events, b'{"type": "genuine"}')
            await async_wait_until(
                lambda: r1.executor_events in events and r1.alive("executor") in tokens,
                10.0,
                "r1's executor heard",
            )
            await async_wait_until(
                lambda: r1.alive("supervisor") in tokens, 30.0, "the supervisor serving r1"
            )
            assert r2.executor_events not in events
            assert [key for key in tokens if key.startswith(r2.prefix)] == []
            unknown = await Client(panel, "r2").ask(GetState())
            assert isinstance(unknown, Failed), unknown
            assert unknown.reason.startswith("no executor has served robot 'r2' (known robots: r1)")


def replies(bus: Bus, key: str, timeout: float = 5.0) -> list[str]:
    """The keys that answered a query on `key` (on a thread: it waits)."""
    return [str(r.ok.key_expr) for r in bus.session.get(key, timeout=timeout) if r.ok is not None]


def answering(bus: Bus, key: str) -> None:
    def answer(query: zenoh.Query) -> None:
        query.reply(query.key_expr, b"goal accepted")

    bus.session.declare_queryable(key, answer)


@pytest.mark.parametrize("robots", [NAMESPACED], ids=["namespaced"])
async def test_given_namespaces_only_its_own_executor_and_bridge_speak_for_a_robot(
    site: SecureSite,
) -> None:
    """Issue 32, on the robots' own keys: with each robot's ROS namespace known
    (bus-secrets --namespace r1=bot1), r1's executor publishes velocity and asks actions
    only under bot1, and r1's robot side publishes and announces interfaces only under
    bot1. Each forgery is said before its genuine twin, on the same link."""
    bot1, bot2 = RobotNames("bot1"), RobotNames("bot2")
    heard: list[str] = []
    announced: list[str] = []

    with (
        site.joined("observer") as observer,
        site.joined("executor-r1") as executor1,
        site.joined("executor-r2") as executor2,
        site.joined("robot-r1") as robot1,
        site.joined("robot-r2") as robot2,
    ):
        for key in (bot2.cmd_vel, bot1.cmd_vel, bot2.odom, bot1.odom):
            observer.subscribe(key, bytes, lambda key, _: heard.append(key))
        observer.watch(BRIDGE_TOKENS, lambda key, up: up and announced.append(key))
        for key in (bot1.cmd_vel, bot2.cmd_vel):
            await until_heard(executor1, key)
        executor1.publish_bytes(bot2.cmd_vel, CODEC.twist(1.0, 0.0))
        executor1.publish_bytes(bot1.cmd_vel, CODEC.twist(1.0, 0.0))
        await async_wait_until(lambda: bot1.cmd_vel in heard, 10.0, "bot1's velocity")
        assert bot2.cmd_vel not in heard

        zid = str(robot1.session.info.zid())
        forged, genuine = (
            BridgeToken(BridgeKind.PUBLISHER, names.odom, "nav_msgs/msg/Odometry").token_key(zid)
            for names in (bot2, bot1)
        )
        robot1.announce(forged)
        robot1.publish_bytes(bot2.odom, b"forged")
        robot1.announce(genuine)
        robot1.publish_bytes(bot1.odom, b"genuine")
        await async_wait_until(
            lambda: genuine in announced and bot1.odom in heard, 10.0, "bot1's robot side"
        )
        assert forged not in announced
        assert bot2.odom not in heard

        goal1, goal2 = bot1.navigate("send_goal"), bot2.navigate("send_goal")
        answering(robot1, goal1)
        answering(robot2, goal2)

        async def answered(bus: Bus, key: str) -> bool:
            return await asyncio.to_thread(replies, bus, key) == [key]

        for bus, key in ((executor1, goal1), (executor2, goal2)):
            await async_wait_until(partial(answered, bus, key), 10.0, f"{key} answered")
        # Refused queries are dropped unanswered: they end at the timeout.
        assert await asyncio.to_thread(replies, executor1, goal2, 2.0) == []


def without_credentials(config: Path, target: Path) -> Path:
    client = json.loads(config.read_text())
    del client["transport"]["auth"]
    target.write_text(json.dumps(client))
    return target


def test_no_credentials_or_a_wrong_password_cannot_connect(
    site: SecureSite, tmp_path: Path
) -> None:
    anonymous = without_credentials(site.config("panel"), tmp_path / "anonymous.json5")
    wrong = json.loads(site.config("panel").read_text())
    wrong["transport"]["auth"]["usrpwd"]["password"] = "guess"
    guessing = tmp_path / "guessing.json5"
    guessing.write_text(json.dumps(wrong))
    path = os.environ["PATH"]
    up, router = (hint(f"voicectl_command('{c}')", REPO, path) for c in ("up", "router"))
    for config in (anonymous, guessing):
        refused = voicectl("state", "--robot", "r1", "--config", str(config), timeout=60)
        assert refused.returncode == 3
        assert refused.stderr.strip() == (
            f"voicectl state: cannot reach the router at {site.endpoint} (waited 3 s; is "
            f"{up} or {router} running, and do its TLS certificates and "
            "credentials match --config?)"
        )
    allowed = voicectl("state", "--robot", "r1", "--config", str(site.config("panel")))
    assert allowed.returncode == 3  # connected; only no supervisor serves r1 here
    assert "no service answered (none is up, or the router's access control" in allowed.stderr


def test_a_certificate_from_another_authority_is_refused(site: SecureSite, tmp_path: Path) -> None:
    other = tmp_path / "other"
    write_bus_secrets(other, ["127.0.0.1"])
    client = json.loads(site.config("panel").read_text())
    client["transport"]["link"]["tls"]["root_ca_certificate"] = str(other / "ca.pem")
    impostor = tmp_path / "impostor.json5"
    impostor.write_text(json.dumps(client))
    refused = voicectl("state", "--robot", "r1", "--config", str(impostor), timeout=60)
    assert refused.returncode == 3
    assert refused.stderr.startswith(f"voicectl state: cannot reach the router at {site.endpoint}")
    plain = voicectl("state", "--robot", "r1", "--connect", site.endpoint.replace("tls/", "tcp/"))
    assert plain.returncode == 3


async def test_the_documented_observer_watches_the_order_stream(site: SecureSite) -> None:
    """docs/deploy.md's Zenoh CLI command, with the observer's credentials, sees what the
    supervisor publishes (and the observer cannot publish itself)."""
    doc = (REPO / "docs" / "deploy.md").read_text()
    command = doc.split("To watch the order stream on a secured router", 1)[1]
    command = command.split("```sh\n", 1)[1].split("\n```", 1)[0]
    words = shlex.split(command.replace("~/.local/share/voicectl/bus", str(site.secrets)))
    assert words[0] == ".venv/bin/zenoh"
    words[0] = str(Path(sys.executable).with_name("zenoh"))
    watcher = await asyncio.create_subprocess_exec(*words, stdout=asyncio.subprocess.PIPE)
    lines: list[bytes] = []

    async def read() -> None:
        assert watcher.stdout is not None
        while line := await watcher.stdout.readline():
            lines.append(line)

    reader = asyncio.ensure_future(read())
    try:
        with site.joined("supervisor") as bus:
            await until_heard(bus, "voice/r1/supervisor/state", timeout=30.0)
            bus.publish_bytes("voice/r1/supervisor/state", b'{"marker": 1}')
            await async_wait_until(
                lambda: any(b'"marker"' in line for line in lines), 10.0, "the observer's line"
            )
    finally:
        if watcher.returncode is None:
            watcher.terminate()
        await asyncio.wait_for(watcher.wait(), 10.0)
        await asyncio.wait_for(reader, 10.0)

    with site.joined("panel") as bus:
        received: list[bytes] = []
        bus.subscribe("voice/r1/supervisor/state", bytes, lambda _k, raw: received.append(raw))
        await asyncio.sleep(0.5)
        with site.joined("observer") as sneaky:
            for _ in range(5):
                sneaky.publish_bytes("voice/r1/supervisor/state", b'{"forged": 1}')
                await asyncio.sleep(0.1)
        await asyncio.sleep(0.5)
        assert received == []


def test_secrets_are_made_once_and_a_client_config_travels(
    site: SecureSite, tmp_path: Path
) -> None:
    """What compose.yaml's first start needs: `--if-missing` keeps the secrets there (the
    running services' passwords stay good), and `--client USER` prints a user's config
    with its CA inside, which works from anywhere (a host command, outside the volume)."""
    before = (site.secrets / "passwords").read_bytes()
    kept = voicectl("bus-secrets", str(site.secrets), "--if-missing", "--host", "other")
    assert (kept.returncode, kept.stdout) == (
        0,
        f"bus secrets in {site.secrets} kept: made before\n",
    )
    assert (site.secrets / "passwords").read_bytes() == before
    made = voicectl("bus-secrets", str(tmp_path / "new"), "--if-missing")
    assert made.returncode == 0
    assert (tmp_path / "new" / "passwords").is_file()
    printed = voicectl(
        "bus-secrets", str(site.secrets), "--client", "operator", "--endpoint", site.endpoint
    )
    assert printed.returncode == 0, printed.stderr
    elsewhere = tmp_path / "elsewhere" / "operator.json5"
    elsewhere.parent.mkdir()
    elsewhere.write_text(printed.stdout)
    assert str(site.secrets) not in printed.stdout  # no path into the secrets' directory
    reached = voicectl("state", "--robot", "r1", "--config", str(elsewhere))
    assert reached.returncode == 3  # connected; only no supervisor serves r1 here
    assert "no service answered" in reached.stderr, reached.stderr
    unknown = voicectl("bus-secrets", str(site.secrets), "--client", "nobody")
    assert unknown.returncode == 1
    assert unknown.stderr.startswith("voicectl bus-secrets: no client 'nobody' in ")


def test_the_secured_router_notices_a_lost_link_as_soon_as_the_open_one() -> None:
    """The secured router template kept Zenoh's 10 s lease while the open router says 3 s:
    a robot cut off from a secured bus went unnoticed for 10 s."""
    import json5

    secured = json5.loads((REPO / "voicectl" / "secure-router.json5").read_text())
    plain = json5.loads((REPO / "deploy" / "zenoh" / "router.json5").read_text())
    lease = plain["transport"]["link"]["tx"]["lease"]
    assert secured["transport"]["link"]["tx"]["lease"] == lease == 3000
