"""The image-guided starts' moment match (evopose.align_kernel) against the NumPy formulation it replaced."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.problems import make_paper_scale_problem, make_telephoto_box_problem
from evopose.fitness import project_into_view
from evopose.init import align_to_view, sample_rotations
from evopose.kernel_backend import align_positions
from geometry import rotation_from_euler


def _masked_median(values, mask, count):
    ordered = np.sort(np.where(mask, values, np.inf), axis=1)
    out = ordered[np.arange(len(values)), np.maximum(count - 1, 0) // 2]
    return np.where(count > 0, out, 0.0)


def numpy_align(problem, view, poses, target_centre, target_spread, iterations=2):
    """The moment match as it was written in NumPy (evopose/init.py before the kernel)."""
    cam = view.camera
    centroid_target = problem.model.points.mean(axis=0)
    R = rotation_from_euler(poses[:, 3:])
    poses = poses.copy()
    for _ in range(iterations):
        proj = project_into_view(problem.model, view, poses)
        count = proj.usable.sum(axis=1)
        ok = count >= 2
        if not np.any(ok):
            break
        cu = _masked_median(proj.uv[..., 0], proj.usable, count)
        cv = _masked_median(proj.uv[..., 1], proj.usable, count)
        spread = _masked_median(np.hypot(proj.uv[..., 0] - cu[:, None], proj.uv[..., 1] - cv[:, None]),
                                proj.usable, count)
        ok &= spread > 0.5
        c_world = poses[:, :3] + R @ centroid_target
        c_cam = c_world @ cam.camera_from_world[:3, :3].T + cam.camera_from_world[:3, 3]
        ok &= c_cam[:, 2] > 0
        z = np.where(ok, c_cam[:, 2], 1.0)
        new_u = target_centre[:, 0] + (cam.fx * c_cam[:, 0] / z + cam.cx - cu)
        new_v = target_centre[:, 1] + (cam.fy * c_cam[:, 1] / z + cam.cy - cv)
        new_z = z * spread / target_spread
        new_cam = np.stack([(new_u - cam.cx) / cam.fx * new_z, (new_v - cam.cy) / cam.fy * new_z, new_z], axis=1)
        new_world = new_cam @ cam.world_from_camera[:3, :3].T + cam.world_from_camera[:3, 3]
        poses[ok, :3] = (new_world - R @ centroid_target)[ok]
    return poses


def _starts(problem, n, rng):
    poses = problem.bounds.uniform(n, rng)
    poses[:, 3:] = sample_rotations(problem.bounds, n, rng)
    return poses


@pytest.mark.parametrize("make", [make_telephoto_box_problem, make_paper_scale_problem], ids=["box", "paper"])
def test_the_compiled_moment_match_is_the_numpy_one(make):
    problem = make(np.random.default_rng(3)).problem
    view, model = problem.views[0], problem.model
    rng = np.random.default_rng(4)
    poses = _starts(problem, 300, rng)
    poses[:5, :3] = view.camera.world_from_camera[:3, 3]  # at the camera: no usable point, left where it is
    centre, spread = np.median(view.points, axis=0), 30.0
    target_centre = centre + rng.normal(0, 3.0, (len(poses), 2))
    target_spread = spread * np.exp(0.15 * rng.standard_normal(len(poses)))
    for iterations in (1, 2, 3):
        expected = numpy_align(problem, view, poses, target_centre, target_spread, iterations)
        got = np.array(poses)
        align_positions(got, model.points, model.normals, True, view.camera.intrinsics,
                        view.camera.camera_from_world, view.camera.world_from_camera, model.points.mean(axis=0),
                        target_centre, target_spread, iterations)
        assert not np.array_equal(got[5:], poses[5:])  # it moved them
        np.testing.assert_array_equal(got[:5], poses[:5])
        np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-9)


def test_aligned_starts_cover_the_image_points():
    """The effect: after the match, each start's projected model is centred on the view's points at their spread."""
    problem = make_telephoto_box_problem(np.random.default_rng(8)).problem
    view = problem.views[0]
    rng = np.random.default_rng(9)
    poses = align_to_view(problem, view, _starts(problem, 200, rng), rng, scale_jitter=0.0, shift_jitter=0.0,
                          iterations=4)
    proj = project_into_view(problem.model, view, poses)
    count = proj.usable.sum(axis=1)
    centre = np.median(view.points, axis=0)
    spread = np.median(np.linalg.norm(view.points - centre, axis=1))
    cu = _masked_median(proj.u, proj.usable, count)
    cv = _masked_median(proj.v, proj.usable, count)
    ok = count >= 3
    assert ok.mean() > 0.9
    assert np.median(np.hypot(cu - centre[0], cv - centre[1])[ok]) < 0.05 * spread
