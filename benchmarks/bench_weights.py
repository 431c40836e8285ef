"""Eq. (4)'s view weights (issue 13): equal vs the paper's step rule vs adaptive, healthy cameras vs one degraded.

    NUMBA_NUM_THREADS=1 python -m benchmarks.bench_weights [--frames 16] [--jobs 1] [--out benchmarks/results/weights.md]

Offline, with the pure estimator (no Zenoh): for each world pair (the paper's image scale: ``exp2-paper-scale`` and
``exp2-paper-scale-degraded``; telephoto: ``exp2`` and ``exp2-degraded``) it renders the same seeded frames of H1 and
H2, extracts the marks with the model's palette (what the agents do), and solves eq. (4) over both views
(``W = 1/2`` each, as the agents pass them) with ``SearchOptions(view_weights=...)`` for each rule, with the same
search seed per frame. The degraded world differs from the healthy one only in H2's camera
(:mod:`scenarios.degrade`: heavy blur, a band over 35 % of the robot, 6 more distractors); H1's frames are the same.

A third group is harder than the two worlds (whose robot stands still): the synthetic paper-scale problems of
``bench_confidence`` (the Pioneer anywhere in a 3 m square with any heading, seen by exp2-paper-scale's H1 and H2,
0.5-2 px noise, 0-30 % clutter, 10 % missing marks; ``--seed``), healthy, and with H2's view degraded alike
(:func:`degrade_view`: 35 % of its marks gone, 1.5 px more noise, 6 more false points near the robot).

Per rule and condition: position and rotation errors (medians, and the share within 5 deg and 5 % of the distance:
"accurate"), the right-basin rate (at least half of the visible true marks identified one to one,
:func:`benchmarks.problems.in_true_basin`), the share called confident and the precision of confident (right
basin among the confident), and H2's final weight over H1's.
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from functools import lru_cache
from pathlib import Path

import numpy as np

from .report import md_table, provenance, write_section

#: scale -> (healthy world, world with H2 degraded); "synthetic" names seeded problems, not worlds
WORLDS = {"paper scale (Pioneer ~25 px)": ("exp2-paper-scale", "exp2-paper-scale-degraded"),
          "telephoto (Pioneer ~180 px)": ("exp2", "exp2-degraded"),
          "synthetic paper scale (random poses, noise, clutter)": ("synthetic", "synthetic-degraded")}
#: Seeds of the synthetic problems (``bench_confidence``'s "paper H1+H2" group; 7 is its reporting seed).
SYNTHETIC_SEED = 7
RULES = ("equal", "step", "adaptive")
CAMERAS = ("H1", "H2")
DEFAULT_OUT = Path(__file__).resolve().parent / "results" / "weights.md"


@lru_cache(maxsize=4)
def _world(name: str):
    from vision.features import colour_ranges
    from scenarios.world import load_scenario

    scenario = load_scenario(name)
    return scenario, colour_ranges(scenario.model.palette)


@lru_cache(maxsize=64)
def frame_problem(world: str, frame: int):
    """The seeded two-view problem of ``frame`` in ``world`` with its truth (a :class:`SyntheticProblem`)."""
    from evopose import PoseProblem, View
    from vision.features import detect_colour_marks
    from scenarios.render import render_frame

    from .problems import SyntheticProblem

    scenario, ranges = _world(world)
    views, correspondences, distances = [], [], []
    for cam in CAMERAS:
        rendered = render_frame(scenario, frame, cam)
        points = detect_colour_marks(rendered.image, ranges).points
        if len(points) == 0:
            points = np.array([[rendered.camera.cx, rendered.camera.cy]])  # nothing seen: one stray point
        views.append(View(rendered.camera, points, 1.0 / len(CAMERAS)))
        correspondences.append((rendered.truth.mark_index, rendered.truth.mark_uv))
        distances.append(float(np.linalg.norm(rendered.camera.center_world - scenario.target_pose(frame)[:3])))
    problem = PoseProblem(scenario.model.evopose_model(), tuple(views), scenario.bounds())
    return SyntheticProblem("pioneer", problem, scenario.target_pose(frame), correspondences, [np.eye(3)],
                            float(np.mean(distances)), float("nan"), float("nan"), 0.0,
                            {"world": world, "points": [len(v.points) for v in views]})


def degrade_view(sp, k: int, rng: np.random.Generator):
    """``sp`` with view ``k`` degraded: 35 % of its true marks removed, 1.5 px more noise on the rest, 6 false points
    near the target (the synthetic counterpart of :mod:`scenarios.degrade`)."""
    from evopose import View

    from .problems import SyntheticProblem

    model_idx, pts = sp.correspondences[k]
    view = sp.problem.views[k]
    is_true = np.array([np.min(np.linalg.norm(pts - p, axis=1)) < 1e-9 if len(pts) else False for p in view.points])
    gone = rng.random(len(pts)) < 0.35
    kept = pts[~gone] + rng.normal(0, 1.5, (int(np.count_nonzero(~gone)), 2))
    lo, hi = pts.min(axis=0) - 15, pts.max(axis=0) + 15
    points = np.concatenate([kept, view.points[~is_true], rng.uniform(lo, hi, (6, 2))])
    views = list(sp.problem.views)
    views[k] = View(view.camera, points, view.weight)
    correspondences = list(sp.correspondences)
    correspondences[k] = (model_idx[~gone], kept)
    return SyntheticProblem(sp.kind, sp.problem.with_views(views), sp.true_pose, correspondences, sp.symmetries,
                            sp.distance, sp.noise, sp.clutter, sp.missing, {**sp.meta, "points": [len(v.points) for v in views]})


@lru_cache(maxsize=64)
def synthetic_problem(name: str, index: int):
    """Problem ``index`` of ``bench_confidence``'s "paper H1+H2" group (weights 1/2), degraded in H2 when asked."""
    from evopose import View

    from .bench_confidence import make

    sp = make("paper H1+H2", SYNTHETIC_SEED, index)
    views = [View(v.camera, v.points, 1.0 / len(sp.problem.views)) for v in sp.problem.views]
    sp.problem = sp.problem.with_views(views)
    sp.meta = {**sp.meta, "points": [len(v.points) for v in views]}
    if name == "synthetic-degraded":
        return degrade_view(sp, 1, np.random.default_rng([SYNTHETIC_SEED, 13, index]))
    return sp


