"""Where the label gate's bar is chosen: 2-4 px marks' chroma against how many of their labels are right.

Run from the repository root on paper-scale *training* datasets with raw EXRs (``benchmarks/photoreal_worlds.py
--set train``)::

    .venv/bin/python -m benchmarks.bench_label_chroma datasets/photoreal-train/photoreal-paper-t[1-4]-* --looks 16

Each frame (the first 2 per camera) is developed through random looks (:func:`scenarios.looks.random_look`, seeds
from ``--first-look``, 0 by default), the contrast front-end runs as agents run it (the look estimated, the shipped scorer), and per frame the
median chroma contrast of its detections (:func:`vision.label_chroma.spot_chroma`) is set beside the share of its
matched detections (1.5 px, one to one) whose label is the mark's colour. Reported per look (the median over its
frames, the share right over them), then how a bar on a frame's median splits the frames: what
:data:`vision.label_chroma.MIN_LABEL_CHROMA` was chosen from. Beside it, a second signal weighed and not adopted: the
total-variation distance of a camera's labels, its frames pooled, from the colours of the marks it faces at the true
pose (:func:`label_distance`), and how a bar on it would split the cameras the chroma bar keeps. ``--first-look 16``
takes looks the bars were not chosen on. Writes ``benchmarks/results/label_chroma.md``.
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
#: Bars on a camera's label distance (:func:`label_distance`) weighed beside the chroma bar (1.0: none).
DISTANCE_BARS = (0.2, 0.25, 0.3, 0.35, 0.4, 1.0)


def frames_of(directory: Path, seed: int, frames: int = 2) -> list[tuple[float, int, int, str, list, list, str]]:
    """``(median chroma, matched, right labels, camera, labels' counts, facing colours' counts, dataset)`` per frame of one
    dataset through random look ``seed`` (frames with at least :data:`vision.label_chroma.MIN_SPOTS` detections); the
    counts per palette colour, the facing marks' at the true pose (:func:`facing_colours`, as an agent near a right
    pose would count them)."""
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
    area, body, model = world.bounds(), world.model.body_colour, world.model
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
            facing = facing_colours(dataset.camera(cam, k), np.asarray(dataset.truth(k).target_pose, float), model)
            labels = np.bincount(found.labels, minlength=len(found.names))
            out.append((chroma, len(pairs), int(right), cam, labels.tolist(), facing.tolist(), directory.name))
    return out


def facing_colours(camera, pose: np.ndarray, model) -> np.ndarray:
    """How many of ``model``'s marks (a :class:`scenarios.target.TargetModel`) of each palette colour (C,)
    ``camera`` sees at ``pose`` (``world_from_target`` (6,)): in front of it, facing it, inside the image."""
    from evopose.projection import project_poses

    u, v, usable = project_poses(np.ascontiguousarray(np.asarray(pose, float).reshape(1, 6)),
                                 np.ascontiguousarray(model.mark_points, float),
                                 np.ascontiguousarray(model.mark_normals, float), True, camera.intrinsics,
                                 np.ascontiguousarray(camera.camera_from_world))
    seen = usable[0] & camera.in_image(np.stack([u[0], v[0]], axis=-1))
    return np.bincount(model.colour_labels()[seen], minlength=len(model.palette)).astype(float)


def label_distance(label_counts: np.ndarray, expected_counts: np.ndarray) -> float:
    """Total-variation distance (0 to 1) between the shares of ``label_counts`` (C,) and ``expected_counts`` (C,)
    (0: the labels come in the proportions the marks have)."""
    got, want = np.asarray(label_counts, float), np.asarray(expected_counts, float)
    if got.sum() <= 0 or want.sum() <= 0:
        return 0.0
    return float(0.5 * np.abs(got / got.sum() - want / want.sum()).sum())


def camera_gate(frames: list[tuple]) -> tuple[float, float, int, int]:
    """One camera's frames (of :func:`frames_of`) as a gate would see them: the median of their chroma medians, the
    distance of their labels pooled from the facing colours pooled, and the matched and right labels."""
    return (float(np.median([f[0] for f in frames])),
            label_distance(np.sum([f[4] for f in frames], axis=0), np.sum([f[5] for f in frames], axis=0)),
            sum(f[1] for f in frames), sum(f[2] for f in frames))


def markdown(per_look: dict[int, list[tuple]], command: str) -> str:
    from vision.label_chroma import MIN_LABEL_CHROMA

    lines = ["## The label gate: 2-4 px marks' chroma against their labels (training worlds, random looks)", "",
             f"Produced by `{command}`; {provenance()}.", "", __doc__.split("\n\n")[3].replace("\n", " "), "",
             f"The bar in force: {MIN_LABEL_CHROMA:g} (8-bit Cr Cb units).", "", "### Per look", ""]
    rows = []
    cameras = {seed: [camera_gate([f for f in frames if f[3] == key[0] and f[6] == key[1]])
                      for key in sorted({(f[3], f[6]) for f in frames})] for seed, frames in per_look.items()}
    for seed, frames in sorted(per_look.items(), key=lambda kv: np.median([f[0] for f in kv[1]] or [0])):
        chroma = np.median([f[0] for f in frames]) if frames else float("nan")
        matched, right = sum(f[1] for f in frames), sum(f[2] for f in frames)
        distance = np.median([c[1] for c in cameras[seed]]) if cameras[seed] else float("nan")
        rows.append([f"random-{seed}", len(frames), f"{chroma:.1f}", f"{distance:.2f}", f"{right / max(matched, 1):.2f}"])
    lines += md_table(["look", "frames", "median chroma", "median label distance (per camera)", "labels right"],
                      rows)
    lines += ["", "### A bar on a frame's median chroma", ""]
    every = [f for frames in per_look.values() for f in frames]
    rows = []
    for bar in BARS:
        kept = [f for f in every if f[0] >= bar]
        dropped = [f for f in every if f[0] < bar]
        share = [sum(f[2] for f in s) / max(sum(f[1] for f in s), 1) for s in (kept, dropped)]
        rows.append([f"{bar:g}", len(kept), f"{share[0]:.2f}", len(dropped), f"{share[1]:.2f}"])
    lines += md_table(["bar", "frames kept", "their labels right", "frames untyped", "their labels right"], rows)
    lines += ["", f"### A bar on a camera's label distance (its frames pooled; with the chroma bar {MIN_LABEL_CHROMA:g})",
              ""]
    every_camera = [c for cams in cameras.values() for c in cams]
    rows = []
    for bar in DISTANCE_BARS:
        kept = [c for c in every_camera if c[0] >= MIN_LABEL_CHROMA and c[1] <= bar]
        dropped = [c for c in every_camera if not (c[0] >= MIN_LABEL_CHROMA and c[1] <= bar)]
        by_distance = [c for c in every_camera if c[0] >= MIN_LABEL_CHROMA and c[1] > bar]
        share = [sum(c[3] for c in s) / max(sum(c[2] for c in s), 1) for s in (kept, dropped, by_distance)]
        rows.append([f"{bar:g}", len(kept), f"{share[0]:.2f}", len(dropped), f"{share[1]:.2f}", len(by_distance),
                     f"{share[2]:.2f}" if by_distance else "-"])
    lines += md_table(["bar", "cameras kept", "their labels right", "cameras untyped", "their labels right",
                       "untyped by the distance alone", "their labels right"], rows)
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("datasets", nargs="+", type=Path, help="paper-scale Cycles datasets with raw/*.exr")
    parser.add_argument("--looks", type=int, default=16, help="random looks, seeds FIRST..FIRST+N-1")
    parser.add_argument("--first-look", type=int, default=0, metavar="FIRST",
                        help="the first random look's seed (looks the bars were not chosen on: 16 and up)")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    missing = [str(d) for d in args.datasets if not any((d / c / "raw").is_dir() for c in ("H1", "H2"))]
    if missing:
        parser.error(f"no raw/*.exr (render with the Cycles engine, keep_raw): {', '.join(missing)}")
    seeds = range(args.first_look, args.first_look + args.looks)
    jobs = [(d, seed) for seed in seeds for d in args.datasets]
    per_look: dict[int, list] = {seed: [] for seed in seeds}
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
