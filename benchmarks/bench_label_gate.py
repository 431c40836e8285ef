"""The label gate along sequences: which cameras' labels the agents send, and how right the sent labels are.

Run from the repository root on paper-scale Cycles datasets (their images as the camera gave them)::

    .venv/bin/python -m benchmarks.bench_label_gate datasets/photoreal-long/photoreal-paper-g2-low \
        datasets/looks-long/paper-g2-*

Each camera's frames go in order through the agents' contrast extractor (:func:`vision.extract.feature_extractor`:
the look tracked, the window near a pose, the label gate of :mod:`vision.label_chroma` deciding per frame whether
the camera's labels are sent), each frame near the true pose (a track that is right). The sent points are matched to
the visible true marks (1.5 px, one to one) and their labels compared with the marks' colours; the label distance is
that of the sent labels' proportions from the colours of the marks the camera faces, its frames pooled
(:func:`benchmarks.bench_label_chroma.label_distance`). A label is worth sending only when it is right: a wrong label
is wrong the same way on every frame and pulls the pose toward the twin it agrees with (:mod:`vision.label_chroma`).
The gate's bar was chosen on the training worlds through random looks, where the frames it keeps label 0.74 of their
marks right (BENCHMARKS.md, "The label gate"); here it is judged on the benchmark's sequences, which it never saw.
Writes ``benchmarks/results/label_gate.md``.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from .report import md_table, provenance, write_section

RESULTS = Path(__file__).resolve().parent / "results" / "label_gate.md"
#: Matching radius of a sent point to a true mark at the paper's scale (pixels), as benchmarks/bench_photoreal_looks.
MATCH_PX = 1.5


def camera_rows(directory: Path) -> list[dict]:
    """One row per camera of the dataset at ``directory``: frames, frames whose labels were sent, points matched on
    those frames, how many of their labels are right, and the wrong ones by (true colour, sent label)."""
    import cv2

    from scenarios.dataset import open_dataset
    from vision.extract import feature_extractor
    from vision.features import match_to_truth

    from .bench_label_chroma import facing_colours, label_distance

    cv2.setNumThreads(1)
    dataset = open_dataset(directory)
    world = dataset.world()
    names = list(world.model.palette)
    rows = []
    for cam in dataset.cameras:
        extract = feature_extractor("contrast", world.model, world.bounds())   # one camera's own trackers
        sent = matched = right = 0
        wrong: Counter[tuple[str, str]] = Counter()
        label_counts, facing_counts = np.zeros(len(names)), np.zeros(len(names))
        for k in range(dataset.frames):
            image = cv2.imread(str(dataset.image_path(cam, k)), cv2.IMREAD_COLOR)
            truth = dataset.truth(k)
            points, labels = extract(image, dataset.camera(cam, k), np.asarray(truth.target_pose, float))
            if labels is None:
                continue
            sent += 1
            label_counts += np.bincount(labels, minlength=len(names))
            facing_counts += facing_colours(dataset.camera(cam, k), np.asarray(truth.target_pose, float), world.model)
            marks = truth.cameras[cam].marks
            uv = np.array([m.uv for m in marks], float).reshape(-1, 2)
            pairs, _ = match_to_truth(points, uv, MATCH_PX)
            matched += len(pairs)
            for i, j in pairs:
                if names[labels[i]] == marks[j].colour:
                    right += 1
                else:
                    wrong[(marks[j].colour, names[labels[i]])] += 1
        rows.append({"dataset": directory.name, "look": dataset.manifest.look or "camera", "camera": cam,
                     "frames": dataset.frames, "sent": sent, "matched": matched, "right": right, "wrong": dict(wrong),
                     "distance": label_distance(label_counts, facing_counts) if sent else None})
    return rows


def markdown(rows: list[dict], command: str) -> str:
    table = [[r["dataset"], r["look"], r["camera"], f"{r['sent']}/{r['frames']}",
              f"{r['right'] / r['matched']:.2f} ({r['right']}/{r['matched']})" if r["matched"] else "-",
              ", ".join(f"{true} as {label} {n}" for (true, label), n in
                        sorted(r["wrong"].items(), key=lambda kv: -kv[1])[:2]) or "-",
              "-" if r["distance"] is None else f"{r['distance']:.2f}"]
             for r in rows]
    sent = [r for r in rows if r["sent"]]
    pooled = sum(r["right"] for r in sent) / max(sum(r["matched"] for r in sent), 1)
    worst = min(sent, key=lambda r: r["right"] / max(r["matched"], 1), default=None)
    lines = [f"Produced by `{command}`; {provenance()}.", "", __doc__.split("\n\n")[3].replace("\n", " "), "",
             *md_table(["dataset", "look", "camera", "frames with labels sent", "sent labels right",
                        "most frequent wrong labels", "label distance"], table), "",
             f"Sent labels right, pooled: {pooled:.2f}."]
    if worst is not None:
        lines.append(f"Worst camera: {worst['dataset']} {worst['camera']}, "
                     f"{worst['right'] / max(worst['matched'], 1):.2f}.")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("datasets", nargs="+", type=Path, help="paper-scale Cycles datasets")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    missing = [str(d) for d in args.datasets if not (d / "manifest.yaml").is_file()]
    if missing:
        parser.error(f"not a dataset (no manifest.yaml): {', '.join(missing)}")
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        rows = [row for found in pool.map(camera_rows, args.datasets) for row in found]
    command = ".venv/bin/python -m benchmarks.bench_label_gate " + " ".join(argv if argv is not None else sys.argv[1:])
    write_section(args.out, "The label gate along sequences: the labels the agents send, against the truth",
                  markdown(rows, command))
    print(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
