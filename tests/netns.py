"""Two Linux network namespaces as two "hosts" joined by a veth pair, for fault tests with real processes.

:class:`Hosts` makes namespaces ``A`` (10.231.0.1) and ``B`` (10.231.0.2) and drops packets between them with
iptables (``statistic --mode random``: this kernel has no netem); :meth:`Hosts.close` kills what was started
in them and deletes them (their iptables rules and the veth pair go with them). :class:`FleetOnHosts` runs
one ``evopose router`` per host (B's router connects to A's) and agents that join their host's router as
Zenoh clients. :class:`TimedProc` is a :class:`tests.fleet_procs.Proc` whose JSON records carry their arrival
time (``_rx_ns``, wall clock), so that fault tests can time what they see. Needs root, ``ip`` and ``iptables``
(:func:`unavailable` says why not).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time

from tests.fleet_procs import Proc

#: The hosts' addresses (only ever inside the namespaces made here).
ADDRESSES = {"A": "10.231.0.1", "B": "10.231.0.2"}
ROUTER_PORT = 7447
CLI = [sys.executable, "-m", "agents.cli"]


def unavailable() -> str | None:
    """Why namespaces cannot be made here, or None."""
    if os.geteuid() != 0:
        return "network namespaces need root"
    for tool in ("ip", "iptables"):
        if shutil.which(tool) is None:
            return f"no `{tool}` on PATH"
    return None


def _run(*cmd: str) -> None:
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"`{' '.join(cmd)}` failed: {done.stderr.strip()[:200]}")


class TimedProc(Proc):
    """A :class:`Proc` whose JSON records get ``_rx_ns``: when this process read the line (ns, wall clock)."""

    def _read(self) -> None:
        for line in self.popen.stdout:
            try:
                record = json.loads(line)
            except ValueError:
                self.lines.put(line)
                continue
            if isinstance(record, dict):
                record["_rx_ns"] = time.time_ns()
            self.lines.put(json.dumps(record))


class Hosts:
    """Namespaces ``A`` and ``B`` joined by a veth pair; see the module docstring."""

    def __init__(self) -> None:
        tag = f"{os.getpid() % 100000}"
        self.names = {"A": f"evopose-{tag}-a", "B": f"evopose-{tag}-b"}
        self.veth = {"A": f"evo{tag}a", "B": f"evo{tag}b"}
        self.procs: list[Proc] = []
        self._cut = False
        try:
            _run("ip", "netns", "add", self.names["A"])
            _run("ip", "netns", "add", self.names["B"])
            _run("ip", "link", "add", self.veth["A"], "type", "veth", "peer", "name", self.veth["B"])
            for host, name in self.names.items():
                _run("ip", "link", "set", self.veth[host], "netns", name)
                _run("ip", "-n", name, "addr", "add", f"{ADDRESSES[host]}/24", "dev", self.veth[host])
                _run("ip", "-n", name, "link", "set", self.veth[host], "up")
                _run("ip", "-n", name, "link", "set", "lo", "up")
        except BaseException:
            self.close()
            raise

    def prefix(self, host: str) -> list[str]:
        """The command prefix that runs a program on ``host``."""
        return ["ip", "netns", "exec", self.names[host]]

    def start(self, host: str, args: list[str]) -> TimedProc:
        """Start ``args`` on ``host``; killed at :meth:`close`."""
        proc = TimedProc([*self.prefix(host), *args])
        self.procs.append(proc)
        return proc

    def _iptables(self, host: str, action: str, rule: list[str]) -> None:
        _run(*self.prefix(host), "iptables", action, "INPUT", "-i", self.veth[host], *rule)

    def drop_inbound(self, host: str, probability: float) -> None:
        """Drop ``probability`` of the packets ``host`` receives from the other host (at random)."""
        self._iptables(host, "-A", ["-m", "statistic", "--mode", "random", "--probability", f"{probability}",
                                    "-j", "DROP"])

    def partition(self) -> None:
        """Drop every packet between the hosts (both directions) until :meth:`heal`."""
        for host in self.names:
            self._iptables(host, "-I", ["-j", "DROP"])
        self._cut = True

    def heal(self) -> None:
        """Undo :meth:`partition` (other rules stay)."""
        for host in self.names:
            self._iptables(host, "-D", ["-j", "DROP"])
        self._cut = False

    def close(self) -> None:
        """Kill every process started here, then delete the namespaces (with their rules and the veth pair)."""
        for proc in self.procs:
            try:
                proc.kill()
            except Exception:  # noqa: BLE001 - clean up the rest whatever happens
                pass
        for name in self.names.values():
            subprocess.run(["ip", "netns", "del", name], capture_output=True)


class FleetOnHosts:
    """One router per host (B's connects to A's); agents join their host's router as clients, on one frame clock."""

    def __init__(self, hosts: Hosts, fleet: str, *, fps: float = 10.0, margin_s: float = 6.0) -> None:
        self.hosts, self.fleet, self.fps = hosts, fleet, fps
        self.epoch = time.time_ns() + int(margin_s * 1e9)
        self.routers: dict[str, TimedProc] = {}
        self.agents: dict[str, TimedProc] = {}
        self.hosts_of: dict[str, str] = {}

    def endpoint(self, host: str) -> str:
        return f"tcp/{ADDRESSES[host]}:{ROUTER_PORT}"

    def start_router(self, host: str) -> TimedProc:
        connect = ["--connect", self.endpoint("A")] if host == "B" else []
        router = self.hosts.start(host, [*CLI, "router", "--listen", self.endpoint(host), *connect, "--json"])
        router.next_record(30)  # listening
        self.routers[host] = router
        return router

    def start_agent(self, host: str, vehicle: str, *args: str, wait_for: str = "") -> TimedProc:
        agent = self.hosts.start(host, [
            *CLI, "agent", "--fleet", self.fleet, "--vehicle", vehicle, "--scenario", "exp2", "--fps", f"{self.fps:g}",
            "--epoch-ns", str(self.epoch), "--json", "--wait-for", wait_for, "--wait-timeout", "40", *args,
            "--mode", "client", "--connect", self.endpoint(host), "--no-multicast"])
        self.agents[vehicle] = agent
        self.hosts_of[vehicle] = host
        return agent

    def frames(self, vehicle: str) -> dict[int, dict]:
        return {r["frame"]: r for r in self.agents[vehicle].all_records() if r.get("event") == "frame"}

    def summary(self, vehicle: str, timeout: float) -> dict:
        return self.agents[vehicle].first_record(timeout, lambda r: r.get("event") == "summary")


def frame_time_ns(proc: Proc, record: dict) -> int:
    """When ``record`` (an event without a stamp, e.g. ``stale``) was emitted, from the fleet clock: the stamp of
    the frame record that follows it in ``proc``'s output (the frame during which the event was emitted)."""
    records = proc.all_records()
    at = next(i for i, r in enumerate(records) if r is record)
    return next(r["stamp_ns"] for r in records[at:] if r.get("event") == "frame")
