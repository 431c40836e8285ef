"""What the reference look makes of a body's paint: the fit behind :func:`vision.camera_look.reference_body_chroma`.

Run from the repository root on datasets as rendered (the reference look: the project's camera model, ``tone:
srgb``), the fit on some and the check on others::

    .venv/bin/python -m benchmarks.bench_reference_chroma --fit datasets/photoreal-bodies/* \\
        datasets/photoreal-train/photoreal-telephoto-* --check datasets/photoreal-bodies-dev/*

A camera's look is measured from the target's body (:func:`vision.camera_look.estimate_look`): the body's chroma
read in the image against what the reference look makes of its paint. Per image of a telephoto dataset (the body
large enough to be read) this takes the body's chroma as the look estimate reads it
(:func:`vision.camera_look.body_reading`) over the model file's paint chroma; one point per paint, the median over
its images. On the fitting datasets ``log(reading) = a + (p - 1) log(c / c_ref)`` is fitted by least squares (``c``
the paint's chroma, ``c_ref`` the reference paint's, :data:`vision.camera_look.REFERENCE_PAINT_CHROMA`), and for
every dataset set the spread (root mean square of the log) of the saturation each paint's reference-look frames
then read, against the reference paint's own reading: with the gain constant over paints (``p`` = 1), with the
shipped power (:data:`vision.camera_look.REFERENCE_CHROMA_POWER`) and with the fitted one. A reading 1 is a paint
read as the reference paint is; the front-end undoes only what lies beyond the dead band (a log of 0.3).
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import cv2
import numpy as np

from .report import md_table, provenance

DEFAULT_OUT = Path(__file__).resolve().parent / "results" / "reference_chroma.md"


def readings(directories: list[Path]) -> dict[tuple[int, int, int], float]:
    """Per body paint (BGR) of the telephoto datasets in ``directories``: the median over its images of the body's
    chroma read in the reference look over the paint's own chroma (images where no body is found left out)."""
    from scenarios.dataset import open_dataset
    from vision.blobs import SMALL_SPOT_PX, mark_prior
    from vision.camera_look import body_reading, chroma_of

    by_paint: dict[tuple[int, int, int], list[float]] = {}
    for directory in directories:
        dataset = open_dataset(directory)
        world = dataset.world()
        area = world.bounds()
        paint = tuple(int(c) for c in world.model.body_colour)
        paint_chroma = float(np.hypot(*chroma_of(np.array(paint, np.uint8))[1]))
        for cam in dataset.cameras:
            for k in range(dataset.frames):
                prior = mark_prior(dataset.camera(cam, k), world.model.mark_radius, world.model.size, area.lo[:3],
                                   area.hi[:3])
                if prior.radius_px[1] < SMALL_SPOT_PX:
                    continue   # the paper's scale: the body's few hundred pixels read its chroma diluted
                image = cv2.imread(str(dataset.image_path(cam, k)), cv2.IMREAD_COLOR)
                _, seen, _ = body_reading(image, paint, prior.extent_px)
                if seen is not None:
                    by_paint.setdefault(paint, []).append(float(np.hypot(*seen)) / paint_chroma)
    return {paint: statistics.median(values) for paint, values in by_paint.items()}


def paint_chroma(paint: tuple[int, int, int]) -> float:
    from vision.camera_look import chroma_of

    return float(np.hypot(*chroma_of(np.array(paint, np.uint8))[1]))


def fit_power(points: dict[tuple[int, int, int], float]) -> float:
    """``p`` of the least-squares line ``log(reading / reading_ref) = (p - 1) log(c / c_ref)`` through the paints'
    points, anchored at the reference paint's reading (as :func:`vision.camera_look.reference_body_chroma` is at
    :data:`vision.camera_look.REFERENCE_BODY_GAIN`); without the reference paint among them, at their median."""
    x, y = _logs(points)
    return float(1.0 + np.dot(x, y) / max(float(np.dot(x, x)), 1e-12))


def spread(points: dict[tuple[int, int, int], float], power: float) -> float:
    """Root mean square of the log saturation the paints' reference-look frames read with ``power``, about the
    reference paint's own reading (the line through it)."""
    x, y = _logs(points)
    return float(np.sqrt(np.mean(np.square(y - (power - 1.0) * x))))


def _logs(points: dict[tuple[int, int, int], float]) -> tuple[np.ndarray, np.ndarray]:
    """``log(c / c_ref)`` and ``log(reading / reading_ref)`` of the paints' points (N,) each."""
    from vision.camera_look import REFERENCE_PAINT_BGR, REFERENCE_PAINT_CHROMA

    base = points.get(REFERENCE_PAINT_BGR, statistics.median(points.values()))
    x = np.log([paint_chroma(p) / REFERENCE_PAINT_CHROMA for p in points])
    return x, np.log(np.array(list(points.values())) / base)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--fit", nargs="+", type=Path, required=True, help="datasets the power is fitted on")
    parser.add_argument("--check", nargs="*", type=Path, default=[], help="datasets it is checked on")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    from vision.camera_look import REFERENCE_CHROMA_POWER

    sets = {"fitted on": readings(args.fit)}
    if args.check:
        sets["checked on"] = readings(args.check)
    fitted = fit_power(sets["fitted on"])
    rows = [[name, len(points), f"{spread(points, 1.0):.3f}", f"{spread(points, REFERENCE_CHROMA_POWER):.3f}",
             f"{spread(points, fitted):.3f}"] for name, points in sets.items()]
    paints = [[name, str(p), f"{paint_chroma(p):.3f}", f"{r:.3f}"]
              for name, points in sets.items() for p, r in sorted(points.items(), key=lambda kv: paint_chroma(kv[0]))]
    command = "python -m benchmarks.bench_reference_chroma " + " ".join(sys.argv[1:] if argv is None else argv)
    lines = ["## What the reference look makes of a body's paint", "",
             f"Command: `{command}` ({provenance()}).", "",
             f"Fitted power {fitted:.2f} (shipped {REFERENCE_CHROMA_POWER:.2f}). Spread of the log saturation each "
             "paint's reference-look frames read, about the reference paint's (root mean square):", "",
             *md_table(["datasets", "paints", "gain constant over paints", "shipped power", "fitted power"], rows), "",
             "Each paint's body chroma read over its file's chroma (median over its telephoto images):", "",
             *md_table(["datasets", "paint (BGR)", "paint chroma", "read / paint"], paints)]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
