"""The solver's figures on a fixed problem set, compared with the last committed ones: fails (exit 1) on a drop.

    NUMBA_NUM_THREADS=1 python -m benchmarks.solver_regression [--repeats 3] [--update]

Two seeded groups, the same every run: 40 telephoto marked boxes
(:func:`benchmarks.problems.make_telephoto_box_problem`, issue 35's problems: 20-30 m, f = 2400 px, 1 px noise,
25 % clutter, 10 % missing) and 20 paper-scale Pioneers (:func:`benchmarks.problems.make_paper_scale_problem`,
H1 and H2 in turn). Each problem is solved with its own seed, so success, errors and evaluations are
reproducible, and are compared with ``benchmarks/results/solver_regression.json`` (the figures of the last
``--update``): a group fails when its success count drops, its median rotation or position error (solved problems)
rises more than :data:`ERROR_SLACK`, or its median evaluations rise more than :data:`EVALUATION_SLACK`.

CPU time is not reproducible on a shared machine, so it is measured side by side: the figures' own commit is
checked out in a temporary git worktree (this module and the problem generator copied in), and the suite is
solved there and here in alternate child processes, ``--repeats`` times each. The suite's time (each problem's
least time over the repeats, summed) is compared, not the median problem's (:func:`side_by_side` says why); the
noise is the spread of the repeats' own ratios. A group fails
when it is slower by more than :data:`TIME_SLACK` or the noise, whichever is larger. ``--update`` writes the new
figures (after a change meant to move them) and ``benchmarks/results/solver_regression.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.stats import chi2

from evopose import SearchOptions, solve

from .problems import (SyntheticProblem, in_true_basin, is_success, make_paper_scale_problem,
                       make_telephoto_box_problem, pose_errors)
from .report import ROOT, code_version, md_table, provenance, write_section

FIGURES = Path("benchmarks/results/solver_regression.json")
MARKDOWN = Path("benchmarks/results/solver_regression.md")
#: Seeded results move only when the code does: a rise of 2 % in a median error or 2 % in evaluations is a change.
ERROR_SLACK = 0.02
EVALUATION_SLACK = 0.02
#: Least relative rise of the suite's time (side by side with the reference) that fails, whatever the noise.
TIME_SLACK = 0.10
SEED = 35
#: What the check has caught: shown under the figures.
CAUGHT = ("Run on the code before and at ca5fe80 (the robust last fit; this module copied into both): against "
          "the figures of d65bb6b, ca5fe80 fails with the telephoto boxes' success 30/40 -> 26/40 (problems 1, "
          "8, 21, 26, 33 lost) and median rotation error 2.52 -> 3.10 deg, paper scale 3.25 -> 3.60 deg. With "
          "the fix (few pairs widen the robust fit's cut-off, evopose/robust_fit.py) the boxes are back to "
          "30/40 at 2.97 deg and 2.04 % (2.33 % before ca5fe80); the paper-scale rotation stays at 3.60 deg "
          "(position 0.73 % against 1.33 %): the robust fit's trade on these synthetic problems, not the few-"
          "pairs cut. At 6ae3948 (the judged stop: a confident verdict on a common basin ends the search) "
          "against the figures of 1cccf59: paper scale success 7/20 -> 6/20 (problem 12 lost: judged confident "
          "in the right basin at generation 1, 7.5 deg off, where the search run on finds a floor of the same "
          "basin 12 % lower by generation 9, 3.6 deg off), the suite's time x0.66 (boxes) and x0.64; kept, as "
          "bench_confidence's 420 problems with a target of seeds 7 and 11 each gained one accurate answer "
          "(BENCHMARKS.md, \"When a search may end on a verdict\"), and the figures updated.")


def suite() -> dict[str, list[SyntheticProblem]]:
    """The fixed problem set: group name -> problems."""
    boxes = [make_telephoto_box_problem(np.random.default_rng([SEED, 0, i])) for i in range(40)]
    pioneers = [make_paper_scale_problem(np.random.default_rng([SEED, 1, i]),
                                         cameras=("H1",) if i % 2 == 0 else ("H2",)) for i in range(20)]
    return {"telephoto box (f = 2400 px, 20-30 m)": boxes, "paper scale (Pioneer ~25 px)": pioneers}


def solve_times(groups: dict[str, list[SyntheticProblem]]) -> dict[str, list[float]]:
    """CPU seconds of one solve of each problem, per group (kernels warmed first)."""
    for problems in groups.values():
        solve(problems[0].problem, seed=0)
    out = {}
    for g, problems in groups.items():
        out[g] = []
        for i, sp in enumerate(problems):
            t0 = time.process_time()
            solve(sp.problem, SearchOptions(), seed=i)
            out[g].append(time.process_time() - t0)
    return out


def side_by_side(commit: str, repeats: int, progress=print) -> dict[str, dict]:
    """This code's solve times against ``commit``'s on the same suite, alternating child processes: per group the
    ratio of the suite's total time (each problem's least time over the repeats, summed), and the noise (spread of
    the repeats' own ratios). Not the ratio of the medians: a group's solve times fall in clusters (problems solved
    at once, problems that restart), and a cost of 0.4 ms a problem can move the median problem from one cluster to
    the next (47 to 55 ms on the telephoto boxes) while the suite takes 1.05x as long."""
    tmp = Path(tempfile.mkdtemp(prefix="solver-regression-"))
    tree = tmp / "reference"
    subprocess.run(["git", "worktree", "add", "--detach", str(tree), commit], cwd=ROOT, check=True,
                   capture_output=True)
    try:
        for name in ("solver_regression.py", "problems.py"):  # the same suite and timing in both
            shutil.copy(Path(__file__).with_name(name), tree / "benchmarks" / name)
        times: dict[str, list[dict]] = {"here": [], "reference": []}
        for r in range(repeats):
            for which, where in (("here", ROOT), ("reference", tree)):
                env = dict(os.environ, PYTHONPATH=str(where), NUMBA_NUM_THREADS="1")
                out = subprocess.run([sys.executable, "-m", "benchmarks.solver_regression", "--times-only"],
                                     cwd=where, env=env, capture_output=True, text=True, check=True)
                times[which].append(json.loads(out.stdout.strip().splitlines()[-1]))
            progress(f"side by side with {commit}: repeat {r + 1}/{repeats}")
    finally:
        subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT, capture_output=True)
        shutil.rmtree(tmp, ignore_errors=True)
    result = {}
    for g in times["here"][0]:
        here = np.array([t[g] for t in times["here"]])          # (repeats, problems)
        ref = np.array([t[g] for t in times["reference"]])
        per_repeat = here.sum(axis=1) / ref.sum(axis=1)
        result[g] = {"ratio": float(here.min(axis=0).sum() / ref.min(axis=0).sum()),
                     "noise": float(np.ptp(per_repeat) / np.median(per_repeat)) if repeats > 1 else 0.0,
                     "here_ms": 1000 * float(np.median(here.min(axis=0))),
                     "reference_ms": 1000 * float(np.median(ref.min(axis=0)))}
    return result


#: A confident pose's error is covered by its covariance when its Mahalanobis distance (6 parameters) lies within
#: the region a 6-D Gaussian puts 99.73 % in, as 3 sigma does in one dimension.
COVERED_MAHALANOBIS = float(np.sqrt(chi2.ppf(0.9973, 6)))


def truth_checks(sp: SyntheticProblem, sol) -> tuple[bool, bool, bool]:
    """What the benchmark knows of a solution beyond its success: whether the solvePnP oracle (given the true
    correspondences, :func:`benchmarks.peers.pnp_oracle_views`) succeeds on the problem, whether the pose lies in
    the right basin (:func:`benchmarks.problems.in_true_basin`) and whether its error lies within its covariance
    (:data:`COVERED_MAHALANOBIS`)."""
    from evopose.uncertainty import mahalanobis

    from .bench_confidence import parameter_errors
    from .peers import pnp_oracle_views

    oracle = pnp_oracle_views(sp).pose
    o_rot, o_pos = pose_errors(oracle, sp.true_pose, sp.symmetries, sp.problem.model.points.mean(axis=0))
    covered = float(mahalanobis(parameter_errors(sp, sol.pose), sol.covariance)[0]) <= COVERED_MAHALANOBIS
    return bool(is_success(o_rot, o_pos, sp.distance)), bool(in_true_basin(sp, sol.pose)), covered


def run(repeats: int, progress=print) -> dict:
    """Solve the suite ``repeats`` times; the figures per group (see the module docstring)."""
    groups = suite()
    for problems in groups.values():  # compile and warm the kernels of each kind of problem before timing
        solve(problems[0].problem, seed=0)
    per_group: dict[str, dict] = {g: {"seconds": [[] for _ in problems]} for g, problems in groups.items()}
    for r in range(repeats):
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
                                                       bool(sol.confident), *truth_checks(sp, sol)))
        progress(f"repeat {r + 1}/{repeats}")
    figures = {"code": code_version(), "date": time.strftime("%Y-%m-%d", time.gmtime()), "repeats": repeats,
               "groups": {}}
    for g, out in per_group.items():
        rows = out["rows"]
        ok = [r for r in rows if r[0]]
        seconds = np.array(out["seconds"])  # (problems, repeats)
        per_repeat = np.median(seconds, axis=0)
        confident = [r for r in rows if r[4]]   # r[5:]: oracle success, right basin, within the covariance
        figures["groups"][g] = {
            "problems": len(rows), "success": len(ok),
            "solved": [i for i, r in enumerate(rows) if r[0]],
            "median_rotation_deg": float(np.median([r[1] for r in ok])) if ok else None,
            "median_position_pct": 100 * float(np.median([r[2] for r in ok])) if ok else None,
            "median_evaluations": float(np.median([r[3] for r in rows])),
            # each problem's least time over the repeats (the least disturbed by other work on the machine)
            "median_ms": 1000 * float(np.median(seconds.min(axis=1))),
            "noise": float(np.ptp(per_repeat) / np.median(per_repeat)) if repeats > 1 else 0.0,
            "confident": len(confident), "confident_right": sum(r[0] for r in confident),
            "oracle_success": sum(r[5] for r in rows),
            "confident_right_basin": sum(r[6] for r in confident),
            "confident_covered": sum(r[7] for r in confident),
            "confident_wrong_oracle_right": [i for i, r in enumerate(rows) if r[4] and not r[0] and r[5]],
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
    return failures


def time_failures(times: dict[str, dict]) -> list[str]:
    """Groups slower than the reference, measured side by side, beyond :data:`TIME_SLACK` or the noise."""
    failures = []
    for g, t in times.items():
        slack = max(TIME_SLACK, t["noise"])
        if t["ratio"] > 1 + slack:
            failures.append(f"{g}: the suite's time x{t['ratio']:.2f} side by side (allowed x{1 + slack:.2f}; "
                            f"median {t['here_ms']:.1f} ms against {t['reference_ms']:.1f} ms)")
    return failures


def markdown(figures: dict, before: dict | None) -> str:
    lines = [f"Command: `NUMBA_NUM_THREADS=1 python -m benchmarks.solver_regression --repeats {figures['repeats']} "
             f"--update` ({provenance()}). `make bench-solver` re-runs it without `--update` and fails on a drop "
             "against the committed figures (`benchmarks/results/solver_regression.json`).", "",
             "Success = rotation error < 5° and position error < 5 % of the distance; errors are medians over the "
             "solved problems; time is the median over problems of the least CPU time of a solve over the repeats "
             "(noise = spread of the repeats' medians; `make bench-solver` compares the suite's total time side by "
             "side with the figures' own commit).",
             ""]
    header = ["group", "problems", "success", "confident (right)", "median rot. err (deg)", "median pos. err (%)",
              "median evaluations", "median time (ms)", "noise"]
    rows = []
    for g, f in figures["groups"].items():
        rows.append([g, f["problems"], f["success"], f"{f['confident']} ({f['confident_right']})",
                     f"{f['median_rotation_deg']:.2f}", f"{f['median_position_pct']:.2f}",
                     f"{f['median_evaluations']:.0f}", f"{f['median_ms']:.1f}", f"{100 * f['noise']:.0f} %"])
    lines += md_table(header, rows)
    if all("oracle_success" in f for f in figures["groups"].values()):
        lines += ["", "What a confident answer is measured against (the success bar above is one): the solvePnP oracle "
                  "given the true correspondences on the same problems, the right basin (at least half of the true "
                  "marks identified), and the pose's own covariance (its error within the 99.73 % region of its "
                  f"6-parameter Gaussian, Mahalanobis <= {COVERED_MAHALANOBIS:.2f}). \"confident, not a success, the "
                  "oracle a success\" lists the problems where a confident answer misses what the points allow.", ""]
        rows = [[g, f"{f['oracle_success']}/{f['problems']}", f"{f['confident_right_basin']}/{f['confident']}",
                 f"{f['confident_covered']}/{f['confident']}", f"{f['confident_right']}/{f['confident']}",
                 ", ".join(map(str, f["confident_wrong_oracle_right"])) or "none"]
                for g, f in figures["groups"].items()]
        lines += md_table(["group", "oracle success", "confident: right basin", "confident: within its covariance",
                           "confident: success", "confident, not a success, the oracle a success"], rows)
    if before is not None:
        lines += ["", f"Previous figures: code at {before['code']}, {before['date']}."]
    lines += ["", CAUGHT]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="times the suite is solved (time noise)")
    parser.add_argument("--update", action="store_true", help="write the figures as the new reference")
    parser.add_argument("--figures", type=Path, default=FIGURES)
    parser.add_argument("--times-only", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.times_only:  # a child of side_by_side
        print(json.dumps(solve_times(suite())))
        return 0
    progress = lambda line: print(line, file=sys.stderr, flush=True)  # noqa: E731
    before = json.loads(args.figures.read_text()) if args.figures.exists() else None
    figures = run(args.repeats if args.update else 1, progress=progress)
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
    reference = before["code"].split()[0]
    times = side_by_side(reference, args.repeats, progress)
    for g, t in times.items():
        print(f"{g}: median {t['here_ms']:.1f} ms here, {t['reference_ms']:.1f} ms at {reference}; the suite's "
              f"time x{t['ratio']:.2f} (noise {100 * t['noise']:.0f} %)")
    failures += time_failures(times)
    for line in failures:
        print(f"REGRESSION {line}", file=sys.stderr)
    if not failures:
        print(f"no regression against the figures of {before['code']} ({before['date']})", file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