def one(task: tuple[str, str, int, str]) -> dict:
    """Solve one frame of one world with one rule; what the benchmark needs of it."""
    from evopose import SearchOptions, solve

    from .problems import in_true_basin, is_success, pose_errors

    scale, world, frame, rule = task
    sp = synthetic_problem(world, frame) if world.startswith("synthetic") else frame_problem(world, frame)
    t0 = time.process_time()
    sol = solve(sp.problem, SearchOptions(view_weights=rule), seed=frame)
    seconds = time.process_time() - t0
    rot, pos = pose_errors(sol.pose, sp.true_pose, sp.symmetries, sp.problem.model.points.mean(axis=0))
    w = np.asarray(sol.view_weights, float)
    return {"scale": scale, "world": world, "degraded": "degraded" in world, "frame": frame, "rule": rule,
            "rot_deg": float(np.rad2deg(rot)), "pos_m": float(pos), "right": bool(in_true_basin(sp, sol.pose)),
            "accurate": bool(is_success(rot, pos, sp.distance)), "confident": bool(sol.confident),
            "w_ratio": float(w[1] / w[0]) if w[0] > 0 else float("inf"), "seconds": seconds,
            "points": sp.meta["points"]}


def tasks(frames: int, synthetic: int) -> list[tuple[str, str, int, str]]:
    picks = sorted(set(np.linspace(0, 49, frames).round().astype(int).tolist()))
    return [(scale, world, f, rule) for scale, pair in WORLDS.items() for world in pair
            for f in (range(synthetic) if world.startswith("synthetic") else picks) for rule in RULES]


def _pct(num: int, den: int) -> str:
    return f"{100 * num / den:.0f} % ({num}/{den})" if den else "n/a"


