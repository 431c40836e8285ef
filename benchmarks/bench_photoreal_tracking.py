"""Two cameras tracking on rendered datasets, in process: what the verdict's numbers rest on, frame by frame.

Run from the repository root on dataset directories (``evopose render WORLD --out DIR``)::

    .venv/bin/python -m benchmarks.bench_photoreal_tracking datasets/photoreal-long/photoreal-paper-g*

Per dataset both cameras' images go through the contrast front-end, frame 0 is solved from scratch
(:func:`evopose.solve`) and every later frame tracked (eq. 2, :func:`evopose.track`) from the last converged and
confident pose, else solved from scratch again (a vehicle keeps searching beside a pose it is unsure of), as a
vehicle that shares feature sets does, without its time slices, and with the tracking gate's motion allowance of
the dataset's model file (``motion``, per frame at the dataset's rate) as an agent has it. Each estimate is compared
with the truth.
Reported: the frames converged and confident; of those, how many are ``precise`` (good) and how many of the good
are more than 5 deg or 0.5 m off (issue 18's bar); the covariance's worst rotation sigma (1 sigma, deg) against the
rotation error actually made; then what an agent publishes (:class:`evopose.pose_filter.PoseFilter`: the good
frames fused into the track, a frame that jumped off it set aside), its good frames, how many of those are off,
its rotation sigma and error; and the mismatch of the tracked pose (eq. 4's unexplained share), with the number of
frames a fixed 0.5 bound would have called lost (:func:`evopose.solver.tracked_mismatch_bound`). Last, the mutual
pairs of the good frames' published poses checked against the truth: a pair is true when its image point lies
within the match radius of its mark's true projection (1.5 px at the paper's scale, else 3 px, as in
``bench_photoreal_features``); the share of false pairs and the median distance (px) of the true and of the false
pairs from their projected marks (what :mod:`evopose.robust_fit` tells apart). Writes
``benchmarks/results/photoreal_tracking.md``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

from vision.extract import feature_extractor
from evopose import PoseObjective, PoseProblem, SearchOptions, View, pose_mismatch, solve, track
from vision.blobs import SMALL_SPOT_PX, mark_prior
from evopose.covariance import mutual_matches
from evopose.pose_filter import PoseFilter
from evopose.uncertainty import rotation_sigma
from geometry import pose_error
from scenarios.dataset import open_dataset

from .report import documented_table, write_section

RESULTS = Path(__file__).resolve().parent / "results" / "photoreal_tracking.md"
#: A good frame further off than this is confident and wrong (issue 18's bar).
WRONG_M, WRONG_DEG = 0.5, 5.0
#: The fixed tracking bound before tracked_mismatch_bound.
FIXED_BOUND = 0.5


def pair_distances(solution, truths: list[dict[int, np.ndarray]], match_px: list[float]) -> tuple[list, list]:
    """Distances (px) of the true and of the false mutual pairs of ``solution``'s pose from their projected marks:
    ``truths[k]`` view ``k``'s visible marks (index -> true pixel), ``match_px[k]`` its match radius."""
    options = solution.options
    objective = PoseObjective(solution.problem, "mutual" if options.fitness == "paper" else options.fitness,
                              options.tau)
    matches = mutual_matches(objective, solution.pose)
    true, false = [], []
    for view, mark, point, residual in zip(matches.view, matches.model_index, matches.image_index, matches.residuals):
        where = truths[view].get(int(mark))
        seen = solution.problem.views[view].points[point]
        right = where is not None and float(np.linalg.norm(seen - where)) <= match_px[view]
        (true if right else false).append(float(np.linalg.norm(residual)))
    return true, false


def run(directory: Path) -> list[dict]:
    """One row per frame of the dataset in ``directory`` (both cameras, weight 1/2 each)."""
    data = open_dataset(directory)
    world = data.world()
    extract = feature_extractor("contrast", world.model, world.bounds())
    model, previous, rows = world.model.evopose_model(), None, []
    # the tracking gate's motion allowance from the model file's motion, per frame at the dataset's rate
    options = SearchOptions(confidence=world.model.confidence_rules(1.0 / data.fps))
    published = PoseFilter.of_rules(options.confidence)  # what an agent publishes: the track (pose_filter)
    for k in range(data.frames):
        views, truths, match_px = [], [], []
        for name in data.cameras:
            camera = data.camera(name, k)
            points, labels = extract(cv2.imread(str(data.image_path(name, k))), camera)
            views.append(View(camera, points, 1.0 / len(data.cameras), labels))
            truths.append({m.index: np.array(m.uv) for m in data.truth(k).cameras[name].marks})
            prior = mark_prior(camera, world.model.mark_radius, world.model.size, world.bounds().lo[:3],
                               world.bounds().hi[:3])
            match_px.append(1.5 if prior.radius_px[1] < SMALL_SPOT_PX else 3.0)
        problem = PoseProblem(model, tuple(views), world.bounds())
        solution = (solve(problem, options, seed=k) if previous is None
                    else track(previous, views, problem=problem, search_when_lost=False, seed=k))
        previous = solution if solution.converged and solution.confident else None
        truth = data.truth(k).target_pose
        error = pose_error(solution.pose, truth)
        published, out = published.step(k, solution.pose, solution.covariance,
                                         solution.converged and solution.confident and solution.precise)
        track_error = pose_error(out.pose, truth)
        rows.append({"frame": k, "on_track": out.on_track, "settled": out.settled, "track_position_m": track_error["position"],
                     "track_rotation_deg": max(track_error[a] for a in ("roll", "pitch", "yaw")),
                     "track_sigma_rotation_deg": _sigma_rotation_deg(out.covariance),
                     "converged": solution.converged, "confident": solution.confident,
                     "precise": solution.precise, "position_m": error["position"],
                     "rotation_deg": max(error[a] for a in ("roll", "pitch", "yaw")),
                     "sigma_rotation_deg": _sigma_rotation_deg(solution.covariance),
                     "mismatch": pose_mismatch(problem, solution.pose, solution.options),
                     "pairs": pair_distances(solution, truths, match_px), "match_px": min(match_px)})
    return rows


