"""One-way hint latency over the fleet bus, p50 and p99, in the topologies a fleet runs in (issue 13).

Run from the repository root::

    .venv/bin/python -m benchmarks.bench_latency [--hints 2000] [--out benchmarks/results/latency.md]

Two vehicle processes play ping-pong with 24-byte hints over :class:`agents.transport.bus.FleetBus`: ``ping``
sends a hint, ``pong`` sends one back when it receives it; one-way latency is half the round trip (one
clock, no synchronisation needed). Topologies: peer to peer on loopback; both vehicles clients of one
``evopose router``; each vehicle on its own router, the routers joined (a mesh of two); and the two-router
case with 20 % of one router's inbound packets dropped (iptables ``statistic`` in a network namespace pair,
when this machine lets us make one; skipped with its reason otherwise).
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from agents.transport.ports import free_loopback_port as free_port

from .bench_capacity import stop
from .report import md_table, provenance, write_section

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = Path(__file__).resolve().parent / "results" / "latency.md"
FLEET = "latency"


def pong(connect: list[str], listen: list[str], mode: str) -> None:
    """The echo side: every hint from ``ping`` goes straight back as this vehicle's hint."""
    from agents.transport.bus import FleetBus
    from agents.transport.session import SessionOptions
    from protocol import Topic

    options = SessionOptions(mode=mode, connect=tuple(connect), listen=tuple(listen))
    with FleetBus.open(options, FLEET, "pong", max_age_s=None) as bus:
        bus.subscribe(Topic.HINT, lambda rx: bus.publish_hint(np.asarray(rx.message.pose)))
        print("ready", flush=True)
        sys.stdin.read()  # until the parent closes our stdin


def ping(connect: list[str], listen: list[str], mode: str, hints: int, rate_hz: float) -> list[float]:
    """Round trips, seconds, of ``hints`` hints sent at ``rate_hz``."""
    from agents.transport.bus import FleetBus
    from agents.transport.session import SessionOptions
    from protocol import Topic

    options = SessionOptions(mode=mode, connect=tuple(connect), listen=tuple(listen))
    sent: dict[float, float] = {}
    rtts: list[float] = []
    done = threading.Event()
    lock = threading.Lock()

    def back(rx) -> None:
        t = time.perf_counter()
        key = float(rx.message.pose[0])
        with lock:
            start = sent.pop(key, None)
            if start is not None:
                rtts.append(t - start)
                if len(rtts) >= hints:
                    done.set()

    with FleetBus.open(options, FLEET, "ping", max_age_s=None) as bus:
        bus.subscribe(Topic.HINT, back)
        if not bus.wait_for_teammates(["pong"], 20.0):
            raise RuntimeError("pong never appeared")
        time.sleep(0.5)  # let the subscriptions propagate through the routers before counting
        for i in range(hints):
            with lock:
                sent[float(i)] = time.perf_counter()
            bus.publish_hint(np.array([float(i), 0, 0, 0, 0, 0]))
            time.sleep(1.0 / rate_hz)
        done.wait(10.0)
    return rtts


def _router(listen: str, connect: list[str], prefix: list[str]) -> subprocess.Popen:
    cmd = [*prefix, sys.executable, "-m", "agents.cli", "router", "--listen", listen, "--json"]
    for endpoint in connect:
        cmd += ["--connect", endpoint]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if not proc.stdout.readline():
        raise RuntimeError(f"router did not start: {proc.stderr.read()[-300:]}")
    return proc


