"""Two hosts on one machine: a host and a robot in Linux network namespaces joined by a
veth pair, a link that can be cut or made slow and lossy, and voicectl processes started
on either side. Used by tests/test_cross_host.py and bench/cross_host.py; needs root.

Each side reaches the other only across the veth (10.213.0.1/30 on the host, .2 on the
robot: addresses that exist inside the two namespaces only). A process outside both, such
as a test, joins a side's router through a Unix socket, as a process on that host would:
a socket file belongs to no network namespace. The routers never connect to each other
that way: a Zenoh router makes no connection to what it learns of by gossip (the cut link
of tests/test_cross_host.py would not lose the executor if they did).

The kernels here have no netem, so delay and loss are made by this module's own shaper:
iptables hands every packet leaving a side through the veth to an NFQUEUE, and a small
process (`python -m harness.netns shape`) gives each its verdict after the delay, or drops
it with the loss probability: netem's `delay D loss L` on both ends of the link.

    python -m harness.netns shape --queue N --delay-ms 100 --loss 5   (inside a namespace)
    python -m harness.netns clean      (remove what runs of killed tests left behind)
    python -m harness.netns rtps --seconds 10 --enough 3   (DDS's datagrams seen here)
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import itertools
import os
import random
import re
import select
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Literal

from .processes import Processes

HOST_ADDR = "10.213.0.1"
ROBOT_ADDR = "10.213.0.2"
PORT = 7447
LEASE_MS = 2000
"""Zenoh lease of every process: a link down longer than this loses the other side."""
LEASE = ("--cfg", f"transport/link/tx/lease:{LEASE_MS}")

Side = Literal["host", "robot"]
SIDES: tuple[Side, ...] = ("host", "robot")
_PREFIX = "vcx"
_NAME = re.compile(rf"^{_PREFIX}(\d+)n\d+[hrl]$")
_COUNTER = itertools.count()


def unavailable() -> str | None:
    """Why two hosts cannot be made here, or None when they can."""
    if os.geteuid() != 0:
        return "network namespaces need root"
    if shutil.which("ip") is None:
        return "iproute2's `ip` is not installed"
    try:
        subprocess.run(["ip", "netns", "list"], check=True, capture_output=True, timeout=10)
    except (OSError, subprocess.SubprocessError) as exc:
        return f"`ip netns` does not work here: {exc}"
    return None


def impairment_unavailable() -> str | None:
    """Why the link cannot be made slow and lossy here, or None when it can."""
    if shutil.which("iptables") is None:
        return "iptables is not installed (Debian package iptables)"
    return None


def _run(*command: str) -> None:
    done = subprocess.run(command, capture_output=True, text=True, timeout=30, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(command)}: {done.stderr.strip() or done.returncode}")


def clean_stale() -> list[str]:
    """Delete the namespaces (and socket directories) of runs whose process is gone (a
    killed test); the names of the namespaces deleted. Those of live runs are left alone."""
    listed = subprocess.run(
        ["ip", "netns", "list"], capture_output=True, text=True, timeout=10, check=False
    ).stdout
    deleted = []
    for line in listed.splitlines():
        name = line.split(" ", 1)[0]
        match = _NAME.match(name)
        if match and not Path(f"/proc/{match[1]}").exists():
            subprocess.run(["ip", "netns", "del", name], capture_output=True, timeout=10)
            deleted.append(name)
    for directory in Path(tempfile.gettempdir()).glob(f"{_PREFIX}*-*"):
        match = _NAME.match(directory.name.split("-", 1)[0] + "h")
        if match and not Path(f"/proc/{match[1]}").exists():
            shutil.rmtree(directory, ignore_errors=True)
    return deleted


class TwoHosts:
    """A host and a robot joined by one veth pair; every process started here is stopped,
    and both namespaces deleted, by `close()`, whatever happened before."""

    def __init__(self, logs: Path) -> None:
        self.logs = logs
        logs.mkdir(parents=True, exist_ok=True)
        tag = f"{_PREFIX}{os.getpid()}n{next(_COUNTER)}"
        self.namespaces: dict[Side, str] = {"host": f"{tag}h", "robot": f"{tag}r"}
        """Namespace names, the same as the names of their ends of the veth."""
        # Unix socket paths must stay under 108 bytes: a directory of its own in /tmp.
        self._sockets = Path(tempfile.mkdtemp(prefix=f"{tag}-"))
        self.processes = Processes(logs)
        self._shapers: list[subprocess.Popen[bytes]] = []
        self._pdeathsig = (
            # Children die with this process even when it is SIGKILLed (a timed-out test).
            ["setpriv", "--pdeathsig", "KILL"] if shutil.which("setpriv") else []
        )
        clean_stale()
        try:
            self._create()
        except BaseException:
            self.close()
            raise

    def _create(self) -> None:
        host, robot = self.namespaces["host"], self.namespaces["robot"]
        _run("ip", "netns", "add", host)
        _run("ip", "netns", "add", robot)
        _run("ip", "link", "add", host, "type", "veth", "peer", "name", robot)
        for side, address in zip(SIDES, (HOST_ADDR, ROBOT_ADDR), strict=True):
            name = self.namespaces[side]
            _run("ip", "link", "set", name, "netns", name)
            _run("ip", "-n", name, "addr", "add", f"{address}/30", "dev", name)
            _run("ip", "-n", name, "link", "set", name, "up")
            _run("ip", "-n", name, "link", "set", "lo", "up")

    # --- endpoints ------------------------------------------------------------------------

    @property
    def host_router(self) -> str:
        """Where the robot's router reaches the host's, across the link."""
        return f"tcp/{HOST_ADDR}:{PORT}"

    @staticmethod
    def local_router() -> str:
        """Where a process reaches its own side's router."""
        return f"tcp/127.0.0.1:{PORT}"

    def socket(self, side: Side) -> str:
        """A side's router for a process outside both namespaces (a test)."""
        return f"unixsock-stream/{self._sockets / side}.sock"

    # --- processes ------------------------------------------------------------------------

    def start(self, side: Side, module: str, *args: str, name: str) -> subprocess.Popen[bytes]:
        """`python -m module args` inside `side`'s namespace; its output goes to a log."""
        # `ip netns exec` and setpriv exec the next program: the child is Python itself.
        prefix = ["ip", "netns", "exec", self.namespaces[side], *self._pdeathsig]
        return self.processes.start(module, *args, name=name, prefix=prefix)

    def start_router(self, side: Side) -> subprocess.Popen[bytes]:
        """`voicectl router` on `side`, listening on its loopback, its Unix socket and (the
        host) its link address; the robot's connects to the host's across the link."""
        listen = [self.local_router(), self.socket(side)]
        if side == "host":
            listen.append(self.host_router)
        args = [arg for endpoint in listen for arg in ("--listen", endpoint)]
        if side == "robot":
            args += ["--connect", self.host_router]
        return self.start(side, "voicectl.services.router", *args, *LEASE, name=f"{side}-router")

    def log(self, name: str) -> str:
        return self.processes.log(name)

    def dump(self) -> str:
        return self.processes.dump()

    # --- the link ---------------------------------------------------------------------------

    @contextlib.contextmanager
    def link_down(self) -> Iterator[None]:
        """The veth down for the time of the block (both directions: its peer loses carrier)."""
        host = self.namespaces["host"]
        _run("ip", "-n", host, "link", "set", host, "down")
        try:
            yield
        finally:
            _run("ip", "-n", host, "link", "set", host, "up")

    @contextlib.contextmanager
    def impaired(self, delay_ms: float, loss_percent: float) -> Iterator[None]:
        """Every packet crossing the link, either way, is delayed by `delay_ms` and lost
        with `loss_percent` % probability, for the time of the block."""
        rules = []
        try:
            for queue, side in enumerate(SIDES, start=1):
                name = self.namespaces[side]
                shaper = self.start(
                    side,
                    "harness.netns",
                    *("shape", "--queue", str(queue), "--delay-ms", str(delay_ms)),
                    *("--loss", str(loss_percent)),
                    name=f"shaper-{name}",
                )
                self._shapers.append(shaper)
                self._wait_ready(shaper, f"shaper-{name}")
                rule = ["-o", name, "-j", "NFQUEUE", "--queue-num", str(queue)]
                _run("ip", "netns", "exec", name, "iptables", "-A", "OUTPUT", *rule)
                rules.append((name, rule))
            yield
        finally:
            for name, rule in rules:
                _run("ip", "netns", "exec", name, "iptables", "-D", "OUTPUT", *rule)
            while self._shapers:  # each lets its held packets go before it exits
                Processes.stop(self._shapers.pop())

    def _wait_ready(self, process: subprocess.Popen[bytes], name: str) -> None:
        deadline = time.monotonic() + 30.0
        while "ready" not in self.log(name):
            if process.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"{name} did not start:\n{self.log(name)}")
            time.sleep(0.05)

    # --- teardown -----------------------------------------------------------------------------

    def close(self) -> list[str]:
        """Stop everything and delete both namespaces (with the veth); what did not stop
        cleanly."""
        try:
            unclean = self.processes.stop_all()
        finally:
            for name in self.namespaces.values():
                subprocess.run(["ip", "netns", "del", name], capture_output=True, timeout=30)
            shutil.rmtree(self._sockets, ignore_errors=True)
        return unclean

    def __enter__(self) -> TwoHosts:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()


