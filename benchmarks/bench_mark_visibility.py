"""How much of each mark a camera look leaves in the image, and the front-end's recall by it (issue 32).

Run from the repository root on Cycles datasets that kept their radiance (``raw/*.exr``; docs/datasets.md)::

    .venv/bin/python -m benchmarks.bench_mark_visibility datasets/photoreal/photoreal-telephoto-g* --frames 3

Recall over every fully visible mark mixes two things: what the front-end misses, and what the look took away (a
face blown past white, a dark face at a stop and a half under, a 1 px blur over a 3 px mark, JPEG at 50). Each frame
is developed through each look as in ``benchmarks/bench_photoreal_looks.py`` and the front-end runs as the agents run
it (:func:`vision.blobs.detect_contrast_marks`, the look estimated and undone); each fully visible mark is then
measured in the developed image itself, from the truth alone (:func:`mark_contrast`): its disc's outline projected
with the frame's target pose, the mean colour of the pixels inside it against the median of a ring around it (the
pixels of every mark in view left out), as the CIE 1976 colour difference (Delta E*ab, in L*a*b* of the sRGB image).
Marks are counted in bins of that difference and the front-end's recall is given per bin: about 2.3 is a just
noticeable difference beside a large patch (Sharma, *Digital Color Imaging Handbook*, 2003), more for a few pixels in
texture and noise. The measure knows nothing of the front-end; a mark under the first bin's bound shows the look
left next to nothing to find, and recall over the marks above a bound says what the front-end does with what the
image holds. Matching as the looks benchmark: within 1.5 px at the paper's scale, 3 px at telephoto, one to one.
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import cv2
import numpy as np

from .bench_photoreal_looks import _scale_of, add_dataset_arguments, chosen_looks, look_of
from .report import provenance

DEFAULT_OUT = Path(__file__).resolve().parent / "results" / "mark_visibility.md"
#: Bounds of the Delta E*ab bins (the first: under a just noticeable difference, ~2.3).
BINS = (2.3, 5.0, 10.0, 20.0)
#: The ring around a mark: from this many pixels outside its outline ...
RING_GAP_PX = 1.0
#: ... this wide, or the mark's radius in pixels where that is wider.
RING_WIDTH_PX = 2.0


def mark_masks(outlines_px: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Each mark's pixels, bool (M, H, W): the pixels whose centres lie inside its projected outline
    ``outlines_px`` (M, P, 2) (u, v; a disc's outline is convex), or, for a mark smaller than that, the pixel
    nearest its outline's centre."""
    h, w = shape
    masks = np.zeros((len(outlines_px), h, w), bool)
    for m, outline in enumerate(np.asarray(outlines_px, float)):
        (u0, v0), (u1, v1) = np.floor(outline.min(axis=0)).astype(int), np.ceil(outline.max(axis=0)).astype(int)
        u0, v0, u1, v1 = max(u0, 0), max(v0, 0), min(u1, w - 1), min(v1, h - 1)
        if u0 <= u1 and v0 <= v1:
            vv, uu = np.mgrid[v0:v1 + 1, u0:u1 + 1]
            edge = np.roll(outline, -1, axis=0) - outline                                  # (P, 2)
            side = (edge[:, None, None, 0] * (vv[None] - outline[:, None, None, 1])
                    - edge[:, None, None, 1] * (uu[None] - outline[:, None, None, 0]))       # (P, h, w)
            masks[m, v0:v1 + 1, u0:u1 + 1] = (side >= 0).all(axis=0) | (side <= 0).all(axis=0)
        if not masks[m].any():
            u, v = np.clip(np.rint(outline.mean(axis=0)).astype(int), 0, [w - 1, h - 1])
            masks[m, v, u] = True
    return masks


def mark_contrast(image_bgr: np.ndarray, outlines_px: np.ndarray) -> np.ndarray:
    """Delta E*ab (M,) between each mark's mean colour and the median colour of a ring around it, in
    ``image_bgr`` (H, W, 3) uint8 sRGB; ``outlines_px`` (M, P, 2) the marks' projected outlines (u, v). The ring:
    from :data:`RING_GAP_PX` outside the outline, :data:`RING_WIDTH_PX` or the mark's radius wide, without any
    mark's pixels. NaN where a mark has no ring pixel in the image."""
    lab = cv2.cvtColor(image_bgr.astype(np.float32) / 255.0, cv2.COLOR_BGR2Lab)
    masks = mark_masks(np.asarray(outlines_px, float), image_bgr.shape[:2])
    any_mark = masks.any(axis=0)
    out = np.full(len(masks), np.nan)
    for m, mask in enumerate(masks):
        radius = np.sqrt(mask.sum() / np.pi)
        reach = RING_GAP_PX + max(RING_WIDTH_PX, radius)
        outside = cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, 5)
        ring = (outside > RING_GAP_PX) & (outside <= reach) & ~any_mark
        if not ring.any():
            continue
        out[m] = float(np.linalg.norm(lab[mask].mean(axis=0) - np.median(lab[ring], axis=0)))
    return out


def outlines_in(dataset, cam: str, k: int, index: np.ndarray) -> np.ndarray:
    """The projected disc outlines (M, P, 2) of the model's marks ``index`` (M,) in camera ``cam`` at frame ``k``."""
    from geometry import matrix_from_pose
    from scenarios.render import mark_outlines

    model = dataset.world().model
    pose = matrix_from_pose(dataset.truth(k).target_pose)
    centres = model.mark_points[index] @ pose[:3, :3].T + pose[:3, 3]
    normals = model.mark_normals[index] @ pose[:3, :3].T
    outline = mark_outlines(centres, normals, model.mark_radius)                     # (M, P, 3) world
    uv, _ = dataset.camera(cam, k).project_world(outline.reshape(-1, 3))
    return np.asarray(uv, float).reshape(len(index), -1, 2)


