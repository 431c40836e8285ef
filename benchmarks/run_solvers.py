"""EvoPose against its peers on the same seeded synthetic problems, in one run.

    python -m benchmarks.run_solvers [--per-group 25] [--cma-per-group 4] [--out benchmarks/results/solvers.md]

Every problem is solved, one after the other, by EvoPose, by the OpenCV ``solvePnP``
oracle (true correspondences) and, on the first ``--cma-per-group`` problems of each
group, by IPOP-CMA-ES on the same fitness with an evaluation budget; the machine is
shared and noisy, so ratios between solvers measured side by side are what to quote, and
times are CPU times of the one process.
Success is accuracy: rotation error < 5 deg and position error < 5 % of the distance. The right basin is
scale-free: at least half of the true marks identified one to one (:func:`benchmarks.problems.in_true_basin`);
at the paper's image scale (the Pioneer ~25 px wide) noise alone costs more than 5 deg.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from evopose import SearchOptions, solve

from .peers import cma_solve, pnp_oracle
from .problems import (KINDS, SyntheticProblem, in_true_basin, is_success, make_paper_scale_problem, make_problem,
                       pose_errors)
from .report import md_table, provenance, write_section

#: Problem groups: name -> (kinds, make_problem keyword arguments, problems per kind in units of --per-group).
#: Unset difficulty is drawn at random: distance 5-30 m, noise 0.5-2 px, missing 0-20 %, target 150-350 px wide.
#: "pioneer": :func:`benchmarks.problems.make_paper_scale_problem` (exp2-paper-scale's H1 and H2 in turn,
#: noise 0.5-2 px, clutter 0-30 %, 10 % missing).
GROUPS: dict[str, tuple[tuple[str, ...], dict, int]] = {
    "clutter 0-20 %": (KINDS, {"clutter": None}, 1),
    "clutter 30 %": (KINDS, {"clutter": 0.3}, 1),
    "grid, 150 image points": (("grid",), {"clutter": 0.1, "scene_points": 90}, 1),
    "paper scale (Pioneer ~25 px)": (("pioneer",), {}, 2),
}
CMA_BUDGET = 100_000
#: True marks in the image from which a problem counts as well-posed.
WELL_POSED_MARKS = 8


@dataclass
class Outcome:
    """One solver on one problem."""

    solver: str
    problem: int
    group: str
    kind: str
    success: bool
    right: bool
    rot_deg: float
    pos_m: float
    pos_rel: float
    seconds: float
    evaluations: int
    n_model: int
    n_image: int
    n_true: int


@dataclass
class Run:
    outcomes: list[Outcome] = field(default_factory=list)

    def add(self, solver: str, problem: int, group: str, sp: SyntheticProblem, pose: np.ndarray, seconds: float,
            evaluations: int) -> Outcome:
        rot, pos = pose_errors(pose, sp.true_pose, sp.symmetries, sp.problem.model.points.mean(axis=0))
        out = Outcome(solver, problem, group, sp.kind, is_success(rot, pos, sp.distance), in_true_basin(sp, pose),
                      float(np.rad2deg(rot)), pos,
                      pos / sp.distance, seconds, evaluations, len(sp.problem.model.points),
                      sum(len(v.points) for v in sp.problem.views), min(len(c[0]) for c in sp.correspondences))
        self.outcomes.append(out)
        return out

    def select(self, **match) -> list[Outcome]:
        return [o for o in self.outcomes if all(getattr(o, k) == v for k, v in match.items())]


def problems(per_group: int, seed: int) -> list[tuple[str, int, SyntheticProblem]]:
    """The seeded problem suite: (group, index within its kind, problem)."""
    suite = []
    for g, (name, (kinds, options, factor)) in enumerate(GROUPS.items()):
        for kind in kinds:
            for i in range(per_group * factor):
                if kind == "pioneer":
                    rng = np.random.default_rng([seed, g, len(KINDS), i])
                    suite.append((name, i, make_paper_scale_problem(rng, cameras=("H1",) if i % 2 == 0 else ("H2",))))
                    continue
                rng = np.random.default_rng([seed, g, KINDS.index(kind), i])
                suite.append((name, i, make_problem(kind, rng, **options)))
    return suite


def run(per_group: int, cma_per_group: int, seed: int, progress=print) -> Run:
    result = Run()
    suite = problems(per_group, seed)
    solve(suite[0][2].problem, seed=0)  # compile and warm the kernels before timing
    for n, (group, i, sp) in enumerate(suite):
        t0 = time.process_time()
        sol = solve(sp.problem, SearchOptions(), seed=i)
        ours = result.add("EvoPose", n, group, sp, sol.pose, time.process_time() - t0, sol.evaluations)
        oracle = pnp_oracle(sp)
        result.add("solvePnP oracle", n, group, sp, oracle.pose, oracle.seconds, oracle.evaluations)
        line = f"[{n + 1}/{len(suite)}] {group:24s} {sp.kind:9s} EvoPose {'ok ' if ours.success else 'MISS'} " \
               f"{1000 * ours.seconds:6.0f} ms"
        if i < cma_per_group:
            peer = cma_solve(sp, budget=CMA_BUDGET, seed=i)
            cma_out = result.add("IPOP-CMA-ES", n, group, sp, peer.pose, peer.seconds, peer.evaluations)
            line += f" | CMA {'ok ' if cma_out.success else 'MISS'} {peer.seconds:5.1f} s"
        progress(line)
    return result


def _median(xs: list[float]) -> float:
    return float(np.median(xs)) if xs else float("nan")


def _p95(xs: list[float]) -> float:
    return float(np.percentile(xs, 95)) if xs else float("nan")


def summary_rows(result: Run, solver: str, group: str | None = None, kind: str | None = None) -> list:
    match = {"solver": solver}
    if group:
        match["group"] = group
    if kind:
        match["kind"] = kind
    outs = result.select(**match)
    if not outs:
        return []
    ok = [o for o in outs if o.success]
    return [solver, len(outs), f"{100 * len(ok) / len(outs):.1f} %", f"{100 * np.mean([o.right for o in outs]):.1f} %",
            f"{_median([o.rot_deg for o in ok]):.2f}", f"{100 * _median([o.pos_rel for o in ok]):.2f} %",
            f"{1000 * _median([o.seconds for o in outs]):.1f}", f"{1000 * _p95([o.seconds for o in outs]):.1f}",
            f"{_median([o.evaluations for o in outs]):.0f}"]


HEADER = ["solver", "problems", "success", "right basin", "median rot. err (deg)", "median pos. err (% dist.)",
          "median time (ms)", "p95 time (ms)", "median evaluations"]


def paired_ratios(result: Run) -> list[list]:
    """EvoPose against each peer on the very problems both ran: error and time ratios."""
    ours = {o.problem: o for o in result.select(solver="EvoPose")}
    rows = []
    oracle = [(ours[o.problem], o) for o in result.select(solver="solvePnP oracle")]
    both = [(a, b) for a, b in oracle if a.success and b.success]
    if both:
        for what, attr in (("rotation", "rot_deg"), ("position", "pos_m")):
            ratio = _median([getattr(a, attr) for a, _ in both]) / _median([getattr(b, attr) for _, b in both])
            rows.append([f"EvoPose / oracle, median {what} error", f"{ratio:.2f}",
                         f"{len(both)} problems both solve"])
    cma = [(ours[o.problem], o) for o in result.select(solver="IPOP-CMA-ES")]
    if cma:
        ratio = _median([b.seconds for _, b in cma]) / _median([a.seconds for a, _ in cma])
        rows.append(["IPOP-CMA-ES / EvoPose, median time", f"{ratio:.1f}",
                     f"{len(cma)} problems; success {100 * np.mean([b.success for _, b in cma]):.0f} % (CMA) vs "
                     f"{100 * np.mean([a.success for a, _ in cma]):.0f} % (EvoPose)"])
        ratio = _median([b.evaluations for _, b in cma]) / _median([a.evaluations for a, _ in cma])
        rows.append(["IPOP-CMA-ES / EvoPose, median evaluations", f"{ratio:.1f}", f"{len(cma)} problems"])
    return rows


def markdown(result: Run, args: argparse.Namespace, seconds: float) -> str:
    lines = [f"Command: `python -m benchmarks.run_solvers --per-group {args.per_group} "
             f"--cma-per-group {args.cma_per_group} --seed {args.seed}` "
             f"({provenance()}; {seconds / 60:.1f} min, one process).",
             "",
             "Success = rotation error < 5° and position error < 5 % of the distance (modulo the grid's half-turn "
             "symmetry); right basin = at least half of the true marks identified one to one. Errors are medians "
             "over the problems the solver solves; EvoPose times are CPU times (NUMBA_NUM_THREADS=1: the machine is "
             "shared, wall times there are inflated by other work). IPOP-CMA-ES runs on the same "
             f"fitness, box and image-guided starts with a budget of {CMA_BUDGET:,} evaluations, on the first "
             f"{args.cma_per_group} problems of each group and kind. The oracle is `cv2.solvePnP` (SQPnP, IPPE for the "
             "grid, LM-refined) given the true correspondences, which EvoPose never sees.", ""]
    for group in GROUPS:
        lines.append(f"### {group}")
        lines.append("")
        rows = []
        for solver in ("EvoPose", "IPOP-CMA-ES", "solvePnP oracle"):
            r = summary_rows(result, solver, group)
            if r:
                rows.append(r)
        lines += md_table(HEADER, rows)
        kinds = sorted({o.kind for o in result.select(group=group)})
        if len(kinds) > 1:
            lines.append("")
            lines.append("EvoPose by target:")
            lines.append("")
            lines += md_table(["target"] + HEADER[1:],
                              [[k] + summary_rows(result, "EvoPose", group, k)[1:] for k in kinds])
        lines.append("")
    lines.append("### Well-posed problems")
    lines.append("")
    lines.append(f"Problems where the oracle succeeds and at least {WELL_POSED_MARKS} true marks are in the image "
                 "(with 6 marks, 2 of them false points, no correspondence-free method can be sure):")
    lines.append("")
    oracle_ok = {o.problem for o in result.select(solver="solvePnP oracle") if o.success}
    oracle_right = {o.problem for o in result.select(solver="solvePnP oracle") if o.right}
    rows = []
    for group in GROUPS:
        outs = [o for o in result.select(solver="EvoPose", group=group)
                if o.problem in oracle_ok and o.n_true >= WELL_POSED_MARKS]
        basin = [o for o in result.select(solver="EvoPose", group=group)
                 if o.problem in oracle_right and o.n_true >= WELL_POSED_MARKS]
        if outs or basin:
            rows.append([group, len(outs), f"{100 * np.mean([o.success for o in outs]):.1f} %" if outs else "n/a",
                         len(basin), f"{100 * np.mean([o.right for o in basin]):.1f} %" if basin else "n/a",
                         f"{1000 * _median([o.seconds for o in outs + basin]):.1f}"])
    lines += md_table(["group", "oracle accurate", "EvoPose accurate", "oracle in the right basin",
                       "EvoPose in the right basin", "median CPU time (ms)"], rows)
    lines.append("")
    lines.append("### Side by side")
    lines.append("")
    rows = paired_ratios(result)
    lines += md_table(["ratio", "value", "on"], rows)
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--per-group", type=int, default=25, help="problems per group and target kind")
    parser.add_argument("--cma-per-group", type=int, default=4, help="of which IPOP-CMA-ES also runs this many")
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/solvers.md"))
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    result = run(args.per_group, args.cma_per_group, args.seed,
                 progress=lambda line: print(line, file=sys.stderr, flush=True))
    text = markdown(result, args, time.perf_counter() - t0)
    write_section(args.out, "Solvers: success, accuracy, speed", text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