class LoopbackOnly:
    """One network namespace with nothing but loopback up, for processes that must reach
    one another and nothing else: DDS participants (real ROS 2), which discover by
    multicast. No route leaves it, so no packet of theirs can leave the machine. A
    process outside joins a Zenoh router in it, or it one outside, through a Unix socket
    (`socket`). Everything started here is stopped, and the namespace deleted, by
    `close()`, whatever happened before; `clean_stale` removes those of killed runs."""

    def __init__(self, logs: Path) -> None:
        logs.mkdir(parents=True, exist_ok=True)
        tag = f"{_PREFIX}{os.getpid()}n{next(_COUNTER)}"
        self.name = f"{tag}l"
        self._sockets = Path(tempfile.mkdtemp(prefix=f"{tag}-"))
        self.processes = Processes(logs)
        self._pdeathsig = ["setpriv", "--pdeathsig", "KILL"] if shutil.which("setpriv") else []
        clean_stale()
        try:
            _run("ip", "netns", "add", self.name)
            _run("ip", "-n", self.name, "link", "set", "lo", "up")
        except BaseException:
            self.close()
            raise

    def socket(self, name: str = "router") -> str:
        """A Zenoh endpoint on a Unix socket that both sides of the namespace reach."""
        return f"unixsock-stream/{self._sockets / name}.sock"

    @property
    def prefix(self) -> list[str]:
        """What runs a command inside (it execs the next program)."""
        return ["ip", "netns", "exec", self.name, *self._pdeathsig]

    def start(
        self,
        module: str,
        *args: str,
        name: str,
        python: str | Path | None = None,
        env: dict[str, str] | None = None,
    ) -> subprocess.Popen[bytes]:
        """`python -m module args` inside; its output goes to a log."""
        return self.processes.start(
            module, *args, name=name, prefix=self.prefix, python=python, env=env
        )

    def run(self, *command: str, env: dict[str, str] | None = None) -> str:
        """Run a command inside to its end; its output (RuntimeError if it fails)."""
        done = subprocess.run(
            [*self.prefix, *command], capture_output=True, text=True, timeout=60, env=env
        )
        if done.returncode != 0:
            raise RuntimeError(f"{' '.join(command)}: {done.stderr.strip() or done.returncode}")
        return done.stdout

    def log(self, name: str) -> str:
        return self.processes.log(name)

    def dump(self) -> str:
        return self.processes.dump()

    def close(self) -> list[str]:
        """Stop everything started here and delete the namespace; what did not stop cleanly."""
        try:
            unclean = self.processes.stop_all()
        finally:
            subprocess.run(["ip", "netns", "del", self.name], capture_output=True, timeout=30)
            shutil.rmtree(self._sockets, ignore_errors=True)
        return unclean

    def __enter__(self) -> LoopbackOnly:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()


