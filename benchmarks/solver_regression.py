"""The solver's figures on a fixed problem set, compared with the last committed ones: fails (exit 1) on a drop.

    NUMBA_NUM_THREADS=1 python -m benchmarks.solver_regression [--repeats 3] [--update]

Two seeded groups, the same every run: 40 telephoto marked boxes (:func:`benchmarks.problems.make_telephoto_box_problem`,
issue 35's problems: 20-30 m, f = 2400 px, 1 px noise, 25 % clutter, 10 % missing) and 20 paper-scale Pioneers
(:func:`benchmarks.problems.make_paper_scale_problem`, H1 and H2 in turn). Each problem is solved with its own
seed, so success, errors and evaluations are reproducible; CPU time is not (a shared 2-core machine), so each
repeat of the suite is preceded by a fixed NumPy workload that does not depend on the project's code; the time
compared is the median over problems of each one's least time over the repeats, over the least time of that
workload, and the spread between the repeats' own ratios is the noise measured side by side.

Against ``benchmarks/results/solver_regression.json`` (the figures of the last ``--update``), a group fails when
its success count drops, its median rotation or position error (solved problems) rises more than
:data:`ERROR_SLACK`, its median evaluations rise more than :data:`EVALUATION_SLACK`, or its median normalised
time rises beyond :data:`TIME_SLACK` or the noise, whichever is larger (evaluations are the exact measure of
work; the time is a backstop on a shared machine). ``--update`` writes the new
figures (after a change meant to move them) and ``benchmarks/results/solver_regression.md``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from evopose import SearchOptions, solve

from .problems import (SyntheticProblem, is_success, make_paper_scale_problem, make_telephoto_box_problem,
                       pose_errors)
from .report import code_version, md_table, provenance, write_section

FIGURES = Path("benchmarks/results/solver_regression.json")
MARKDOWN = Path("benchmarks/results/solver_regression.md")
#: Seeded results move only when the code does: a rise of 2 % in a median error or 2 % in evaluations is a change.
ERROR_SLACK = 0.02
EVALUATION_SLACK = 0.02
#: Least relative rise of the normalised median time that fails, whatever the measured noise.
TIME_SLACK = 0.10
SEED = 35
#: What the check has caught: shown under the figures.
CAUGHT = ("Run on the code before and at ca5fe80 (the robust last fit; this module copied into both): against the "
          "figures of d65bb6b, ca5fe80 fails with the telephoto boxes' success 30/40 -> 26/40 (problems 1, 8, 21, 26, "
          "33 lost) and median rotation error 2.52 -> 3.10 deg, paper scale 3.25 -> 3.60 deg. With the fix (few pairs "
          "widen the robust fit's cut-off, evopose/robust_fit.py) the boxes are back to 30/40 at 2.97 deg and 2.04 % "
          "(2.33 % before ca5fe80); the paper-scale rotation stays at 3.60 deg (position 0.73 % against 1.33 %): "
          "the robust fit's trade on these synthetic problems, not the few-pairs cut.")


def suite() -> dict[str, list[SyntheticProblem]]:
    """The fixed problem set: group name -> problems."""
    boxes = [make_telephoto_box_problem(np.random.default_rng([SEED, 0, i])) for i in range(40)]
    pioneers = [make_paper_scale_problem(np.random.default_rng([SEED, 1, i]), cameras=("H1",) if i % 2 == 0 else ("H2",))
                for i in range(20)]
    return {"telephoto box (f = 2400 px, 20-30 m)": boxes, "paper scale (Pioneer ~25 px)": pioneers}


def calibration_seconds() -> float:
    """CPU seconds of a fixed single-threaded NumPy workload (sorts, element-wise maths, small-array calls; no BLAS,
    the project's code not involved)."""
    x = np.random.default_rng(0).standard_normal(20_000)
    small = x[:18]
    t0 = time.process_time()
    for _ in range(400):
        np.sort(x)
        np.exp(np.tanh(x)).sum()
    for _ in range(40_000):
        np.minimum(small, 0.5).argmin()
    return time.process_time() - t0


def run(repeats: int, progress=print) -> dict:
    """Solve the suite ``repeats`` times; the figures per group (see the module docstring)."""
    groups = suite()
    for problems in groups.values():  # compile and warm the kernels of each kind of problem before timing
        solve(problems[0].problem, seed=0)
    per_group: dict[str, dict] = {g: {"seconds": [[] for _ in problems]} for g, problems in groups.items()}
    calibration = []
    for r in range(repeats):
        calibration.append(calibration_seconds())
        for g, problems in groups.items():
            out = per_group[g]
            for i, sp in enumerate(problems):
                t0 = time.process_time()
                sol = solve(sp.problem, SearchOptions(), seed=i)
                out["seconds"][i].append(time.process_time() - t0)
                if r == 0:
                    rot, pos = pose_errors(sol.pose, sp.true_pose, sp.symmetries, sp.problem.model.points.mean(axis=0))
                    out.setdefault("rows", []).append((bool(is_success(rot, pos, sp.distance)), float(np.rad2deg(rot)),
                                                       float(pos / sp.distance), int(sol.evaluations),
                                                       bool(sol.confident)))
        progress(f"repeat {r + 1}/{repeats}: calibration {1000 * calibration[-1]:.0f} ms")
    figures = {"code": code_version(), "date": time.strftime("%Y-%m-%d", time.gmtime()), "repeats": repeats,
               "calibration_ms": 1000 * float(np.median(calibration)), "groups": {}}
    for g, out in per_group.items():
        rows = out["rows"]
        ok = [r for r in rows if r[0]]
        seconds = np.array(out["seconds"])  # (problems, repeats)
        normalised = np.median(seconds, axis=0) / np.array(calibration)  # per repeat: its noise
        confident = [r for r in rows if r[4]]
        figures["groups"][g] = {
            "problems": len(rows), "success": len(ok),
            "solved": [i for i, r in enumerate(rows) if r[0]],
            "median_rotation_deg": float(np.median([r[1] for r in ok])) if ok else None,
            "median_position_pct": 100 * float(np.median([r[2] for r in ok])) if ok else None,
            "median_evaluations": float(np.median([r[3] for r in rows])),
            # each problem's least time over the repeats (the least disturbed by other work on the machine)
            "median_ms": 1000 * float(np.median(seconds.min(axis=1))),
            "median_normalised": float(np.median(seconds.min(axis=1)) / min(calibration)),
            "noise": float(np.ptp(normalised) / np.median(normalised)) if repeats > 1 else 0.0,
            "confident": len(confident), "confident_right": sum(r[0] for r in confident),
        }
    return figures


def compare(now: dict, before: dict) -> list[str]:
    """What got worse from ``before`` to ``now`` (empty: nothing)."""
    failures = []
    for g, b in before["groups"].items():
        n = now["groups"].get(g)
        if n is None:
            failures.append(f"{g}: group missing")
            continue
        if n["success"] < b["success"]:
            lost = sorted(set(b["solved"]) - set(n["solved"]))
            failures.append(f"{g}: success {n['success']}/{n['problems']} < {b['success']}/{b['problems']} "
                            f"(lost problems {lost})")
        for key in ("median_rotation_deg", "median_position_pct"):
            if b[key] is not None and n[key] is not None and n[key] > b[key] * (1 + ERROR_SLACK):
                failures.append(f"{g}: {key} {n[key]:.3f} > {b[key]:.3f}")
        if n["median_evaluations"] > b["median_evaluations"] * (1 + EVALUATION_SLACK):
            failures.append(f"{g}: median evaluations {n['median_evaluations']:.0f} > {b['median_evaluations']:.0f}")
        slack = max(TIME_SLACK, n["noise"], b["noise"])
        if n["median_normalised"] > b["median_normalised"] * (1 + slack):
            failures.append(f"{g}: median time {n['median_normalised']:.2f} > {b['median_normalised']:.2f} "
                            f"calibrations (+{100 * (n['median_normalised'] / b['median_normalised'] - 1):.0f} %, "
                            f"allowed +{100 * slack:.0f} %)")
    return failures


def markdown(figures: dict, before: dict | None) -> str:
    lines = [f"Command: `NUMBA_NUM_THREADS=1 python -m benchmarks.solver_regression --repeats {figures['repeats']} "
             f"--update` ({provenance()}). `make bench-solver` re-runs it without `--update` and fails on a drop "
             "against the committed figures (`benchmarks/results/solver_regression.json`).", "",
             "Success = rotation error < 5° and position error < 5 % of the distance; errors are medians over the "
             "solved problems; time is the median over problems of the least CPU time of a solve over the repeats (and in "
             "units of a fixed NumPy workload timed before each repeat, which is what is compared; noise = spread of "
             "the repeats' median ratios).",
             ""]
    header = ["group", "problems", "success", "confident (right)", "median rot. err (deg)", "median pos. err (%)",
              "median evaluations", "median time (ms)", "time / calibration", "noise"]
    rows = []
    for g, f in figures["groups"].items():
        rows.append([g, f["problems"], f["success"], f"{f['confident']} ({f['confident_right']})",
                     f"{f['median_rotation_deg']:.2f}", f"{f['median_position_pct']:.2f}",
                     f"{f['median_evaluations']:.0f}", f"{f['median_ms']:.1f}", f"{f['median_normalised']:.2f}",
                     f"{100 * f['noise']:.0f} %"])
    lines += md_table(header, rows)
    if before is not None:
        lines += ["", f"Previous figures: code at {before['code']}, {before['date']}."]
    lines += ["", CAUGHT]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="times the suite is solved (time noise)")
    parser.add_argument("--update", action="store_true", help="write the figures as the new reference")
    parser.add_argument("--figures", type=Path, default=FIGURES)
    args = parser.parse_args(argv)
    before = json.loads(args.figures.read_text()) if args.figures.exists() else None
    figures = run(args.repeats, progress=lambda line: print(line, file=sys.stderr, flush=True))
    print(markdown(figures, before))
    if args.update:
        args.figures.write_text(json.dumps(figures, indent=1) + "\n")
        write_section(MARKDOWN, "Solver regression check: a fixed problem set against the committed figures",
                      markdown(figures, before))
        return 0
    if before is None:
        print(f"no committed figures at {args.figures}: run with --update", file=sys.stderr)
        return 1
    failures = compare(figures, before)
    for line in failures:
        print(f"REGRESSION {line}", file=sys.stderr)
    if not failures:
        print(f"no regression against the figures of {before['code']} ({before['date']})", file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