def rows_of(records: list[dict]) -> list[list]:
    rows = []
    for scale in WORLDS:
        for degraded in (False, True):
            for rule in RULES:
                recs = [r for r in records if r["scale"] == scale and r["degraded"] == degraded and r["rule"] == rule]
                if not recs:
                    continue
                conf = [r for r in recs if r["confident"]]
                ratios = [r["w_ratio"] for r in recs]
                rows.append([scale.split(" (")[0], "H2 degraded" if degraded else "healthy", rule, len(recs),
                             f"{100 * np.median([r['pos_m'] for r in recs]):.1f}",
                             f"{np.median([r['rot_deg'] for r in recs]):.1f}",
                             _pct(sum(r["accurate"] for r in recs), len(recs)),
                             _pct(sum(r["right"] for r in recs), len(recs)),
                             _pct(len(conf), len(recs)), _pct(sum(r["right"] for r in conf), len(conf)),
                             f"{np.median(ratios):.2f} ({np.min(ratios):.2f}-{np.max(ratios):.2f})",
                             f"{1000 * np.median([r['seconds'] for r in recs]):.0f}"])
    return rows


HEADER = ["scale", "cameras", "weights", "frames (problems)", "median pos. err (cm)", "median rot. err (deg)",
          "accurate", "right basin", "confident", "precision of confident", "W_H2 / W_H1 median (range)",
          "median CPU ms"]


def markdown(records: list[dict], command: str, minutes: float, jobs: int) -> str:
    frames = len({r["frame"] for r in records if not r["world"].startswith("synthetic")})
    problems = len({r["frame"] for r in records if r["world"].startswith("synthetic")})
    points = {}
    for r in records:
        points.setdefault(r["world"], []).append(r["points"])
    seen = "; ".join(f"`{w}` H1 {np.mean([p[0] for p in ps]):.1f}, H2 {np.mean([p[1] for p in ps]):.1f}"
                     for w, ps in points.items())
    lines = [f"Command: `{command}` ({provenance()}; {minutes:.1f} min, {jobs} process(es); CPU times per solve on a "
             "shared machine).", "",
             f"{frames} seeded frames per world and {problems} synthetic problems per condition (the same frames, "
             "problems and search seeds for every rule); H1 and H2 each "
             "give eq. (4) one view of weight 1/2. The degraded worlds differ from the healthy ones only in H2's "
             "camera: heavy blur, a band over 35 % of the robot, 6 more distractor blobs (`scenarios/degrade.py`). "
             f"Image points per frame (mean): {seen}.", "",
             "Rules (`SearchOptions.view_weights`, `evopose/weights.py`): `equal` keeps W = 1/2 each; `step` is the "
             "paper's step rule (a view whose term exceeds 0.8 tau gets 0); `adaptive`: during the search the step "
             "rule only for views matching < 5 marks one to one, then at the best pose each view's weight scaled by "
             "its reliability (share of its image points matched one to one x its matched marks' Gauss-Newton "
             "information over the camera's nominal one) relative to the most reliable view, bounded to [1/4, 1], "
             "and the final polish refines the pose under those weights. Accurate = rotation < 5 deg and position < 5 % of the distance; right basin = at "
             "least half of the visible true marks identified one to one; precision of confident = right basin "
             "among the confident.", ""]
    lines += md_table(HEADER, rows_of(records))
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, default=16, help="seeded frames per world (spread over its 50)")
    parser.add_argument("--synthetic", type=int, default=30, help="synthetic problems per condition")
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument("--only", choices=["paper", "telephoto", "synthetic"], default=None, help="one scale only (a quick look)")
    args = parser.parse_args(argv)
    todo = tasks(args.frames, args.synthetic)
    if args.only:
        todo = [t for t in todo if t[0].startswith(args.only)]
    command = "NUMBA_NUM_THREADS=1 python -m benchmarks.bench_weights " + " ".join(argv if argv is not None
                                                                                   else sys.argv[1:])
    t0 = time.perf_counter()
    records = []
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        for n, rec in enumerate(pool.map(one, todo, chunksize=3)):
            records.append(rec)
            print(f"[{n + 1}/{len(todo)}] {rec['world']:26s} f{rec['frame']:02d} {rec['rule']:8s} "
                  f"{'right' if rec['right'] else 'WRONG':5s} pos {100 * rec['pos_m']:6.1f} cm rot {rec['rot_deg']:5.1f} "
                  f"w2/w1 {rec['w_ratio']:.2f} conf={rec['confident']!s:5s} {1000 * rec['seconds']:5.0f} ms", flush=True)
    minutes = (time.perf_counter() - t0) / 60
    body = markdown(records, command.strip(), minutes, args.jobs)
    print(body)
    write_section(args.out, "Eq. (4) view weights: equal, step, adaptive; healthy and one degraded camera", body)
    return 0


if __name__ == "__main__":
    sys.exit(main())