# --- DDS's packets, counted: that they stay in the namespace -----------------------------

_ETH_P_ALL = 0x0003
_UDP = 17


def is_rtps(frame: bytes) -> bool:
    """Whether a link-layer frame (AF_PACKET, Ethernet framing, as loopback has too) is a
    UDP datagram of RTPS, DDS's wire protocol: its payload starts with b'RTPS'."""
    if len(frame) < 14:
        return False
    ethertype = int.from_bytes(frame[12:14], "big")
    if ethertype == 0x0800 and len(frame) >= 34 and frame[23] == _UDP:
        udp = 14 + (frame[14] & 0x0F) * 4
    elif ethertype == 0x86DD and len(frame) >= 54 and frame[20] == _UDP:
        udp = 14 + 40
    else:
        return False
    return frame[udp + 8 : udp + 12] == b"RTPS"


class RtpsCounter:
    """Counts, on a thread of its own, the RTPS datagrams that cross any link of the
    network namespace it was made in (sent or received), until closed; `reached` is set
    once `enough` are seen. Needs root."""

    def __init__(self, enough: int = 1) -> None:
        self.count = 0
        self.reached = threading.Event()
        self._enough = enough
        self._sniffer = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(_ETH_P_ALL))
        self._sniffer.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
        self._sniffer.settimeout(0.1)
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._count, name="rtps-counter", daemon=True)
        self._thread.start()

    def _count(self) -> None:
        while not self._stopping.is_set():
            try:
                frame = self._sniffer.recv(65535)
            except TimeoutError:
                continue
            if is_rtps(frame):
                self.count += 1
                if self.count >= self._enough:
                    self.reached.set()

    def close(self) -> int:
        """Stop counting; the count."""
        self._stopping.set()
        self._thread.join()
        self._sniffer.close()
        return self.count

    def __enter__(self) -> RtpsCounter:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()


