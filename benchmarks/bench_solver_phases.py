"""Where a solve's time goes, per phase, on the solver regression set; optionally beside another checkout.

    NUMBA_NUM_THREADS=1 python -m benchmarks.bench_solver_phases [--repeats 3] [--other PATH] [--out FILE]

Phases (CPU time inside each, by wrapping the functions :func:`evopose.solve` calls): *init* (the optimiser's
``ask``: image-guided starts of :mod:`evopose.init`, children), *screen* (coarse fitness of the fresh starts),
*evaluate + refine* (eq. 4 and the Lamarckian refinement of the candidates), *tell* (selection of distinct
basins, the stop rules), *polish* (the best pose's last refinement), *rivals* (the other basins polished for the
verdict), *verdict* (:func:`evopose.uncertainty.assess`), *robust fit + covariance* (the published pose,
:func:`evopose.solver.published`); *other* is the rest of the solve.

``--other PATH`` runs the same measurement on the code at PATH (a git worktree, or a ``git archive`` of a commit
with its compiled kernels, with this module copied in when it predates it) in a child process started there, the
two alternating repeat by repeat on the same problems, so the ratios compare code under the same load. Per group of
the suite it also gives success, confident answers and the median and mean time (when both modules record them).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

PHASES = ("init", "screen", "evaluate + refine", "tell", "polish", "rivals", "verdict", "robust fit + covariance",
          "other")


def _wrap(owner, name: str, phase: str, spent: dict) -> None:
    original = getattr(owner, name)

    def timed(*args, **kwargs):
        t0 = time.process_time()
        try:
            return original(*args, **kwargs)
        finally:
            spent[phase] += time.process_time() - t0

    setattr(owner, name, timed)


def measure(repeats: int) -> dict:
    """Per problem and repeat: seconds per phase, total, evaluations, success (this process's evopose)."""
    import evopose.loop as loop
    import evopose.search as search
    import evopose.solver as solver
    from evopose import SearchOptions, solve

    from .problems import is_success, pose_errors
    from .solver_regression import suite

    spent = {p: 0.0 for p in PHASES}
    _wrap(search.EvoPose, "ask", "init", spent)
    _wrap(search.EvoPose, "tell", "tell", spent)
    _wrap(loop.Evaluator, "screen", "screen", spent)
    _wrap(loop.Evaluator, "until", "evaluate + refine", spent)
    _wrap(solver, "refine", "polish", spent)
    _wrap(solver, "_rivals", "rivals", spent)
    _wrap(solver, "assess", "verdict", spent)
    _wrap(solver, "published", "robust fit + covariance", spent)
    groups = suite()
    problems = [sp for group in groups.values() for sp in group]
    names = [g for g, group in groups.items() for _ in group]
    solve(problems[0].problem, seed=0)
    solve(problems[-1].problem, seed=0)
    rows = []
    for _ in range(repeats):
        for i, sp in enumerate(problems):
            for p in spent:
                spent[p] = 0.0
            t0 = time.process_time()
            sol = solve(sp.problem, SearchOptions(), seed=i % 40)
            total = time.process_time() - t0
            # polish wraps solver.refine, which _rivals also calls: count rivals' refinement once, under rivals
            phases = dict(spent)
            phases["polish"] = max(phases["polish"] - phases["rivals"], 0.0)
            phases["other"] = max(total - sum(v for k, v in phases.items() if k != "other"), 0.0)
            rot, pos = pose_errors(sol.pose, sp.true_pose, sp.symmetries, sp.problem.model.points.mean(axis=0))
            rows.append({"total": total, "phases": phases, "evaluations": int(sol.evaluations),
                         "ok": bool(is_success(rot, pos, sp.distance)), "generations": int(sol.generations),
                         "stop": sol.stop_reason, "group": names[i], "confident": bool(sol.confident)})
    return {"rows": rows, "problems": len(problems)}


def summary(result: dict) -> dict:
    rows = result["rows"]
    n = result["problems"]
    repeats = len(rows) // n
    total = np.array([r["total"] for r in rows]).reshape(repeats, n).min(axis=0)  # least over repeats per problem
    phases = {p: float(np.mean([r["phases"][p] for r in rows])) for p in PHASES}
    share = {p: v / max(sum(phases.values()), 1e-12) for p, v in phases.items()}
    first = rows[:n]
    return {"median_ms": 1000 * float(np.median(total)), "mean_ms": 1000 * float(np.mean(total)),
            "share": share, "evaluations": float(np.median([r["evaluations"] for r in first])),
            "generations": float(np.median([r["generations"] for r in first])),
            "success": sum(r["ok"] for r in first), "problems": n,
            "stops": {s: sum(r["stop"] == s for r in first) for s in sorted({r["stop"] for r in first})}}


def by_group(result: dict) -> dict[str, dict]:
    """Per group of the suite: success, confident (and of those, successes), median and mean of each problem's
    least CPU time over the repeats, median evaluations."""
    rows, n = result["rows"], result["problems"]
    repeats = len(rows) // n
    total = np.array([r["total"] for r in rows]).reshape(repeats, n).min(axis=0)
    out: dict[str, dict] = {}
    for g in dict.fromkeys(r["group"] for r in rows[:n]):
        idx = [i for i, r in enumerate(rows[:n]) if r["group"] == g]
        first = [rows[i] for i in idx]
        out[g] = {"problems": len(idx), "success": sum(r["ok"] for r in first),
                  "confident": sum(r["confident"] for r in first),
                  "confident_right": sum(r["ok"] and r["confident"] for r in first),
                  "median_ms": 1000 * float(np.median(total[idx])), "mean_ms": 1000 * float(np.mean(total[idx])),
                  "evaluations": float(np.median([r["evaluations"] for r in first]))}
    return out


def group_lines(results: dict[str, dict]) -> list[str]:
    """The per-group table (and this / other ratios when there is another checkout); checkouts whose module
    predates the groups are left out."""
    known = {name: by_group(r) for name, r in results.items() if r["rows"] and "group" in r["rows"][0]}
    if not known:
        return []
    lines = ["", "| code | group | success | confident (successes) | median time (ms) | mean time (ms) | "
                 "median evaluations |", "|---|---|---|---|---|---|---|"]
    for name, groups in known.items():
        for g, s in groups.items():
            lines.append(f"| {name} | {g} | {s['success']}/{s['problems']} | {s['confident']} ({s['confident_right']}) "
                         f"| {s['median_ms']:.1f} | {s['mean_ms']:.1f} | {s['evaluations']:.0f} |")
    if "this" in known and "other" in known:
        lines.append("")
        for g, s in known["this"].items():
            o = known["other"][g]
            lines.append(f"{g}, this / other: median time {s['median_ms'] / o['median_ms']:.2f}, mean time "
                         f"{s['mean_ms'] / o['mean_ms']:.2f}, median evaluations "
                         f"{s['evaluations'] / o['evaluations']:.2f}")
    return lines


def _commit(tree: Path) -> str:
    out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=tree, capture_output=True, text=True)
    return out.stdout.strip() or str(tree)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--other", type=Path, help="another checkout to measure alternately (side by side)")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(measure(args.repeats)))
        return 0
    here = Path(__file__).resolve().parents[1]
    trees = {"this": here} | ({"other": args.other.resolve()} if args.other else {})
    results: dict[str, dict] = {k: {"rows": [], "problems": 0} for k in trees}
    for _ in range(args.repeats):  # alternate: the same load for both
        for name, tree in trees.items():
            env = dict(os.environ, PYTHONPATH=str(tree), NUMBA_NUM_THREADS="1")
            out = subprocess.run([sys.executable, "-m", "benchmarks.bench_solver_phases", "--child", "--repeats",
                                  "1"], cwd=tree, env=env, capture_output=True, text=True, check=True)
            r = json.loads(out.stdout.strip().splitlines()[-1])
            results[name]["rows"] += r["rows"]
            results[name]["problems"] = r["problems"]
    sums = {k: summary(v) for k, v in results.items()}
    from .report import provenance, write_section

    lines = [f"Command: `NUMBA_NUM_THREADS=1 python -m benchmarks.bench_solver_phases --repeats {args.repeats}"
             + (f" --other {args.other}" if args.other else "") + f"` ({provenance()}"
             + (f"; other = {_commit(args.other)}" if args.other else "") + ").", "",
             "The solver regression set (40 telephoto boxes, 20 paper-scale Pioneers); time = median (mean) over "
             "problems of each one's least CPU time over the repeats; phase shares of the CPU time summed over all "
             "solves.", ""]
    header = ["code", "success", "median time (ms)", "mean time (ms)", "median evaluations", "median generations",
              "stops"] + [f"{p} (%)" for p in PHASES]
    lines.append("| " + " | ".join(header) + " |")
    lines.append("|" + "---|" * len(header))
    for name, s in sums.items():
        stops = ", ".join(f"{k} {v}" for k, v in s["stops"].items())
        lines.append("| " + " | ".join([name, f"{s['success']}/{s['problems']}", f"{s['median_ms']:.1f}",
                                         f"{s['mean_ms']:.1f}", f"{s['evaluations']:.0f}",
                                         f"{s['generations']:.0f}", stops]
                                        + [f"{100 * s['share'][p]:.1f}" for p in PHASES]) + " |")
    if "other" in sums:
        lines += ["", f"this / other: median time {sums['this']['median_ms'] / sums['other']['median_ms']:.2f}, "
                      f"mean time {sums['this']['mean_ms'] / sums['other']['mean_ms']:.2f}, median evaluations "
                      f"{sums['this']['evaluations'] / sums['other']['evaluations']:.2f}"]
    lines += group_lines(results)
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        write_section(args.out, "Where a solve's time goes: per phase, before and after", text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
