"""What numpy's BLAS thread pool costs an agent process: CPU with the pool as numpy starts it, and with one thread.

Run from the repository root (run nothing else; it takes a few seconds per condition)::

    .venv/bin/python -m benchmarks.bench_blas_threads [--seconds 5] [--rate 200] [--rounds 2]

Each condition is its own process that repeats, at an agent's generation rate (``--rate``, the default hint rate),
the numpy call that kept the pool spinning in agents: the covariance's truncated-Gaussian moment
(:func:`evopose.covariance.in_box_second_moment`, 16384 Monte Carlo samples through a ``(16384, 6) @ (6, 6)``
product), then a sleep until the next slot. Reported: the process's CPU (every thread) per second of wall time,
and the CPU of the calls themselves (the calling thread). What is above the calls is the pool's workers:
OpenBLAS keeps them spinning for a while after each split product, which in an agent that computes every few
milliseconds is all the time. ``one BLAS thread`` is what agents do (``agents/vehicle/threads.py``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from .report import md_table, provenance, write_section

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = Path(__file__).resolve().parent / "results" / "blas_threads.md"
CONDITIONS = ("numpy's default pool", "one BLAS thread (agents)")


def work(limited: bool, seconds: float, rate: float) -> None:
    """One condition (run in its own process): the moment at ``rate`` per second for ``seconds``; prints JSON."""
    import numpy as np

    from agents.vehicle.threads import limit_blas_threads
    from evopose.covariance import in_box_second_moment

    if limited:
        limit_blas_threads()
    estimate = np.zeros(6)
    information = np.diag([1e4, 1e4, 1e4, 1e3, 1e3, 1e3])
    lo, hi = np.full(6, -0.005), np.full(6, 1.0)  # a bound within 4 sigma: the Monte Carlo path runs
    periodic = np.zeros(6, bool)
    assert in_box_second_moment(estimate, information, lo, hi, periodic) is not None
    period, calls, call_cpu = 1.0 / rate, 0, 0.0
    start, cpu0 = time.monotonic(), time.process_time()
    next_s = start
    while time.monotonic() - start < seconds:
        t0 = time.thread_time()
        in_box_second_moment(estimate, information, lo, hi, periodic)
        call_cpu += time.thread_time() - t0
        calls += 1
        next_s += period
        time.sleep(max(0.0, next_s - time.monotonic()))
    wall, cpu = time.monotonic() - start, time.process_time() - cpu0
    print(json.dumps({"calls": calls, "wall_s": wall, "cpu_s": cpu, "call_cpu_s": call_cpu}), flush=True)


def measure(condition: str, seconds: float, rate: float) -> dict:
    code = (f"from benchmarks.bench_blas_threads import work; "
            f"work({condition == CONDITIONS[1]}, {seconds}, {rate})")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                          timeout=seconds + 120)
    if done.returncode != 0:
        raise RuntimeError(f"{condition}: {done.stderr[-1500:]}")
    return {"condition": condition, **json.loads(done.stdout.strip().splitlines()[-1])}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--rate", type=float, default=200.0, help="Calls per second (an agent's generation rate).")
    parser.add_argument("--rounds", type=int, default=2, help="Repeat the conditions, interleaved.")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args()
    rows = []
    for _ in range(args.rounds):
        for condition in CONDITIONS:
            row = measure(condition, args.seconds, args.rate)
            rows.append(row)
            print(json.dumps(row), flush=True)
    table = [[r["condition"], f"{r['calls'] / r['wall_s']:.0f}", f"{r['cpu_s'] / r['wall_s']:.2f}",
              f"{r['call_cpu_s'] / r['wall_s']:.2f}", f"{(r['cpu_s'] - r['call_cpu_s']) / r['wall_s']:.2f}"]
             for r in rows]
    header = ["condition", "calls/s", "process CPU, cores", "of which the calls", "the rest (the pool's workers)"]
    body = "\n".join([
        f"Command: `.venv/bin/python -m benchmarks.bench_blas_threads --seconds {args.seconds:g} --rate {args.rate:g} "
        f"--rounds {args.rounds}` ({provenance()}).", "",
        "One process per condition repeats, at an agent's generation rate, the numpy call that kept the pool spinning "
        "in agents: the covariance's truncated-Gaussian moment (16384 Monte Carlo samples, a `(16384, 6) @ (6, 6)` "
        "product), sleeping until the next slot. CPU per second of wall time, every thread of the process, and the "
        "calling thread's share. In the agents the same change took a feature-sharing victim at 10 fps from 1.61-1.67 "
        "cores to 0.54 (Flood, `no flood`; about 0.25 of it is the renderer's own change of the same commit, 51 -> 26 "
        "ms a frame).",
        "", *md_table(header, table)])
    write_section(args.out, "BLAS threads in an agent process", body)
    print(args.out)


if __name__ == "__main__":
    main()
