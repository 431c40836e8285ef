"""How well ``time_budget`` holds on problems at the size limits, where one generation is far longer than the budget.

Run from the repository root::

    NUMBA_NUM_THREADS=1 .venv/bin/python -m benchmarks.bench_time_budget [--budget 1]

Random problems (seeded): image points uniform over a 640 x 480 image, model points uniform in a 0.6 m cube, a
search box 3-6 m in front of the camera; sizes up to the problem file's limits (``agents/problem/problem_file.py``:
16384 image points per view, 4096 model points, 32 views). Each is solved with ``SearchOptions(time_budget=B)``
after a small solve has compiled the kernels. Wall time is what the caller waits for (search and verdict); the
ratio to the budget is the overrun. The budget is held inside a generation by evaluating and refining a chunk of
candidates at a time (``evopose/loop.py``); the overrun left is about one candidate's work per phase, and one
evaluation of one pose grows with views x model points.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.report import md_table, provenance, write_section
from evopose import Bounds, Camera, Model, PoseProblem, SearchOptions, View, solve

#: (image points per view, model points, views)
SIZES = ((2048, 512, 1), (16384, 4096, 1), (4096, 1024, 8), (16384, 4096, 32))
DEFAULT_OUT = Path(__file__).resolve().parent / "results" / "time_budget.md"


def random_problem(n_points: int, n_model: int, n_views: int, seed: int = 0) -> PoseProblem:
    rng = np.random.default_rng(seed)
    camera = Camera(fx=800, fy=800, cx=320, cy=240, width=640, height=480)
    views = tuple(View(camera, rng.uniform((0, 0), (640, 480), (n_points, 2))) for _ in range(n_views))
    model = Model(rng.uniform(-0.3, 0.3, (n_model, 3)))
    return PoseProblem(model, views, Bounds.from_dict({"x": (-1, 1), "y": (-1, 1), "z": (3, 6)}))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--budget", type=float, default=1.0, help="time_budget, s")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    solve(random_problem(50, 20, 2), SearchOptions(max_generations=2), seed=0)  # compile the kernels first
    rows = []
    for n_points, n_model, n_views in SIZES:
        problem = random_problem(n_points, n_model, n_views)
        t0 = time.perf_counter()
        solution = solve(problem, SearchOptions(time_budget=args.budget), seed=0)
        wall = time.perf_counter() - t0
        rows.append([n_points, n_model, n_views, f"{wall:.2f}", f"{wall / args.budget:.1f}x", solution.generations,
                     solution.evaluations, solution.stop_reason, "yes" if solution.confident else "no"])
        print(rows[-1], file=sys.stderr, flush=True)
    body = "\n".join([
        f"`NUMBA_NUM_THREADS=1 python -m benchmarks.bench_time_budget --budget {args.budget:g}` ({provenance()}).", "",
        "Random problems up to the problem file's size limits, each solved with `time_budget` = "
        f"{args.budget:g} s; wall time includes the verdict (which may take 10 % more, else the answer is not "
        "confident). Before the budget was held inside a generation, a single generation of the 16384 x 4096 "
        "one-view problem ran for more than 4 minutes (stopped by hand).", "",
        *md_table(["image points / view", "model points", "views", "wall s", "of the budget", "generations",
                   "evaluations", "stop", "confident"], rows)])
    write_section(args.out, "Time budget at the size limits", body)
    print(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