def count_rtps(seconds: float, enough: int) -> int:
    """RTPS datagrams seen in this namespace within `seconds`, stopping early at `enough`."""
    with RtpsCounter(enough) as counter:
        counter.reached.wait(seconds)
        return counter.count


# --- the shaper: netem's delay and loss in user space, through NFQUEUE ---------------------

_NETLINK_NETFILTER = 12
_SOL_NETLINK, _NETLINK_NO_ENOBUFS = 270, 5
_QUEUE = 3 << 8  # NFNL_SUBSYS_QUEUE
_PACKET, _VERDICT, _CONFIG = _QUEUE | 0, _QUEUE | 1, _QUEUE | 2
_REQUEST, _ACK = 1, 4
_ERROR = 2  # NLMSG_ERROR
_CFG_CMD, _CFG_PARAMS, _CFG_QUEUE_MAXLEN = 1, 2, 3
_CMD_BIND = 1
_COPY_META = 1
_PACKET_HDR, _VERDICT_HDR = 1, 2
_DROP, _ACCEPT = 0, 1


def _attribute(kind: int, payload: bytes) -> bytes:
    raw = struct.pack("=HH", 4 + len(payload), kind) + payload
    return raw + b"\0" * (-len(raw) % 4)


def _message(kind: int, queue: int, attributes: bytes, flags: int = _REQUEST) -> bytes:
    body = struct.pack("=BB", socket.AF_UNSPEC, 0) + struct.pack("!H", queue) + attributes
    return struct.pack("=IHHII", 16 + len(body), kind, flags, 0, 0) + body


