"""Where the label gate's bar is chosen: 2-4 px marks' chroma against how many of their labels are right.

Run from the repository root on paper-scale *training* datasets with raw EXRs (``benchmarks/photoreal_worlds.py
--set train``)::

    .venv/bin/python -m benchmarks.bench_label_chroma datasets/photoreal-train/photoreal-paper-t[1-4]-* --looks 16

Each frame (the first 2 per camera) is developed through random looks (:func:`scenarios.looks.random_look`, seeds
0..N-1), the contrast front-end runs as agents run it (the look estimated, the shipped scorer), and per frame the
median chroma contrast of its detections (:func:`vision.label_chroma.spot_chroma`) is set beside the share of its
matched detections (1.5 px, one to one) whose label is the mark's colour. Reported per look (the median over its
frames, the share right over them), then how a bar on a frame's median splits the frames: what
:data:`vision.label_chroma.MIN_LABEL_CHROMA` was chosen from. Writes ``benchmarks/results/label_chroma.md``.
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from .report import md_table, provenance

RESULTS = Path(__file__).resolve().parent / "results" / "label_chroma.md"
BARS = (4.0, 5.0, 6.0, 7.0, 8.0)


def frames_of(directory: Path, seed: int, frames: int = 2) -> list[tuple[float, int, int]]:
    """``(median chroma, matched, right labels)`` per frame of one dataset through random look ``seed`` (frames with
    at least :data:`vision.label_chroma.MIN_SPOTS` detections)."""
    import cv2

    from scenarios.dataset import open_dataset
    from scenarios.looks import apply_look, random_look
    from scenarios.photoreal.develop import camera_model_of, develop_exr
    from vision.blobs import detect_contrast_marks, mark_prior
    from vision.camera_look import estimate_look
    from vision.features import match_to_truth
    from vision.label_chroma import MIN_SPOTS, spot_chroma

    cv2.setNumThreads(1)
    dataset = open_dataset(directory)
    world = dataset.world()
    area, body = world.bounds(), world.model.body_colour
    spec = apply_look(camera_model_of(world), random_look(np.random.default_rng(seed)))
    out = []
    for cam in dataset.cameras:
        for k in range(min(frames, dataset.frames)):
            encoded, _ = develop_exr(world, directory / cam / "raw" / f"{k:06d}.exr", k, cam, spec)
            image = cv2.imdecode(np.frombuffer(encoded, np.uint8), cv2.IMREAD_COLOR)
            marks = dataset.truth(k).cameras[cam].marks
            uv = np.array([m.uv for m in marks], float).reshape(-1, 2)
            prior = mark_prior(dataset.camera(cam, k), world.model.mark_radius, world.model.size, area.lo[:3],
                               area.hi[:3])
            look = estimate_look(image, body, prior.extent_px)
            found = detect_contrast_marks(image, world.model.palette, prior, body=body, look=look)
            if len(found.points) < MIN_SPOTS:
                continue
            chroma = float(np.median(spot_chroma(image, found.points, found.radius, look)))
            pairs, _ = match_to_truth(found.points, uv, 1.5)
            right = sum(found.names[found.labels[i]] == marks[j].colour for i, j in pairs)
            out.append((chroma, len(pairs), int(right)))
    return out


def markdown(per_look: dict[int, list[tuple[float, int, int]]], command: str) -> str:
    from vision.label_chroma import MIN_LABEL_CHROMA

    lines = ["## The label gate: 2-4 px marks' chroma against their labels (training worlds, random looks)", "",
             f"Produced by `{command}`; {provenance()}.", "", __doc__.split("\n\n")[3].replace("\n", " "), "",
             f"The bar in force: {MIN_LABEL_CHROMA:g} (8-bit Cr Cb units).", "", "### Per look", ""]
    rows = []
    for seed, frames in sorted(per_look.items(), key=lambda kv: np.median([f[0] for f in kv[1]] or [0])):
        chroma = np.median([f[0] for f in frames]) if frames else float("nan")
        matched, right = sum(f[1] for f in frames), sum(f[2] for f in frames)
        rows.append([f"random-{seed}", len(frames), f"{chroma:.1f}", f"{right / max(matched, 1):.2f}"])
    lines += md_table(["look", "frames", "median chroma", "labels right"], rows)
    lines += ["", "### A bar on a frame's median chroma", ""]
    every = [f for frames in per_look.values() for f in frames]
    rows = []
    for bar in BARS:
        kept = [f for f in every if f[0] >= bar]
        dropped = [f for f in every if f[0] < bar]
        share = [sum(f[2] for f in s) / max(sum(f[1] for f in s), 1) for s in (kept, dropped)]
        rows.append([f"{bar:g}", len(kept), f"{share[0]:.2f}", len(dropped), f"{share[1]:.2f}"])
    lines += md_table(["bar", "frames kept", "their labels right", "frames untyped", "their labels right"], rows)
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("datasets", nargs="+", type=Path, help="paper-scale Cycles datasets with raw/*.exr")
    parser.add_argument("--looks", type=int, default=16, help="random looks, seeds 0..N-1")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    missing = [str(d) for d in args.datasets if not any((d / c / "raw").is_dir() for c in ("H1", "H2"))]
    if missing:
        parser.error(f"no raw/*.exr (render with the Cycles engine, keep_raw): {', '.join(missing)}")
    jobs = [(d, seed) for seed in range(args.looks) for d in args.datasets]
    per_look: dict[int, list] = {seed: [] for seed in range(args.looks)}
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        for (directory, seed), frames in zip(jobs, pool.map(frames_of, *zip(*jobs))):
            per_look[seed] += frames
    command = ".venv/bin/python -m benchmarks.bench_label_chroma " + " ".join(argv if argv is not None else sys.argv[1:])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(markdown(per_look, command), encoding="utf-8")
    print(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
