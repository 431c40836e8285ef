"""Why a frame is wrong: the front-end's points, the information they carry, or the search.

Run from the repository root on rendered datasets (``evopose render``, ``evopose develop --look``)::

    .venv/bin/python -m benchmarks.bench_wrong_frames datasets/looks-paper/*-hable-faded

Each frame's camera images go through the agents' contrast front-end (no pose to look near, as a pair's first
frame: :func:`vision.extract.feature_extractor`, its label gate kept per camera across the frames) and the frame is
solved from scratch with both cameras (eq. 4, weights 1/2; :func:`evopose.solve` with the model file's rules). Each
answer is judged against the truth and against eq. (4) itself (the views' own weights, as the verdict reads them):

* **right**: within 10 cm and 5 deg of the truth (the fleet benchmark's "right"), confident or not;
* **wrong, search**: eq. (4) at the truth, polished where it lies (the solver's own last polish,
  :data:`evopose.solver.POLISH_SCHEDULE`), is lower than at the answer: the points prefer the truth and the search
  did not find it; the search run again with the truth among its starts says whether it then keeps it;
* **wrong, information**: the answer fits at least as well as the truth polished: on these points eq. (1) prefers a
  wrong pose, and no search can help; the front-end's marks say what was missing.

Per dataset: frames of each kind, confident ones and good ones (converged, confident and precise: what an agent
publishes as good), each with those wrong (> 0.5 m or 5 deg), and per camera the
fully visible marks the front-end found (within 1.5 px where marks are under 3 px, else 3 px), its points, the
false ones among them (within that radius of no mark, whole or in part, one to one), and the frames whose labels its
gate kept. Writes ``benchmarks/results/wrong_frames.md``.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

import cv2
import numpy as np

from evopose import PoseObjective, PoseProblem, SearchOptions, View, solve
from evopose.refine import refine
from evopose.solver import POLISH_SCHEDULE
from geometry import pose_error
from scenarios.dataset import open_dataset
from vision.blobs import SMALL_SPOT_PX, mark_prior
from vision.extract import feature_extractor
from vision.features import match_to_truth

from .report import provenance

#: Right: within this position (m) and rotation (deg) of the truth; confidently wrong past 0.5 m or 5 deg.
RIGHT_M, RIGHT_DEG, WRONG_M = 0.10, 5.0, 0.5
#: What the results file says of its columns.
DESCRIPTION = ("Each frame from scratch with both cameras, as a pair's first frame (the agents' front-end, its label "
               "gate kept per camera). *right*: within 10 cm and 5 deg of the truth, confident or not; *wrong, "
               "search*: eq. (4) at the truth, polished there, is lower than at the answer (the points prefer the "
               "truth; in brackets the frames where a search started at the truth keeps it); *wrong, information*: "
               "the answer fits at least as well as the truth polished (eq. (1) on these points prefers a wrong "
               "pose). *good*: converged, confident and precise, what an agent publishes as good; *wrong* there: "
               "> 0.5 m or 5 deg off. Marks: fully visible marks the front-end found (1.5 px under 3 px marks, else "
               "3 px); false points: within that radius of no mark, whole or in part (one to one).")


def _errors(pose: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    error = pose_error(pose, truth)
    return error["position"], max(error[a] for a in ("roll", "pitch", "yaw"))


def frame_rows(directory: Path) -> list[dict]:
    """One row per frame of the dataset in ``directory`` (see the module's docstring)."""
    data = open_dataset(directory)
    world = data.world()
    area = world.bounds()
    extract = feature_extractor("contrast", world.model, area)
    model = world.model.evopose_model()
    options = SearchOptions(confidence=world.model.confidence_rules(1.0 / data.fps))
    rows = []
    for k in range(data.frames):
        views, cameras = [], []
        for name in data.cameras:
            camera = data.camera(name, k)
            points, labels = extract(cv2.imread(str(data.image_path(name, k))), camera)
            views.append(View(camera, points, 1.0 / len(data.cameras), labels))
            marks = data.truth(k).cameras[name].marks
            whole = np.array([m.uv for m in marks if m.fully_visible], float).reshape(-1, 2)
            every = np.array([m.uv for m in marks], float).reshape(-1, 2)
            prior = mark_prior(camera, world.model.mark_radius, world.model.size, area.lo[:3], area.hi[:3])
            radius_px = 1.5 if prior.radius_px[1] < SMALL_SPOT_PX else 3.0
            found = len(match_to_truth(points, whole, radius_px)[0]) if len(points) and len(whole) else 0
            # a point on a mark (seen whole or in part) within the radius, one to one: the rest are false
            on_marks = len(match_to_truth(points, every, radius_px)[0]) if len(points) and len(every) else 0
            cameras.append({"found": found, "visible": len(whole), "points": len(points),
                            "false": len(points) - on_marks, "labelled": labels is not None})
        problem = PoseProblem(model, tuple(views), area)
        truth = data.truth(k).target_pose
        answer = solve(problem, options, seed=k)
        position, rotation = _errors(answer.pose, truth)
        objective = PoseObjective(problem, options.fitness, options.tau)
        at_answer = float(objective(answer.pose[None])[0])
        _, polished = refine(objective, truth[None], None, POLISH_SCHEDULE)
        at_truth = float(polished[0])
        if position <= RIGHT_M and rotation <= RIGHT_DEG:
            kind, kept = "right", None
        elif at_truth < at_answer:
            again = solve(problem, options, seed=k, initial=truth[None])
            kind, kept = "wrong, search", all(e <= b for e, b in zip(_errors(again.pose, truth), (RIGHT_M, RIGHT_DEG)))
        else:
            kind, kept = "wrong, information", None
        rows.append({"dataset": directory.name, "look": data.manifest.look or "camera", "frame": k, "kind": kind,
                     "kept_from_truth": kept, "confident": bool(answer.confident),
                     "confident_wrong": bool(answer.confident and (position > WRONG_M or rotation > RIGHT_DEG)),
                     "good": bool(answer.converged and answer.confident and answer.precise),
                     "position_m": position, "rotation_deg": rotation, "fit_answer": at_answer,
                     "fit_truth": at_truth, "cameras": cameras})
    return rows


def summary_table(rows: list[dict], key: str) -> list[str]:
    """Per ``key`` ("look" or "dataset"): frames of each kind, confident ones, and the front-end's marks."""
    lines = [f"| {key} | frames | right | wrong, search (kept when started at the truth) | wrong, information | "
             "confident (and wrong) | good (and wrong) | marks found / fully visible, per camera | points per camera | "
             "false points of all, per camera | frames with labels, per camera |", "|" + "---|" * 11]
    for name in sorted({r[key] for r in rows}):
        group = [r for r in rows if r[key] == name]
        kinds = Counter(r["kind"] for r in group)
        kept = sum(bool(r["kept_from_truth"]) for r in group)
        n_cameras = len(group[0]["cameras"])
        found = [sum(r["cameras"][c]["found"] for r in group) for c in range(n_cameras)]
        visible = [sum(r["cameras"][c]["visible"] for r in group) for c in range(n_cameras)]
        points = [np.mean([r["cameras"][c]["points"] for r in group]) for c in range(n_cameras)]
        false = [sum(r["cameras"][c]["false"] for r in group) for c in range(n_cameras)]
        every = [sum(r["cameras"][c]["points"] for r in group) for c in range(n_cameras)]
        labelled = [sum(r["cameras"][c]["labelled"] for r in group) for c in range(n_cameras)]
        lines.append(
            f"| {name} | {len(group)} | {kinds['right']} | {kinds['wrong, search']} ({kept}) | "
            f"{kinds['wrong, information']} | {sum(r['confident'] for r in group)} "
            f"({sum(r['confident_wrong'] for r in group)}) | {sum(r['good'] for r in group)} "
            f"({sum(r['good'] and r['confident_wrong'] for r in group)}) | "
            + ", ".join(f"{f}/{v}" for f, v in zip(found, visible)) + " | "
            + ", ".join(f"{p:.1f}" for p in points) + " | " + ", ".join(f"{f}/{n}" for f, n in zip(false, every))
            + " | " + ", ".join(map(str, labelled)) + " |")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("datasets", nargs="+", type=Path, help="rendered dataset directories")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/wrong_frames.md"))
    args = parser.parse_args(argv)
    cv2.setNumThreads(1)
    rows = []
    for directory in args.datasets:
        rows += frame_rows(directory)
        mine = [r for r in rows if r["dataset"] == directory.name]
        print(f"{directory.name}: " + ", ".join(
            f"{r['kind']}{' (confident)' if r['confident'] else ''}{' (good)' if r['good'] else ''} "
            f"{100 * r['position_m']:.0f} cm {r['rotation_deg']:.1f} deg" for r in mine), flush=True)
    command = ".venv/bin/python -m benchmarks.bench_wrong_frames " + " ".join(str(d) for d in args.datasets)
    lines = (["## Why a frame is wrong: the front-end's points, their information, or the search", "",
              f"Produced by `{command}`; {provenance()}.", "", DESCRIPTION, "", "### Per camera look", ""]
             + summary_table(rows, "look") + ["", "### Per dataset", ""] + summary_table(rows, "dataset"))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