def measure(topology: str, hints: int, rate_hz: float, netns: tuple[str, str] | None = None) -> dict:
    """Start the routers and ``pong`` for ``topology``, run ``ping`` here (or in a namespace), return stats."""
    procs: list[subprocess.Popen] = []
    ping_prefix: list[str] = []
    try:
        if topology == "peer to peer":
            port = free_port()
            pong_args = ([], [f"tcp/127.0.0.1:{port}"], "peer")
            ping_args = ([f"tcp/127.0.0.1:{port}"], [], "peer")
        elif topology == "one router":
            port = free_port()
            procs.append(_router(f"tcp/127.0.0.1:{port}", [], []))
            pong_args = ping_args = ([f"tcp/127.0.0.1:{port}"], [], "client")
        else:  # two routers, joined; optionally on two namespace hosts
            a, b = (("10.77.0.1", "10.77.0.2") if netns else ("127.0.0.1", "127.0.0.1"))
            pa, pb = (7447, 7447) if netns else (free_port(), free_port())
            ns_a = ["ip", "netns", "exec", netns[0]] if netns else []
            ns_b = ["ip", "netns", "exec", netns[1]] if netns else []
            procs.append(_router(f"tcp/{a}:{pa}", [], ns_a))
            procs.append(_router(f"tcp/{b}:{pb}", [f"tcp/{a}:{pa}"], ns_b))
            pong_args = ([f"tcp/{b}:{pb}"], [], "client")
            ping_args = ([f"tcp/{a}:{pa}"], [], "client")
            pong_prefix, ping_prefix = ns_b, ns_a
        prefix = pong_prefix if topology.startswith("two") else []
        code = (f"from benchmarks.bench_latency import pong; pong({pong_args[0]!r}, {pong_args[1]!r}, "
                f"{pong_args[2]!r})")
        pong_proc = subprocess.Popen([*prefix, sys.executable, "-c", code], cwd=ROOT, stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        procs.append(pong_proc)
        if pong_proc.stdout.readline().strip() != "ready":
            raise RuntimeError(f"pong did not start: {pong_proc.stderr.read()[-300:]}")
        if ping_prefix:
            code = (f"import json; from benchmarks.bench_latency import ping; "
                    f"print(json.dumps(ping({ping_args[0]!r}, {ping_args[1]!r}, {ping_args[2]!r}, {hints}, {rate_hz})))")
            out = subprocess.run([*ping_prefix, sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                                 timeout=hints / rate_hz + 120)
            import json
            rtts = json.loads(out.stdout.strip().splitlines()[-1])
        else:
            rtts = ping(*ping_args, hints, rate_hz)
    finally:
        for proc in procs:
            if proc.stdin:
                proc.stdin.close()
        stop(procs)
    one_way = np.array(rtts) / 2 * 1e3
    return {"topology": topology, "sent": hints, "received": len(rtts),
            "p50_ms": float(np.percentile(one_way, 50)) if len(one_way) else float("nan"),
            "p99_ms": float(np.percentile(one_way, 99)) if len(one_way) else float("nan"),
            "max_ms": float(one_way.max()) if len(one_way) else float("nan")}


def make_namespaces(loss: float) -> tuple[str, str] | str:
    """Two network namespaces joined by a veth pair, ``loss`` of the second's inbound packets dropped; or why not."""
    if os.geteuid() != 0 or shutil.which("ip") is None or shutil.which("iptables") is None:
        return "needs root, ip and iptables"
    a, b = "evoposeA", "evoposeB"
    cmds = [["ip", "netns", "add", a], ["ip", "netns", "add", b],
            ["ip", "link", "add", "veth-evoa", "type", "veth", "peer", "name", "veth-evob"],
            ["ip", "link", "set", "veth-evoa", "netns", a], ["ip", "link", "set", "veth-evob", "netns", b],
            ["ip", "-n", a, "addr", "add", "10.77.0.1/24", "dev", "veth-evoa"],
            ["ip", "-n", b, "addr", "add", "10.77.0.2/24", "dev", "veth-evob"],
            ["ip", "-n", a, "link", "set", "veth-evoa", "up"], ["ip", "-n", b, "link", "set", "veth-evob", "up"],
            ["ip", "-n", a, "link", "set", "lo", "up"], ["ip", "-n", b, "link", "set", "lo", "up"],
            ["ip", "netns", "exec", b, "iptables", "-A", "INPUT", "-i", "veth-evob", "-m", "statistic", "--mode",
             "random", "--probability", f"{loss}", "-j", "DROP"]]
    for cmd in cmds:
        out = subprocess.run(cmd, capture_output=True, text=True)
        if out.returncode != 0:
            drop_namespaces((a, b))
            return f"`{' '.join(cmd)}` failed: {out.stderr.strip()[:120]}"
    return a, b


def drop_namespaces(names: tuple[str, str]) -> None:
    for name in names:
        subprocess.run(["ip", "netns", "del", name], capture_output=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hints", type=int, default=2000)
    parser.add_argument("--rate", type=float, default=200.0, help="Hints per second (the paper: over 100 Hz).")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args()
    rows, notes = [], []
    for topology in ("peer to peer", "one router", "two routers"):
        rows.append(measure(topology, args.hints, args.rate))
        print(rows[-1], flush=True)
    spaces = make_namespaces(0.2)
    if isinstance(spaces, str):
        notes.append(f"Two routers with 20 % loss: not measured ({spaces}).")
    else:
        try:
            rows.append(measure("two routers, two netns hosts, 20 % inbound loss", args.hints, args.rate, spaces))
            print(rows[-1], flush=True)
        finally:
            drop_namespaces(spaces)
    table = md_table(["topology", "hints sent", "echoed", "one-way p50, ms", "one-way p99, ms", "max, ms"],
                     [[r["topology"], r["sent"], r["received"], f"{r['p50_ms']:.3f}", f"{r['p99_ms']:.3f}",
                       f"{r['max_ms']:.2f}"] for r in rows])
    body = "\n".join([
        f"Command: `.venv/bin/python -m benchmarks.bench_latency --hints {args.hints} --rate {args.rate:g}` "
        f"({provenance()}).", "",
        "Ping-pong of 24-byte hints between two vehicle processes over the fleet bus (`FleetBus`, BLOCK congestion "
        "control); one-way latency = half the round trip. Target: p99 <= 1 ms peer to peer on loopback.", "",
        *table, "", *notes])
    write_section(args.out, "Hint latency", body)
    print(args.out)


if __name__ == "__main__":
    main()
