"""The second marked target (issue 32, "Any marked target"): the Husky-like UGV of scenarios/models/husky.yaml, its
worlds and its committed Cycles fixtures (tests/data/photoreal/husky-paper, husky-telephoto; docs/datasets.md)."""

from __future__ import annotations

import colorsys
from pathlib import Path

import cv2
import numpy as np
import pytest

from scenarios.dataset import open_dataset
from scenarios.target import load_model
from scenarios.world import load_scenario

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "photoreal"
PALETTE = ("red", "blue", "violet", "black")


def _hue_deg(bgr) -> float:
    b, g, r = (c / 255 for c in bgr)
    return 360 * colorsys.rgb_to_hsv(r, g, b)[0]


def test_the_model_loads_with_its_own_body_and_palette():
    husky, pioneer = load_model("husky"), load_model("pioneer")
    assert husky.name == "husky-ugv" and "Husky" in husky.description
    assert set(husky.palette) == set(PALETTE) and set(husky.mark_colours) == set(PALETTE)
    assert not set(husky.palette) & set(pioneer.palette)
    counts = {c: husky.mark_colours.count(c) for c in PALETTE}
    assert len(husky.mark_points) >= 16 and min(counts.values()) >= 4, counts
    # the body: yellow, not the Pioneer's red; every mark colour differs from it in hue or in lightness
    body, red_body = husky.body_colour, pioneer.body_colour
    assert body != red_body and abs(_hue_deg(body) - _hue_deg(red_body)) > 30
    for name, bgr in husky.palette.items():
        hue_gap = abs((_hue_deg(bgr) - _hue_deg(body) + 180) % 360 - 180)
        light_gap = abs(sum(bgr) - sum(body)) / 3
        assert hue_gap > 40 or light_gap > 80, name
    # marks on the top and on all four sides, not coplanar
    normals = {tuple(np.round(n).astype(int)) for n in husky.mark_normals}
    assert normals == {(0, 0, 1), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0)}
    centred = husky.mark_points - husky.mark_points.mean(axis=0)
    assert np.linalg.svd(centred, compute_uv=False)[-1] > 0.1
    assert 0.025 <= husky.mark_radius <= 0.035
    assert husky.motion is not None and husky.good_within is not None


@pytest.mark.parametrize("world, pioneer_world", [("exp2-photoreal-husky", "exp2-photoreal"),
                                                  ("exp2-photoreal-telephoto-husky", "exp2-photoreal-telephoto")])
def test_the_worlds_change_only_the_target_model(world, pioneer_world):
    husky, pioneer = load_scenario(world), load_scenario(pioneer_world)
    assert husky.model.name == "husky-ugv" and pioneer.model.name == "pioneer-2dx"
    for k in (0, 7):
        assert np.allclose(husky.target_pose(k), pioneer.target_pose(k))


@pytest.mark.parametrize("name, world", [("husky-paper", "exp2-photoreal-husky"),
                                         ("husky-telephoto", "exp2-photoreal-telephoto-husky")])
def test_the_committed_fixtures_open_and_see_the_marks(name, world):
    root = DATA / name
    ds = open_dataset(root)
    assert ds.name == world and ds.frames == 2 and ds.cameras == ("H1", "H2") and ds.target_visible
    assert ds.manifest.engine.name == "cycles"
    assert not list(root.rglob("*.exr")) and not (root / ".blender").exists()
    model = ds.world().model
    assert model.name == "husky-ugv" and set(model.palette) == set(PALETTE)
    scenario = load_scenario(world)
    for k in range(ds.frames):
        truth = ds.truth(k)
        assert np.allclose(truth.target_pose, scenario.target_pose(k))
        for camera in ds.cameras:
            marks = truth.cameras[camera].marks
            assert len(marks) >= 6, (camera, k, len(marks))
            assert {m.colour for m in marks} <= set(PALETTE)
            assert cv2.imread(str(ds.image_path(camera, k))).shape == (480, 640, 3)


def test_the_fixtures_are_small():
    size = sum(p.stat().st_size for name in ("husky-paper", "husky-telephoto")
               for p in (DATA / name).rglob("*") if p.is_file())
    assert size <= 1_500_000, size
