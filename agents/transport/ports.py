"""A free loopback TCP port for a fleet that will listen on it a moment later (tests, benchmarks, demos).

Binding port 0 and releasing it gives a port from the kernel's ephemeral range, and that is where the kernel
also takes the ports of every ``tcp/127.0.0.1:0`` listener (each Zenoh peer, session.PEER_LISTEN) and the
source port of every outgoing connection. Between the release and the fleet's own bind (a second or two of
Python start-up), the fleet's other processes open many of those, so the port can be taken from under it:
the agent that should listen fails, and an observer connected to the port meets someone else. A port below
the ephemeral range is only ever taken by an explicit bind, so it is drawn there, at random, and checked.
"""

from __future__ import annotations

import errno
import random
import socket
from pathlib import Path

#: Where the kernel draws ephemeral ports (Linux's default, used when /proc does not say).
DEFAULT_EPHEMERAL = (32768, 60999)
#: The lowest port drawn (above the registered services most hosts run).
LOWEST_PORT = 20000
_RANGE_FILE = Path("/proc/sys/net/ipv4/ip_local_port_range")


def ephemeral_range() -> tuple[int, int]:
    """The kernel's ephemeral port range (first, last)."""
    try:
        first, last = (int(word) for word in _RANGE_FILE.read_text().split())
        return first, last
    except (OSError, ValueError):
        return DEFAULT_EPHEMERAL


def free_loopback_port(attempts: int = 200) -> int:
    """A TCP port on 127.0.0.1 that nobody listens on now, below the ephemeral range when there is room."""
    first_ephemeral, last_ephemeral = ephemeral_range()
    low, high = (LOWEST_PORT, first_ephemeral - 1) if first_ephemeral - 1 > LOWEST_PORT \
        else (last_ephemeral + 1, 65535)
    for _ in range(attempts):
        port = random.randint(low, high)
        with socket.socket() as sock:
            try:
                sock.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    raise OSError(f"no free loopback TCP port in {low}-{high} after {attempts} attempts")


def listening(endpoint: str) -> bool:
    """Whether something listens on the TCP endpoint ``tcp/HOST:PORT`` (``tls/`` too) now: a bind that fails. False
    for other endpoints and port 0. The probe reuses the address, as listeners do, so a port left in TIME_WAIT by a
    fleet that just stopped is free."""
    import re

    found = re.fullmatch(r"(?:tcp|tls)/\[?([^\]]*?)\]?:(\d+)(?:#.*)?", endpoint)
    if found is None or int(found.group(2)) == 0:
        return False
    host, port = found.group(1), int(found.group(2))
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((host, port))
        except OSError as err:
            return err.errno == errno.EADDRINUSE
    return False


def next_port(endpoint: str) -> str:
    """``endpoint`` with the next port (``tcp/127.0.0.1:7447`` -> ``tcp/127.0.0.1:7448``), as another one to try."""
    host, _, port = endpoint.rpartition(":")
    return f"{host}:{int(port) + 1}" if port.isdigit() else endpoint
