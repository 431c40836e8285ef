"""The photoreal renderer with Blender itself (skipped, with the reason, when ``bpy`` is not installed:
`make photoreal`): a glowing ball lands where the project's camera projects it, and a small Cycles dataset."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from evopose import Camera
from geometry import matrix_from_pose
from scenarios.mesh import ellipsoid_mesh
from scenarios.photoreal.exr import read_exr
from scenarios.photoreal.runner import PhotorealUnavailable, blender_version, run_job
from scenarios.photoreal.scene import ENGINE_DEFAULTS, FORMAT, blender_camera, blender_matrix
from scenarios.photoreal.shapes import from_mesh
from scenarios.world import IntrinsicsSpec


@pytest.fixture(scope="module")
def blender():
    try:
        return blender_version()
    except PhotorealUnavailable as err:
        pytest.skip(f"Blender's bpy is not available: {err}")


def _glow_job(k: IntrinsicsSpec, T: np.ndarray, point: np.ndarray, radius: float, path: Path) -> dict:
    ball = from_mesh(ellipsoid_mesh(point, [radius] * 3, (0, 0, 0), (48, 24)), True)
    return {"format": FORMAT, "world": "glow", "engine": {**ENGINE_DEFAULTS, "samples": 16},
            "materials": {"glow": {"base_colour": [0, 0, 0], "roughness": 1.0, "emission": 1.0},
                          "black": {"base_colour": [0, 0, 0], "roughness": 1.0}},
            "objects": [{"name": "ball", "parent": None, "material": "glow", **ball.to_json()}],
            "ground": {"half_size": 1.0, "material": "black"},
            "lighting": {"sky": "overcast", "sun_direction": [0, 0, 1], "sun_strength": 0, "sun_angle": 0.01,
                         "sky_strength": 0.0, "sun_elevation": 1.5, "sun_azimuth": 0},
            "cameras": {"C": blender_camera(k, "C")},
            "frames": [{"frame": 0, "target": None, "movers": {},
                        "renders": [{"camera": "C", "matrix": blender_matrix(T).tolist(), "path": str(path),
                                     "seed": 1}]}]}


@pytest.mark.parametrize("k", [IntrinsicsSpec(fx=90.0, fy=90.0, cx=41.3, cy=37.8, width=97, height=61),
                               IntrinsicsSpec(fx=2400.0, fy=2400.0, cx=80.0, cy=60.0, width=160, height=120)],
                         ids=["odd-wide", "telephoto"])
def test_a_point_renders_where_the_camera_projects_it(blender, tmp_path, k):
    T = matrix_from_pose([17.7, -3.5, 8.5, -2.0, 0.1, 1.4])
    camera = Camera(k.fx, k.fy, k.cx, k.cy, k.width, k.height, np.zeros(5), T)
    uv = np.array([0.3 * k.width, 0.7 * k.height])
    depth = 15.0
    point = T[:3, :3] @ (np.linalg.solve(camera.matrix, [uv[0], uv[1], 1.0]) * depth) + T[:3, 3]
    expected = camera.project_world(point[None])[0][0]
    run_job(_glow_job(k, T, point, 3.0 * depth / k.fx, tmp_path / "glow.exr"), tmp_path / "job.json", lambda e: None)
    image = read_exr(tmp_path / "glow.exr").sum(axis=2)
    v, u = np.mgrid[: image.shape[0], : image.shape[1]]
    centre = np.array([(image * u).sum(), (image * v).sum()]) / image.sum()
    assert np.linalg.norm(centre - expected) < 0.3, (centre, expected)


def test_a_small_cycles_dataset(blender, tmp_path):
    from agents.tools.render_dataset import render_dataset
    from scenarios.dataset import open_dataset

    world = tmp_path / "small.yaml"
    world.write_text("extends: exp2-photoreal-telephoto\nname: small\nvehicles:\n"
                     "  - {name: H1, camera: {intrinsics: {fx: 3000, fy: 3000, cx: 80, cy: 60, width: 160, "
                     "height: 120}}}\n", encoding="utf-8")
    out = tmp_path / "ds"
    events = []
    summary = render_dataset(world, out, frames=1, samples=4, cameras=["H1"], progress=events.append)
    assert summary["images_rendered"] == 1 and [e["rendered"] for e in events] == [True]
    ds = open_dataset(out)
    assert ds.manifest.engine.name == "cycles" and ds.manifest.engine.blender == blender
    image = cv2.imread(str(ds.image_path("H1", 0)))
    assert image.shape == (120, 160, 3)
    assert (out / "H1" / "raw" / "000000.exr").is_file()
    # the robot's red paint is around its marks
    marks = ds.truth(0).cameras["H1"].marks
    assert len(marks) >= 6
    u, v = np.mean([m.uv for m in marks], axis=0).astype(int)
    patch = image[v - 8:v + 8, u - 8:u + 8].astype(int)
    assert np.sum((patch[..., 2] > patch[..., 1] + 30) & (patch[..., 2] > patch[..., 0] + 30)) > 20
    # resumed with the JPEG gone: developed again from the EXR, nothing rendered
    (out / "H1" / "000000.jpg").unlink()
    events.clear()
    again = render_dataset(world, out, frames=1, samples=4, cameras=["H1"], progress=events.append)
    assert again["images_rendered"] == 0 and [e["rendered"] for e in events] == [False]
    assert np.array_equal(cv2.imread(str(out / "H1" / "000000.jpg")), image)
