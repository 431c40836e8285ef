"""Feature front-ends on rendered datasets (docs/datasets.md): recall, precision and labels against the truth.

Run from the repository root on one or more dataset directories (``evopose render WORLD --out DIR``)::

    .venv/bin/python -m benchmarks.bench_photoreal_features datasets/first-paper datasets/first-telephoto

For every camera of every dataset the colour front-ends run on every image: ``marks`` (preset hue bands,
:func:`vision.features.detect_colour_marks`), ``contrast`` (:func:`vision.blobs.detect_contrast_marks`, sized
by :func:`vision.blobs.mark_prior` from the frame's camera and the world's operating area, with the shipped mark
scorer, or ``--scorer FILE``) and ``bars`` (the same without a scorer: the hand-set bars alone; for marks of 3 px
and more the two are one front-end). A detection within the
match radius of a visible mark's projected centre is a true positive (one-to-one, nearest first): 1.5 px when the
marks' largest expected radius is under 3 px (the paper's scale), else 3 px. Recall counts the fully visible marks;
precision every detection; labels the matched detections whose colour is the mark's; position the rms error per
axis of the matched detections against the true projections.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import cv2
import numpy as np

from vision.blobs import SMALL_SPOT_PX, detect_contrast_marks, mark_prior
from vision.features import colour_ranges, detect_colour_marks, match_to_truth
from vision.mark_scorer import MarkScorer
from vision.mark_scorer import load as load_scorer
from scenarios.dataset import open_dataset

from .report import provenance

DEFAULT_OUT = Path(__file__).resolve().parent / "results" / "photoreal_features.md"
FRONT_ENDS = ("marks", "contrast", "bars")
#: Distances (px) from the nearest mark that band the false detections in the pooled line.
FALSE_BANDS_PX = (3.0, 6.0, 10.0)


def evaluate(directory: Path, scorer: str | MarkScorer = "shipped", look: str | None = "auto") -> list[dict]:
    """One row per camera and front-end of the dataset in ``directory``; ``contrast`` with ``scorer``; the contrast
    front-ends with the camera's ``look`` estimated and undone (``"auto"``) or not (None: vision.camera_look)."""
    dataset = open_dataset(directory)
    world = dataset.world()
    area = world.bounds()
    rows = []
    for cam in dataset.cameras:
        acc = {name: np.zeros(5) for name in FRONT_ENDS}
        by_colour = {name: {c: np.zeros(2) for c in world.model.palette} for name in FRONT_ENDS}  # matched, right
        squared = {name: np.zeros(2) for name in FRONT_ENDS}  # sum of squared position errors (px^2), pairs
        false_at = {name: np.zeros(len(FALSE_BANDS_PX) + 1, int) for name in FRONT_ENDS}  # by distance to a mark
        match_px = 3.0
        for k in range(dataset.frames):
            image = cv2.imread(str(dataset.image_path(cam, k)), cv2.IMREAD_COLOR)
            camera = dataset.camera(cam, k)
            marks = dataset.truth(k).cameras[cam].marks
            uv = np.array([m.uv for m in marks], float).reshape(-1, 2)
            whole = np.array([m.fully_visible for m in marks], bool)
            colours = [m.colour for m in marks]
            prior = mark_prior(camera, world.model.mark_radius, world.model.size, area.lo[:3], area.hi[:3])
            match_px = 1.5 if prior.radius_px[1] < SMALL_SPOT_PX else 3.0
            for name in FRONT_ENDS:
                det = (detect_colour_marks(image, colour_ranges(world.model.palette)) if name == "marks"
                       else detect_contrast_marks(image, world.model.palette, prior, body=world.model.body_colour,
                                                  scorer=scorer if name == "contrast" else None, look=look))
                found, _ = match_to_truth(det.points, uv[whole], match_px)
                correct, _ = match_to_truth(det.points, uv, match_px)
                labelled = sum(det.names[det.labels[i]] == colours[j] for i, j in correct)
                matched = {i for i, _ in correct}
                for i in range(len(det.points)):
                    if i not in matched:  # a false detection: how far from the nearest mark (seen or hidden)
                        nearest = float(np.min(np.linalg.norm(uv - det.points[i], axis=1))) if len(uv) else np.inf
                        false_at[name][int(np.searchsorted(FALSE_BANDS_PX, nearest))] += 1
                for i, j in correct:
                    by_colour[name][colours[j]] += [1, det.names[det.labels[i]] == colours[j]]
                    squared[name] += [float(np.sum((det.points[i] - uv[j]) ** 2)), 1]
                acc[name] += [whole.sum(), len(found), len(det), len(correct), labelled]
        for name, a in acc.items():
            rows.append({"dataset": directory.name, "world": dataset.manifest.world, "camera": cam,
                         "engine": dataset.manifest.engine.name, "front_end": name, "frames": dataset.frames,
                         "marks": int(a[0]), "detections": int(a[2]), "match_px": match_px,
                         "recall": a[1] / max(a[0], 1), "precision": a[3] / max(a[2], 1),
                         "labels": a[4] / max(a[3], 1),
                         # of a found mark's position, per axis: how well a true mark is located (the detections
                         # within match px of one; a mislabelled or false point is a matching error, not this)
                         "position_rms_px": float(np.sqrt(squared[name][0] / max(2 * squared[name][1], 1))),
                         "labels_by_colour": {c: (int(n[0]), int(n[1])) for c, n in by_colour[name].items()},
                         "false_at": false_at[name].tolist()})
    return rows


