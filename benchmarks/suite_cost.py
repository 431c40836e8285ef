"""Where `make test`'s time goes: per test, its wall time, the CPU of the process running it and of the processes it
started and waited for, and what is left (waiting: leads, sleeps, frame clocks).

`make test` must finish in 10 minutes on two cores, and its two passes spend time differently: the first keeps both
workers busy, so its cost is CPU (an interpreter started per test costs ~0.8 CPU-s of imports); the real-time pass
runs one test at a time, so its cost is wall time, and a test that waits holds the whole machine. Run::

    python -m benchmarks.suite_cost [--pass first|realtime|both] [--top 25] [PYTEST ARGS...]

It runs the pass(es) as `make test` does, with this module as a pytest plugin (``-p benchmarks.suite_cost``), and
prints the modules and tests that cost most. As a plugin alone, ``SUITE_COST_DIR`` names the directory each process
(each xdist worker) writes its rows to (``cost-<worker>.json``: ``[node id, wall s, own CPU s, children's CPU s]``).
A child's CPU counts once the test has waited for it (``RUSAGE_CHILDREN``); one still running at the test's end counts
for none.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PASSES = {"first": ["-n", "2", "-m", "not realtime"], "realtime": ["-m", "realtime"]}
_rows: list[tuple[str, float, float, float]] = []


def _cpu() -> tuple[float, float]:
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, children.ru_utime + children.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None):
    """Times one test with its set-up and tear-down."""
    started, (own, children) = time.monotonic(), _cpu()
    yield
    own_after, children_after = _cpu()
    _rows.append((item.nodeid, time.monotonic() - started, own_after - own, children_after - children))


def pytest_sessionfinish(session: pytest.Session) -> None:
    folder = os.environ.get("SUITE_COST_DIR")
    if folder and _rows:
        worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
        (Path(folder) / f"cost-{worker}.json").write_text(json.dumps(_rows), encoding="utf-8")


def run_pass(name: str, extra: list[str]) -> tuple[float, list[tuple[str, float, float, float]]]:
    """One pass of `make test` with this plugin: its wall time (s) and every test's row."""
    with tempfile.TemporaryDirectory() as folder:
        env = {**os.environ, "SUITE_COST_DIR": folder, "EVOPOSE_REQUIRE_AOT": "1"}
        started = time.monotonic()
        subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "benchmarks.suite_cost", "-p", "no:cacheprovider",
                        *PASSES[name], *extra], cwd=ROOT, env=env, check=False)
        wall = time.monotonic() - started
        rows = [tuple(r) for f in sorted(Path(folder).glob("cost-*.json"))
                for r in json.loads(f.read_text(encoding="utf-8"))]
    return wall, rows


def report(name: str, wall: float, rows: list, top: int) -> str:
    """The pass's totals, its costliest modules and tests, and those that waited most (markdown)."""
    wall_sum, own, children = (sum(r[k] for r in rows) for k in (1, 2, 3))
    lines = [f"## {name} pass: {wall:.0f} s wall, {len(rows)} tests", "",
             f"Tests' wall time summed {wall_sum:.0f} s; CPU {own:.0f} s in the test processes, {children:.0f} s in "
             f"the processes they started; waiting {max(wall_sum - own - children, 0):.0f} s.", "",
             "| module | tests | wall s | own CPU s | children's CPU s | waiting s |", "|---|---|---|---|---|---|"]
    modules: dict[str, list[float]] = defaultdict(lambda: [0, 0.0, 0.0, 0.0])
    for node, w, o, c in rows:
        m = modules[node.split("::")[0]]
        m[0] += 1
        m[1] += w
        m[2] += o
        m[3] += c
    for module, (n, w, o, c) in sorted(modules.items(), key=lambda kv: -kv[1][1])[:top]:
        lines.append(f"| {module} | {n} | {w:.1f} | {o:.1f} | {c:.1f} | {max(w - o - c, 0):.1f} |")
    for title, key in (("costliest tests", lambda r: -r[1]), ("tests that waited most", lambda r: r[2] + r[3] - r[1])):
        lines += ["", f"| {title} | wall s | own CPU s | children's CPU s | waiting s |", "|---|---|---|---|---|"]
        for node, w, o, c in sorted(rows, key=key)[:top]:
            lines.append(f"| {node} | {w:.2f} | {o:.2f} | {c:.2f} | {max(w - o - c, 0):.2f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pass", dest="which", choices=("first", "realtime", "both"), default="both")
    parser.add_argument("--top", type=int, default=25, help="rows per table")
    args, extra = parser.parse_known_args(argv)
    for name in (("first", "realtime") if args.which == "both" else (args.which,)):
        wall, rows = run_pass(name, extra)
        print(report(name, wall, rows, args.top))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
