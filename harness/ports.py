"""Free loopback ports, for a router, a panel or a service started by a test or a benchmark."""

from __future__ import annotations

import contextlib
import socket


def free_ports(count: int) -> list[int]:
    """`count` different free ports: each socket stays bound until all are chosen, or two
    calls in a row may be given the same port (a stack's router and panel once were)."""
    with contextlib.ExitStack() as held:
        ports = []
        for _ in range(count):
            sock = held.enter_context(socket.socket())
            sock.bind(("127.0.0.1", 0))
            ports.append(sock.getsockname()[1])
        return ports


def free_port() -> int:
    return free_ports(1)[0]