def _sigma_rotation_deg(cov: np.ndarray) -> float:
    """The worst rotation axis's 1-sigma (deg) of a covariance (6, 6); nan when it is not finite."""
    return float(np.degrees(rotation_sigma(cov)))


def summary(name: str, rows: list[dict]) -> list[str]:
    basin = [r for r in rows if r["converged"] and r["confident"]]
    good = [r for r in basin if r["precise"]]
    wrong = [r for r in good if r["position_m"] > WRONG_M or r["rotation_deg"] > WRONG_DEG]
    sigma = [r["sigma_rotation_deg"] for r in basin]
    error = [r["rotation_deg"] for r in basin]
    z = [e / s for e, s in zip(error, sigma) if s > 0]
    mismatch = [r["mismatch"] for r in basin]

    def span(values: list[float], digits: int = 1) -> str:
        return f"{min(values):.{digits}f}-{max(values):.{digits}f}" if values else "-"

    published = [r for r in good if r["on_track"] and r["settled"]]
    published_wrong = [r for r in published if r["track_position_m"] > WRONG_M or r["track_rotation_deg"] > WRONG_DEG]
    published_z = [r["track_rotation_deg"] / r["track_sigma_rotation_deg"] for r in published
                   if r["track_sigma_rotation_deg"] > 0]
    return [name, f"{len(basin)}/{len(rows)}", f"{len(good)}", f"{len(wrong)}", span(sigma), span(error),
            f"{max(z):.1f}" if z else "-", f"{len(published)}", f"{len(published_wrong)}",
            span([r["track_sigma_rotation_deg"] for r in published]),
            span([r["track_rotation_deg"] for r in published]), f"{max(published_z):.1f}" if published_z else "-",
            span(mismatch, 2), f"{sum(m > FIXED_BOUND for m in mismatch)}", *pairs_columns(good)]


def pairs_columns(good: list[dict]) -> list[str]:
    """The false pairs of the ``good`` frames' rows (of all pairs) and the median distance of the true and of the
    false pairs from their marks (px)."""
    true = [d for r in good for d in r["pairs"][0]]
    false = [d for r in good for d in r["pairs"][1]]

    def median(values: list[float]) -> str:
        return f"{np.median(values):.2f}" if values else "-"

    return [f"{len(false)}/{len(true) + len(false)}", f"{median(true)} / {median(false)}"]


HEADER = ["dataset", "converged and confident", "good (precise too)", "good but > 5 deg or 0.5 m off",
          "rotation sigma deg (1 sigma)", "rotation error deg", "largest error / sigma",
          "published: good (on the track)", "published good but off", "published rotation sigma deg",
          "published rotation error deg", "published largest error / sigma", "mismatch",
          "frames a fixed 0.5 would lose", "false pairs of the good frames", "pair distance px, true / false"]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("datasets", nargs="+", type=Path, help="dataset directories (with the target)")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    table, good_by_scale = [], {}
    for directory in args.datasets:
        rows = run(directory)
        table.append(summary(directory.name, rows))
        print(" | ".join(table[-1]), flush=True)
        for r in rows:
            if r["converged"] and r["confident"] and r["precise"]:
                good_by_scale.setdefault(r["match_px"], []).append(r)
    pooled = []
    for px, rows in sorted(good_by_scale.items()):
        false_share, distances = pairs_columns(rows)
        pooled.append(f"match radius {px:g} px: false pairs {false_share}, distance of the true / false pairs "
                      f"{distances} px (median)")
    pooled_line = "Pooled over the good frames, " + "; ".join(pooled) + "."
    print(pooled_line)
    command = "python -m benchmarks.bench_photoreal_tracking " + " ".join(argv if argv is not None else sys.argv[1:])
    write_section(args.out, "Two cameras tracking on rendered datasets (in process)",
                  documented_table(command, __doc__, "Per dataset", HEADER, table) + "\n\n" + pooled_line)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