def _by_colour(counts: dict) -> str:
    """``{colour: (matched, labelled right)}`` as "yellow 0.99, cyan 0.68, ..." ("-": none matched)."""
    return ", ".join(f"{c} {f'{right / matched:.2f}' if matched else '-'}" for c, (matched, right) in counts.items())


def pooled_by_colour(rows: list[dict], front_end: str) -> dict:
    """``{colour: (matched, labelled right)}`` summed over the ``rows`` of ``front_end``."""
    out: dict = {}
    for r in rows:
        if r["front_end"] == front_end:
            for c, (matched, right) in r["labels_by_colour"].items():
                m, k = out.get(c, (0, 0))
                out[c] = (m + matched, k + right)
    return out


def _bands(rows: list[dict], front_end: str) -> str:
    """The false detections of ``front_end`` pooled over ``rows``, by distance band: "under 3 px 285, 3-6 px ..."."""
    counts = np.sum([r["false_at"] for r in rows if r["front_end"] == front_end], axis=0)
    edges = ("under", *FALSE_BANDS_PX)
    names = [f"{a:g}-{b:g} px" if a != "under" else f"under {b:g} px" for a, b in zip(edges, FALSE_BANDS_PX)]
    return ", ".join(f"{n} {int(c)}" for n, c in zip([*names, f"over {FALSE_BANDS_PX[-1]:g} px"], counts))


def pooled(rows: list[dict], front_end: str) -> dict:
    """Recall, precision and labels of ``front_end`` over all ``rows`` (every camera and frame counted once):
    found marks over marks, true detections over detections, right labels over true detections."""
    mine = [r for r in rows if r["front_end"] == front_end]
    marks, detections = sum(r["marks"] for r in mine), sum(r["detections"] for r in mine)
    found = sum(r["recall"] * r["marks"] for r in mine)
    correct = sum(r["precision"] * r["detections"] for r in mine)
    right = sum(r["labels"] * r["precision"] * r["detections"] for r in mine)
    return {"recall": found / max(marks, 1), "precision": correct / max(detections, 1),
            "labels": right / max(correct, 1e-9)}


def markdown(rows: list[dict], command: str) -> str:
    lines = ["## Feature front-ends on rendered datasets", "",
             f"Produced by `{command}`; {provenance()}, OpenCV {cv2.__version__}, load average "
             f"{os.getloadavg()[0]:.1f}.", "",
             "Recall over fully visible marks, precision over all detections, labels over matched detections, "
             "and per true colour; position: the rms error per axis of the matched detections against the marks' "
             "true projections (benchmarks/bench_photoreal_features.py says how).", "",
             "| dataset | world | engine | camera | front-end | frames | marks | detections | match px | recall "
             "| precision | labels | position rms px | labels by colour |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['dataset']} | {r['world']} | {r['engine']} | {r['camera']} | {r['front_end']} "
                     f"| {r['frames']} | {r['marks']} | {r['detections']} | {r['match_px']:g} | {r['recall']:.2f} "
                     f"| {r['precision']:.2f} | {r['labels']:.2f} | {r['position_rms_px']:.2f} "
                     f"| {_by_colour(r['labels_by_colour'])} |")
    lines += ["", "Pooled over every camera and frame: " + "; ".join(
        f"{name} recall {p['recall']:.3f}, precision {p['precision']:.3f}, labels {p['labels']:.3f}"
        for name, p in ((name, pooled(rows, name)) for name in FRONT_ENDS)) + "."]
    lines += ["", "False detections by distance to the nearest mark's projection (seen or hidden), pooled: "
              + "; ".join(f"{name}: {_bands(rows, name)}" for name in FRONT_ENDS) + "."]
    lines += ["", "Labels by true colour, pooled: " + "; ".join(
        f"{name}: {_by_colour(pooled_by_colour(rows, name))}" for name in FRONT_ENDS) + "."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("datasets", nargs="+", type=Path, help="dataset directories")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument("--scorer", type=Path, default=None,
                        help="the contrast front-end's mark scorer (JSON of evopose train-scorer; default: shipped)")
    args = parser.parse_args(argv)
    scorer = "shipped" if args.scorer is None else load_scorer(args.scorer)
    cv2.setNumThreads(1)
    rows = []
    for directory in args.datasets:
        rows += evaluate(directory, scorer)
        for r in rows[-2 * len(FRONT_ENDS):]:
            print(f"{r['dataset']:20s} {r['camera']:4s} {r['front_end']:8s} recall {r['recall']:.2f} "
                  f"precision {r['precision']:.2f} labels {r['labels']:.2f}", flush=True)
    argv_text = " ".join(argv if argv is not None else sys.argv[1:])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(markdown(rows, f".venv/bin/python -m benchmarks.bench_photoreal_features {argv_text}"),
                        encoding="utf-8")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
