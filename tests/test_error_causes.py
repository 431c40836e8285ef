"""Errors that name their cause and say what to do (issue 34, "The first hour"): one line on stderr and exit code 2,
never a traceback, with real processes and sockets. A port that something already listens on (a router, an agent,
a scenario run, ``make demo``), a router that cannot be reached (a peer that waits for team-mates in vain, a client
that cannot connect), team-mates present under another fleet name, and a fleet name that is not one."""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import subprocess
import sys

import pytest

from agents.transport.ports import listening
from tests.fleet_procs import ROOT, Fleet, free_port

CLI = [sys.executable, "-m", "agents.cli"]


@contextlib.contextmanager
def occupied_port():
    """A loopback port that a plain socket listens on, as another fleet's router would."""
    port = free_port()
    with socket.socket() as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(("127.0.0.1", port))
        sock.listen()
        yield port


def run_cli(*args: str, timeout: float = 120) -> tuple[int, str]:
    done = subprocess.run([*CLI, *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout)
    return done.returncode, done.stderr


def one_line(stderr: str) -> str:
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in stderr, stderr
    assert lines[0].startswith("error: "), lines[0]
    return lines[0]


def test_listening_tells_a_listener_from_a_free_port():
    with occupied_port() as port:
        assert listening(f"tcp/127.0.0.1:{port}")
    assert not listening(f"tcp/127.0.0.1:{free_port()}")
    assert not listening("tcp/127.0.0.1:0") and not listening("udp/127.0.0.1:7447")


@pytest.mark.parametrize("command", [
    ["router", "--no-multicast"],
    ["agent", "--fleet", "demo", "--vehicle", "H1", "--frames", "1"],
    ["scenario", "run", "exp2a-features", "--frames", "2"],
])
def test_a_port_in_use_is_named_with_what_to_do(command):
    with occupied_port() as port:
        code, stderr = run_cli(*command, "--listen", f"tcp/127.0.0.1:{port}")
    line = one_line(stderr)
    assert code == 2
    assert f"tcp/127.0.0.1:{port} is already in use" in line and f"--listen tcp/127.0.0.1:{port + 1}" in line, line


def test_make_demo_takes_the_port_and_says_when_it_is_taken():
    """``make demo PORT=P`` with P taken stops before starting anything and names the next port; needs the venv
    that make builds (skipped, saying so, where it is not built: make would install it first)."""
    stamp = ROOT / ".venv" / ".installed"
    inputs = [ROOT / "pyproject.toml", ROOT / "constraints.txt"]
    if shutil.which("make") is None or not stamp.exists() or any(
            p.stat().st_mtime > stamp.stat().st_mtime for p in inputs):
        pytest.skip("make's .venv is not built or older than pyproject.toml / constraints.txt: make demo would "
                    "install it first")
    with occupied_port() as port:
        done = subprocess.run(["make", "--no-print-directory", "demo", f"PORT={port}"], cwd=ROOT,
                              capture_output=True, text=True, timeout=60, env={**os.environ, "MAKEFLAGS": ""})
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert f"port {port} is in use" in done.stderr and f"make demo PORT={port + 1}" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr and done.stdout == ""


def test_a_client_whose_router_is_not_there():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    code, stderr = run_cli("agent", "--fleet", "demo", "--vehicle", "H1", "--frames", "1", "--mode", "client",
                           "--connect", endpoint)
    line = one_line(stderr)
    assert code == 2 and f"could not reach the fleet's router at {endpoint}: nothing listens there" in line, line
    assert f"evopose router --listen {endpoint}" in line


def test_a_team_mate_that_never_appeared_because_nothing_answered():
    """A peer that connects to nothing (its router was never started) waits for its team-mate, then says why."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    code, stderr = run_cli("agent", "--fleet", "demo", "--vehicle", "H1", "--frames", "1", "--connect", endpoint,
                           "--wait-for", "H2", "--wait-timeout", "2", "--no-multicast")
    line = one_line(stderr)
    assert code == 2 and "H2 of H1 did not appear" in line, line
    assert f"nothing answered at {endpoint}" in line and "evopose router --listen" in line, line


def test_team_mates_in_another_fleet_name_the_right_fleet():
    port = free_port()
    fleet = Fleet(port, "right-fleet")
    try:
        router = fleet.start("router", "--listen", fleet.endpoint, "--json", "--no-multicast", connect=False)
        router.next_record(10, lambda r: r.get("event") == "ready")
        mate = fleet.start("agent", "--fleet", "right-fleet", "--vehicle", "H2", "--frames", "100000", "--json")
        mate.next_record(120, lambda r: r.get("event") == "ready")
        code, stderr = run_cli("agent", "--fleet", "wrong-fleet", "--vehicle", "H1", "--frames", "1", "--wait-for",
                               "H2", "--wait-timeout", "2", "--connect", fleet.endpoint, "--mode", "client",
                               "--no-multicast")
    finally:
        fleet.close()
    line = one_line(stderr)
    assert code == 2 and "no team-mate H2 in fleet 'wrong-fleet'" in line, line
    assert "H2 in 'right-fleet'" in line and "use --fleet right-fleet" in line, line


def test_a_fleet_name_that_is_not_one():
    code, stderr = run_cli("agent", "--fleet", "my fleet", "--vehicle", "H1", "--frames", "1")
    line = one_line(stderr)
    assert code == 2 and "fleet 'my fleet' must be" in line, line