def _packet_ids(data: bytes) -> Iterator[int]:
    """The ids of the packets in one netlink read; raises on an error message."""
    offset = 0
    while offset + 16 <= len(data):
        length, kind = struct.unpack_from("=IH", data, offset)
        if kind == _ERROR:
            (error,) = struct.unpack_from("=i", data, offset + 16)
            if error:
                raise OSError(-error, f"nfqueue: {os.strerror(-error)}")
        elif kind == _PACKET:
            position, end = offset + 20, offset + length
            while position + 4 <= end:
                size, attribute = struct.unpack_from("=HH", data, position)
                if attribute & 0x7FFF == _PACKET_HDR:
                    yield struct.unpack_from("!I", data, position + 4)[0]
                position += max(4, (size + 3) & ~3)
        offset += max(16, (length + 3) & ~3)


def shape(queue: int, delay: float, loss: float) -> None:
    """Hold each packet of NFQUEUE `queue` for `delay` seconds, dropping a `loss` fraction,
    until SIGTERM; then let every held packet go."""
    stopping = False

    def stop(_signum: int, _frame: object) -> None:
        nonlocal stopping
        stopping = True

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    with socket.socket(socket.AF_NETLINK, socket.SOCK_RAW, _NETLINK_NETFILTER) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
        sock.setsockopt(_SOL_NETLINK, _NETLINK_NO_ENOBUFS, 1)
        sock.bind((0, 0))
        for attribute in (
            _attribute(_CFG_CMD, struct.pack("!BBH", _CMD_BIND, 0, 0)),
            _attribute(_CFG_PARAMS, struct.pack("!IB", 0, _COPY_META)),
            _attribute(_CFG_QUEUE_MAXLEN, struct.pack("!I", 20_000)),
        ):
            sock.send(_message(_CONFIG, queue, attribute, _REQUEST | _ACK))
            list(_packet_ids(sock.recv(4096)))  # the acknowledgement, or an error raised
        print(f"ready: queue {queue}, delay {delay * 1000:g} ms, loss {loss:.1%}", flush=True)

        def verdict(packet_id: int, what: int) -> None:
            sock.send(
                _message(
                    _VERDICT, queue, _attribute(_VERDICT_HDR, struct.pack("!II", what, packet_id))
                )
            )

        held: collections.deque[tuple[float, int]] = collections.deque()
        seen = dropped = 0
        while not stopping:
            wait = max(0.0, held[0][0] - time.monotonic()) if held else 0.2
            try:
                readable, _, _ = select.select([sock], [], [], wait)
            except InterruptedError:
                continue
            if readable:
                for packet_id in _packet_ids(sock.recv(1 << 20)):
                    seen += 1
                    if random.random() < loss:
                        dropped += 1
                        verdict(packet_id, _DROP)
                    else:
                        held.append((time.monotonic() + delay, packet_id))
            now = time.monotonic()
            while held and held[0][0] <= now:
                verdict(held.popleft()[1], _ACCEPT)
        for _, packet_id in held:
            verdict(packet_id, _ACCEPT)
        print(f"stopped: {seen} packets, {dropped} dropped", flush=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m harness.netns", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)
    shaper = commands.add_parser("shape", help="delay and drop the packets of one NFQUEUE")
    shaper.add_argument("--queue", type=int, required=True)
    shaper.add_argument("--delay-ms", type=float, default=100.0)
    shaper.add_argument("--loss", type=float, default=5.0, metavar="PERCENT")
    commands.add_parser("clean", help="delete namespaces left by killed runs")
    rtps = commands.add_parser("rtps", help="count DDS's datagrams on this namespace's links")
    rtps.add_argument("--seconds", type=float, default=10.0, help="count for this long")
    rtps.add_argument("--enough", type=int, default=1, help="stop once this many are seen")
    args = parser.parse_args(argv)
    if args.command == "shape":
        shape(args.queue, args.delay_ms / 1000, args.loss / 100)
    elif args.command == "rtps":
        print(count_rtps(args.seconds, args.enough))
    else:
        print("\n".join(clean_stale()) or "nothing to clean")
    return 0


if __name__ == "__main__":
    sys.exit(main())
