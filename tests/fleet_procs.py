"""Helpers for multi-process fleet tests: free loopback ports, `evopose` subprocesses that are always killed,
and their JSON-line output read with timeouts."""

from __future__ import annotations

import contextlib
import json
import queue
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

from agents.runs import pose_rows
from agents.transport.ports import free_loopback_port as free_port
from agents.vehicle.start_signal import release_line

ROOT = Path(__file__).resolve().parents[1]


class Proc:
    """A subprocess whose stdout lines are collected by a thread; JSON lines are parsed."""

    def __init__(self, args: list[str]) -> None:
        self.args = args
        # an agent of `--epoch-from-stdin` reads its epoch from stdin (release_when_warm); the others never read it
        stdin = subprocess.PIPE if "--epoch-from-stdin" in args else subprocess.DEVNULL
        self.popen = subprocess.Popen(args, cwd=ROOT, stdin=stdin, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                      text=True)
        self.lines: queue.Queue[str] = queue.Queue()
        self.records: list[dict] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.popen.stdout:
            self.lines.put(line)

    def next_record(self, timeout: float, where=lambda record: True) -> dict:
        """The next JSON line satisfying ``where``, waiting up to ``timeout`` s."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                line = self.lines.get(timeout=max(deadline - time.monotonic(), 0.01))
            except queue.Empty:
                raise AssertionError(f"no matching output from {self.args} within {timeout} s; "
                                     f"exit code {self.popen.poll()}, stderr: {self.stderr_now()}") from None
            try:
                record = json.loads(line)
            except ValueError:
                continue
            self.records.append(record)
            if where(record):
                return record

    def first_record(self, timeout: float, where=lambda record: True) -> dict:
        """The first JSON line satisfying ``where``, among those already read or, waiting up to ``timeout`` s, the
        next ones (for events whose order with others is not fixed)."""
        for record in self.all_records():
            if where(record):
                return record
        return self.next_record(timeout, where)

    def stderr_now(self) -> str:
        return "" if self.popen.poll() is None else self.popen.stderr.read()

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 5.0) -> tuple[int, float]:
        """Send ``sig`` and wait; return the exit code and how long the exit took (s)."""
        started = time.monotonic()
        self.popen.send_signal(sig)
        code = self.popen.wait(timeout)
        self._reader.join(2)
        return code, time.monotonic() - started

    def wait(self, timeout: float) -> int:
        code = self.popen.wait(timeout)
        self._reader.join(2)
        return code

    def all_records(self) -> list[dict]:
        while not self.lines.empty():
            try:
                self.records.append(json.loads(self.lines.get_nowait()))
            except ValueError:
                pass
        return self.records

    def kill(self) -> None:
        if self.popen.poll() is None:
            self.popen.kill()
            self.popen.wait(5)


def release_when_warm(procs: list[Proc], timeout: float = 120) -> int:
    """Once every agent of ``procs`` (started with ``--epoch-from-stdin``) has said ``warm``, give all the same epoch,
    as ``evopose scenario run`` does (agents.experiments.runner.release_when_warm); the epoch."""
    for proc in procs:
        proc.next_record(timeout, lambda r: r.get("event") == "warm")
    epoch, line = release_line()
    for proc in procs:
        proc.popen.stdin.write(line)
        proc.popen.stdin.flush()
    return epoch


class Fleet:
    """Starts `python -m agents.cli ...` processes connected to one router; kills them all in :meth:`close`."""

    def __init__(self, router_port: int, fleet: str) -> None:
        self.endpoint = f"tcp/127.0.0.1:{router_port}"
        self.fleet = fleet
        self.procs: list[Proc] = []

    def start(self, *args: str, connect: bool = True) -> Proc:
        net = ["--connect", self.endpoint, "--mode", "client", "--no-multicast"] if connect else []
        proc = Proc([sys.executable, "-m", "agents.cli", *args, *net])
        self.procs.append(proc)
        return proc

    def python(self, code: str) -> Proc:
        proc = Proc([sys.executable, "-c", code])
        self.procs.append(proc)
        return proc

    def close(self) -> None:
        for proc in self.procs:
            proc.kill()


@contextlib.contextmanager
def fleet_with_router(name: str) -> Iterator[Fleet]:
    """A :class:`Fleet` named ``name`` whose router listens on a free loopback port; everything killed at the end."""
    fleet = Fleet(free_port(), name)
    try:
        router = fleet.start("router", "--listen", fleet.endpoint, "--json", "--no-multicast", connect=False)
        router.next_record(10, lambda r: r.get("event") == "ready")
        yield fleet
    finally:
        fleet.close()


def client_session(endpoint: str):
    """A Zenoh session of the test itself: a client of the router at ``endpoint``, multicast scouting off."""
    import zenoh

    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", f'["{endpoint}"]')
    config.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(config)


def peer_session(endpoint: str):
    """A Zenoh session of the test itself: a peer that connects to ``endpoint`` and listens nowhere (an outsider on
    the fleet's network: a forger, a flooder), multicast scouting off."""
    import zenoh

    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("connect/endpoints", f'["{endpoint}"]')
    config.insert_json5("listen/endpoints", "[]")
    config.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(config)


def good_from_first(summary: dict) -> tuple[int, bool]:
    """From an agent's summary (its last published poses, :class:`agents.runs.PoseRow`): how many
    frames came before the first good one, and whether every frame after it was good (a pose once confident is
    not lost: the real-time search may take a few frames, then the vehicle holds the target)."""
    flags = [row.good for row in pose_rows(summary)]
    if True not in flags:
        return len(flags), False
    first = flags.index(True)
    return first, all(flags[first:])
