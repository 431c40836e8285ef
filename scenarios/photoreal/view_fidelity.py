"""How close the camera model's Blender tones (3D LUTs, :func:`scenarios.view_luts.view_transform`) come to
Blender itself on a real render (docs/camera-model.md, "Looks")::

    .venv/bin/python -m scenarios.photoreal.view_fidelity datasets/photoreal/photoreal-paper-g1-high/H1/raw/000000.exr

The EXR's radiance is exposed as the default camera model does (auto exposure: the median at 0.18) and clipped at
the sensor's saturation (1.0); Blender (``bake_view_luts.py --develop``, in its own interpreter) saves these levels
through each view transform to an 8-bit PNG, and the LUT path develops the same levels. Prints, per view, the mean
and largest absolute difference in 8-bit levels, and the share of values more than one level apart.
"""

from __future__ import annotations

import argparse
import subprocess
import tempfile
from pathlib import Path

import cv2
import numpy as np

from ..camera_model import CameraModelSpec, expose, exposure_of
from ..view_luts import VIEW_TONES, view_transform
from .exr import read_exr
from .runner import bpy_python

BAKE_SCRIPT = Path(__file__).with_name("bake_view_luts.py")


def compare(exr: Path, tones=VIEW_TONES) -> dict[str, dict[str, float]]:
    radiance = read_exr(exr)
    level = np.clip(expose(radiance, exposure_of(radiance, CameraModelSpec())), 0.0, 1.0)
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        levels = Path(tmp) / "levels.npy"
        np.save(levels, np.ascontiguousarray(level[..., ::-1]))  # Blender is RGB
        for tone in tones:
            png = Path(tmp) / f"{tone}.png"
            subprocess.run([str(bpy_python()), str(BAKE_SCRIPT), "--develop", str(levels), "--view", tone,
                            "--png", str(png)], check=True, capture_output=True)
            blender = cv2.imread(str(png), cv2.IMREAD_COLOR).astype(int)
            ours = view_transform(level, tone).astype(int)
            diff = np.abs(blender - ours)
            results[tone] = {"mean": float(diff.mean()), "max": float(diff.max()),
                             "over_1": float((diff > 1).mean()), "median_level": float(np.median(ours))}
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("exr", type=Path)
    args = parser.parse_args()
    for tone, r in compare(args.exr).items():
        print(f"{tone}: mean {r['mean']:.3f}, max {r['max']:.0f} levels, {100 * r['over_1']:.3f} % more than 1 "
              f"level apart (median output {r['median_level']:.0f})")


if __name__ == "__main__":
    main()
