"""What the encoder costs: the same Cycles radiance developed through three encoders, front-end and pose compared.

Run from the repository root on Cycles datasets kept with their radiance (``raw/``, docs/datasets.md)::

    .venv/bin/python -m benchmarks.bench_photoreal_encoding datasets/photoreal/photoreal-paper-g*

Each dataset's ``raw/*.exr`` (the engine's linear radiance before the camera model) is developed again by its
world's camera model, seeded as the renderer seeds it (the 4:2:0 images come out byte for byte as rendered), with
the encoder's chroma at 4:2:0 (what cameras stream), at 4:4:4, and lossless (PNG), into a temporary copy of the
dataset. On each copy: the contrast front-end's recall, precision and labels, pooled over cameras and frames
(:func:`benchmarks.bench_photoreal_features.evaluate`), and the two cameras tracking in process
(:func:`benchmarks.bench_photoreal_tracking.run`): frames good, and good but more than 5 deg or 0.5 m off. Only
the encoder differs between the rows: the scene, the light, the sensor's noise and the exposure are the same.
Writes ``benchmarks/results/photoreal_encoding.md``.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

from scenarios.photoreal.develop import develop_exr
from scenarios.dataset import open_dataset
from scenarios.photoreal.develop import camera_model_of

from . import bench_photoreal_features, bench_photoreal_tracking
from .report import documented_table, write_section

RESULTS = Path(__file__).resolve().parent / "results" / "photoreal_encoding.md"
#: Encoder variants: name -> the camera model's fields replaced (None: the world's own, 4:2:0 JPEG).
ENCODERS = {"JPEG 4:2:0 (as rendered)": {}, "JPEG 4:4:4": {"chroma": "444"}, "lossless PNG": {"jpeg_quality": None}}


def redevelop(source: Path, out: Path, changes: dict) -> Path:
    """A copy of the dataset ``source`` in ``out`` (its files, each camera's calibration and poses) whose images are
    its ``raw/`` radiance developed again with the world's camera model, ``changes`` applied to it."""
    dataset = open_dataset(source)
    world = dataset.world()
    spec = camera_model_of(world).model_copy(update=changes)
    out.mkdir(parents=True)
    for entry in source.iterdir():
        if entry.is_file():
            shutil.copy(entry, out / entry.name)
    for camera in dataset.cameras:
        (out / camera).mkdir()
        for entry in (source / camera).iterdir():
            if entry.is_file() and entry.suffix in (".yaml", ".jsonl"):
                shutil.copy(entry, out / camera / entry.name)
        for k in range(dataset.frames):
            exr = source / camera / "raw" / f"{k:06d}.exr"
            if not exr.is_file():
                raise SystemExit(f"{exr}: missing; this benchmark needs the datasets' radiance (render with raw/ kept)")
            encoded, suffix = develop_exr(world, exr, k, camera, spec)
            (out / camera / f"{k:06d}{suffix}").write_bytes(encoded)
    return out


def measure(directories: list[Path]) -> dict:
    """Pooled front-end numbers (:func:`benchmarks.bench_photoreal_features.pooled`) and tracking counts over
    ``directories`` (one encoder's copies)."""
    rows, good, wrong, frames = [], 0, 0, 0
    for directory in directories:
        rows += bench_photoreal_features.evaluate(directory)
        tracked = bench_photoreal_tracking.run(directory)
        summary = bench_photoreal_tracking.summary(directory.name, tracked)
        good, wrong, frames = good + int(summary[2]), wrong + int(summary[3]), frames + len(tracked)
    return {**bench_photoreal_features.pooled(rows, "contrast"), "good": good, "wrong": wrong, "frames": frames}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("datasets", nargs="+", type=Path, help="Cycles dataset directories with raw/")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    table = []
    with tempfile.TemporaryDirectory(prefix="evopose-encoding-") as tmp:
        for i, (name, changes) in enumerate(ENCODERS.items()):
            copies = [redevelop(d, Path(tmp) / str(i) / d.name, changes) for d in args.datasets]
            m = measure(copies)
            table.append([name, f"{m['recall']:.2f}", f"{m['precision']:.2f}", f"{m['labels']:.2f}",
                          f"{m['good']}/{m['frames']}", f"{m['wrong']}"])
            print(" | ".join(table[-1]), flush=True)
    command = ("python -m benchmarks.bench_photoreal_encoding "
               + " ".join(argv if argv is not None else sys.argv[1:]))
    header = ["encoder", "recall", "precision", "labels right", "two cameras tracking: good frames",
              "good but > 5 deg or 0.5 m off"]
    write_section(args.out, "What the encoder costs (the same Cycles radiance, three encoders)",
                  documented_table(command, __doc__, "Each dataset", header, table))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
