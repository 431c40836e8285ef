"""The image-only path (``evopose solve --image I --model M --camera C``): no search box given, one camera.

Run from the repository root::

    NUMBA_NUM_THREADS=1 .venv/bin/python -m benchmarks.bench_image_only [--frames 10]

For each helicopter of exp2 (telephoto: the Pioneer ~180 px wide) and of exp2-paper-scale (the paper's
scale: ~25 px, with the world's clutter, blur and noise), every frame is rendered, its marks are found with
the model's palette (what ``solve --image`` does) and the pose is searched in the box
:func:`vision.images.frustum_bounds` derives from the camera and the model's size. Side by side, on
the same frames and seeds, the box of the first version: its depth from the full spread of every detected
point (clutter included). Right = rotation error < 5 deg and position error < 5 % of the range
(``benchmarks.problems.is_success``); confident precision = right among those marked confident.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from vision.images import detect_marks, frustum_bounds
from benchmarks.problems import is_success, pose_errors
from benchmarks.report import md_table, provenance, write_section
from evopose import Bounds, Camera, Model, PoseProblem, SearchOptions, View, solve
from scenarios.render import render_frame
from scenarios.world import load_scenario

WORLDS = ("exp2", "exp2-paper-scale")
VEHICLES = ("H1", "H2")
DEFAULT_OUT = Path(__file__).resolve().parent / "results" / "image_only.md"


def full_spread_box(camera: Camera, model: Model, points: np.ndarray) -> Bounds:
    """The first version's box, the peer: depth from the largest extent of all points, the whole view laterally."""
    spread = float(np.max(np.ptp(points, axis=0))) if len(points) > 1 else 0.0
    depth = 0.5 * (camera.fx + camera.fy) * 2 * model.radius / max(spread, 1.0)
    corners = np.array([[(u - camera.cx) / camera.fx * z, (v - camera.cy) / camera.fy * z, z]
                        for z in (0.5 * depth, 2.0 * depth) for u in (0.0, camera.width) for v in (0.0, camera.height)])
    world = corners @ camera.world_from_camera[:3, :3].T + camera.world_from_camera[:3, 3]
    lo, hi = world.min(axis=0) - 2 * model.radius, world.max(axis=0) + 2 * model.radius
    return Bounds.from_dict({n: (float(lo[i]), float(hi[i])) for i, n in enumerate("xyz")})


BOXES = {"model size, robust (now)": frustum_bounds, "full spread (before)": full_spread_box}


def run(frames: int) -> list[list]:
    rows = []
    for world in WORLDS:
        scenario = load_scenario(world)
        model = scenario.model.evopose_model()
        centroid = model.points.mean(axis=0)
        for vehicle in VEHICLES:
            tally = {name: {"right": 0, "confident": 0, "confident_right": 0, "n": 0} for name in BOXES}
            for k in range(min(frames, scenario.frames)):
                frame = render_frame(scenario, k, vehicle)
                points = detect_marks(frame.image, scenario.model.palette).points
                truth = frame.truth.target_pose
                distance = float(np.linalg.norm(truth[:3] - frame.truth.camera_pose[:3]))
                for name, box in BOXES.items():
                    t = tally[name]
                    t["n"] += 1
                    if len(points) < 3:
                        continue
                    problem = PoseProblem(model, (View(frame.camera, points),), box(frame.camera, model, points))
                    sol = solve(problem, SearchOptions(), seed=k)
                    rot, pos = pose_errors(np.asarray(sol.pose), truth, [np.eye(3)], centroid)
                    right = is_success(rot, pos, distance)
                    t["right"] += right
                    t["confident"] += bool(sol.confident)
                    t["confident_right"] += bool(sol.confident) and right
                print(world, vehicle, k, {n: tally[n]["right"] for n in BOXES}, file=sys.stderr, flush=True)
            for name, t in tally.items():
                precision = f"{t['confident_right']}/{t['confident']}" if t["confident"] else "-"
                rows.append([world, vehicle, name, t["n"], f"{t['right']}/{t['n']}", f"{t['confident']}/{t['n']}",
                             precision])
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, default=10, help="frames per helicopter and world")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    rows = run(args.frames)
    body = "\n".join([
        f"`NUMBA_NUM_THREADS=1 python -m benchmarks.bench_image_only --frames {args.frames}` ({provenance()}).", "",
        "One camera, no search box given: the box comes from the camera and the model's size "
        "(`vision/images.py: frustum_bounds`), beside the first version's box on the same frames and seeds. "
        "Right: rotation < 5 deg and position < 5 % of the range.", "",
        *md_table(["world", "camera", "search box", "frames", "right", "confident", "right among confident"], rows)])
    write_section(args.out, "Image-only solve: the search box from one camera", body)
    print(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