def evaluate(directory: Path, look: str, frames: int | None = None) -> dict:
    """Per fully visible mark of ``directory`` developed through ``look`` (its first ``frames`` frames): its
    Delta E*ab and whether the front-end found it; with the dataset's model and scale."""
    from scenarios.dataset import open_dataset
    from scenarios.photoreal.develop import camera_model_of, develop_exr
    from vision.blobs import SMALL_SPOT_PX, detect_contrast_marks, mark_prior
    from vision.features import match_to_truth

    cv2.setNumThreads(1)
    dataset = open_dataset(directory)
    world = dataset.world()
    area = world.bounds()
    spec = look_of(camera_model_of(world), look)
    contrast, found = [], []
    for cam in dataset.cameras:
        for k in range(dataset.frames if frames is None else min(frames, dataset.frames)):
            encoded, _ = develop_exr(world, Path(directory) / cam / "raw" / f"{k:06d}.exr", k, cam, spec)
            image = cv2.imdecode(np.frombuffer(encoded, np.uint8), cv2.IMREAD_COLOR)
            seen = dataset.truth(k).cameras[cam].marks          # every mark whose centre the camera sees
            whole = np.array([m.fully_visible for m in seen], bool)
            if not whole.any():
                continue
            uv = np.array([m.uv for m in seen], float)[whole]
            prior = mark_prior(dataset.camera(cam, k), world.model.mark_radius, world.model.size, area.lo[:3],
                               area.hi[:3])
            det = detect_contrast_marks(image, world.model.palette, prior, body=world.model.body_colour)
            pairs, _ = match_to_truth(det.points, uv, 1.5 if prior.radius_px[1] < SMALL_SPOT_PX else 3.0)
            hit = np.zeros(len(uv), bool)
            hit[[j for _, j in pairs]] = True
            outlines = outlines_in(dataset, cam, k, np.array([m.index for m in seen]))
            contrast += mark_contrast(image, outlines)[whole].tolist()   # the others' pixels kept out of each ring
            found += hit.tolist()
    return {"dataset": directory.name, "model": world.model.name, "scale": _scale_of(dataset.manifest.world),
            "look": look, "contrast": contrast, "found": found}


def bin_rows(contrast: np.ndarray, found: np.ndarray) -> list[str]:
    """Per bin of :data:`BINS`: ``"marks (recall)"``."""
    edges = (-np.inf, *BINS, np.inf)
    cells = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        at = (contrast >= lo) & (contrast < hi)
        cells.append(f"{at.sum()} ({found[at].mean():.2f})" if at.any() else "0")
    return cells


def markdown(rows: list[dict], command: str, looks: list[str]) -> str:
    heads = [f"< {BINS[0]:g}"] + [f"{a:g}-{b:g}" for a, b in zip(BINS[:-1], BINS[1:])] + [f">= {BINS[-1]:g}"]
    lines = ["## How much of each mark a look leaves, and recall by it", "",
             f"Produced by `{command}`; {provenance()}, OpenCV {cv2.__version__}.", "",
             __doc__.split("\n\n")[3].replace("\n", " "), "",
             "Per look: the fully visible marks, the front-end's recall over all of them, the marks in each bin of "
             "Delta E*ab with the recall in it, and the recall over the marks of Delta E*ab 5 and more, and 10 and "
             "more.", ""]
    for model, scale in sorted({(r["model"], r["scale"]) for r in rows}):
        lines += [f"### {model}, {scale} scale", "",
                  "| look | marks | recall | " + " | ".join(f"dE {h}" for h in heads) + " | recall, dE >= 5 | "
                  "recall, dE >= 10 |", "|---|" + "---|" * (len(heads) + 4)]
        for look in looks:
            mine = [r for r in rows if (r["model"], r["scale"], r["look"]) == (model, scale, look)]
            if not mine:
                continue
            contrast = np.nan_to_num(np.concatenate([r["contrast"] for r in mine]), nan=-1.0)
            found = np.concatenate([r["found"] for r in mine]).astype(bool)
            over = [f"{found[contrast >= b].mean():.3f} ({(contrast >= b).sum()})" if (contrast >= b).any() else "-"
                    for b in (5.0, 10.0)]
            lines.append(f"| {look} | {len(found)} | {found.mean():.3f} | " + " | ".join(bin_rows(contrast, found))
                         + " | " + " | ".join(over) + " |")
        lines.append("")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    add_dataset_arguments(parser, DEFAULT_OUT)
    parser.add_argument("--pool-models", default=None, metavar="NAME",
                        help="report every target model under this one name (datasets of many robots, one each)")
    args = parser.parse_args(argv)
    looks = chosen_looks(parser, args)
    jobs = [(d, lk) for lk in looks for d in args.datasets]
    rows = []
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        for row in pool.map(evaluate, *zip(*jobs), [args.frames] * len(jobs)):
            if args.pool_models:
                row["model"] = args.pool_models
            rows.append(row)
            print(f"{row['dataset']:40s} {row['look']:12s} {len(row['found'])} marks", flush=True)
    command = ".venv/bin/python -m benchmarks.bench_mark_visibility " + " ".join(argv if argv is not None
                                                                                  else sys.argv[1:])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(markdown(rows, command, looks), encoding="utf-8")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
