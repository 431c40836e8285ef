"""Unit tests of evopose.camera: pinhole + plumb_bob projection of whole populations, checked against OpenCV."""

from __future__ import annotations

import warnings

import cv2
import numpy as np
import pytest

from evopose.camera import FAR_AWAY_PX, MIN_DEPTH, Camera
from geometry import euler_from_rotation, invert_transform, matrix_from_pose


def random_distortion(rng: np.random.Generator) -> np.ndarray:
    """Moderate plumb_bob [k1, k2, p1, p2, k3]."""
    return np.array([rng.uniform(-0.2, 0.2), rng.uniform(-0.05, 0.05), rng.uniform(-0.002, 0.002),
                     rng.uniform(-0.002, 0.002), rng.uniform(-0.01, 0.01)])


def random_extrinsic_pose(rng: np.random.Generator) -> np.ndarray:
    return np.r_[rng.uniform(-2, 2, 3), rng.uniform(-np.pi, np.pi), rng.uniform(-1.2, 1.2), rng.uniform(-np.pi, np.pi)]


def poses_in_front(rng: np.random.Generator, camera: Camera, n: int) -> np.ndarray:
    """world_from_target poses whose origin is 4-10 m in front of ``camera``, within +-0.25 rad of its axis."""
    depth = rng.uniform(4, 10, n)
    ray = np.stack([rng.uniform(-0.25, 0.25, n), rng.uniform(-0.25, 0.25, n), np.ones(n)], axis=1)
    p_cam = ray * depth[:, None]
    p_world = p_cam @ camera.world_from_camera[:3, :3].T + camera.world_from_camera[:3, 3]
    rpy = np.stack([rng.uniform(-np.pi, np.pi, n), rng.uniform(-1.4, 1.4, n), rng.uniform(-np.pi, np.pi, n)], axis=1)
    return np.concatenate([p_world, rpy], axis=1)


def opencv_projection(camera: Camera, pose: np.ndarray, points_target: np.ndarray) -> np.ndarray:
    camera_from_target = invert_transform(camera.world_from_camera) @ matrix_from_pose(pose)
    rvec, _ = cv2.Rodrigues(camera_from_target[:3, :3])
    tvec = camera_from_target[:3, 3].copy()
    uv, _ = cv2.projectPoints(points_target.reshape(-1, 1, 3), rvec, tvec, camera.matrix, camera.distortion)
    return uv.reshape(-1, 2)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_project_population_matches_opencv(seed):
    rng = np.random.default_rng(seed)
    camera = Camera.from_pose(rng.uniform(400, 1200), rng.uniform(400, 1200), rng.uniform(280, 360),
                              rng.uniform(200, 280), 640, 480, distortion=random_distortion(rng),
                              world_from_camera_pose=random_extrinsic_pose(rng))
    assert not np.allclose(camera.world_from_camera, np.eye(4))
    points = rng.uniform(-0.5, 0.5, (25, 3))
    poses = poses_in_front(rng, camera, 12)
    with np.errstate(all="raise"):
        uv, in_front = camera.project_population(poses, points)
    assert uv.shape == (12, 25, 2) and in_front.shape == (12, 25)
    assert in_front.dtype == bool and in_front.all()
    for n, pose in enumerate(poses):
        np.testing.assert_allclose(uv[n], opencv_projection(camera, pose, points), rtol=0, atol=1e-6)


def test_project_population_without_distortion_is_pinhole():
    rng = np.random.default_rng(4)
    camera = Camera.from_pose(800, 780, 321.5, 239.5, world_from_camera_pose=random_extrinsic_pose(rng))
    points = rng.uniform(-0.5, 0.5, (10, 3))
    poses = poses_in_front(rng, camera, 5)
    uv, _ = camera.project_population(poses, points)
    p_cam = camera.to_camera_frame(poses, points)
    np.testing.assert_allclose(uv[..., 0], 800 * p_cam[..., 0] / p_cam[..., 2] + 321.5, atol=1e-9)
    np.testing.assert_allclose(uv[..., 1], 780 * p_cam[..., 1] / p_cam[..., 2] + 239.5, atol=1e-9)
    for n, pose in enumerate(poses):
        np.testing.assert_allclose(uv[n], opencv_projection(camera, pose, points), rtol=0, atol=1e-6)


def test_identity_extrinsic_means_world_is_camera_frame():
    camera = Camera(500, 500, 320, 240)
    np.testing.assert_array_equal(camera.world_from_camera, np.eye(4))
    np.testing.assert_array_equal(camera.camera_from_world, np.eye(4))
    np.testing.assert_array_equal(camera.center_world, np.zeros(3))
    # the origin of a target 5 m straight ahead lands on the principal point
    uv, in_front = camera.project_population(np.array([[0, 0, 5, 0.3, 0.2, 0.1]]), np.zeros((1, 3)))
    np.testing.assert_allclose(uv[0, 0], [320, 240], atol=1e-12)
    assert in_front[0, 0]
    # x right, y down in the optical frame
    uv, _ = camera.project_world(np.array([[1.0, 0, 5], [0, 1.0, 5]]))
    np.testing.assert_allclose(uv, [[420, 240], [320, 340]], atol=1e-12)


def test_from_pose_frames():
    pose = np.array([1.0, -2.0, 0.5, 0.1, -0.4, 2.0])
    camera = Camera.from_pose(600, 600, 320, 240, world_from_camera_pose=pose)
    np.testing.assert_allclose(camera.world_from_camera, matrix_from_pose(pose), atol=1e-15)
    np.testing.assert_allclose(camera.camera_from_world @ camera.world_from_camera, np.eye(4), atol=1e-12)
    np.testing.assert_allclose(camera.center_world, pose[:3], atol=1e-15)
    np.testing.assert_array_equal(camera.matrix, [[600, 0, 320], [0, 600, 240], [0, 0, 1]])
    # the camera's own centre plus 3 m along its optical axis projects onto the principal point
    ahead = camera.world_from_camera[:3, :3] @ [0, 0, 3.0] + pose[:3]
    uv, in_front = camera.project_world(ahead[None])
    np.testing.assert_allclose(uv[0], [320, 240], atol=1e-9)
    assert in_front[0]


def test_points_behind_camera_are_flagged_and_far_away():
    rng = np.random.default_rng(5)
    camera = Camera.from_pose(700, 700, 320, 240, distortion=[0.15, -0.05, 0.002, -0.002, 0.01],
                              world_from_camera_pose=random_extrinsic_pose(rng))
    p_cam = np.array([
        [0.3, -0.2, 0.0],          # on the camera plane
        [0.0, 0.0, 0.0],           # the optical centre itself
        [1.0, 2.0, -1e-12],
        [-3.0, 0.5, -2.0],         # behind
        [50.0, -80.0, -100.0],     # far behind, off axis
        [0.2, 0.1, 0.5 * MIN_DEPTH],  # in front but too close to project
        [1e-9, -1e-9, -1e-9],
        [0.1, 0.2, 3.0],           # a regular point in front
        [-0.4, 0.3, 2 * MIN_DEPTH],   # just in front of the limit
    ])
    expect_in_front = np.array([False] * 7 + [True, True])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with np.errstate(all="raise"):
            uv_cam, front_cam = camera.project_camera_points(p_cam)
            p_world = p_cam @ camera.world_from_camera[:3, :3].T + camera.world_from_camera[:3, 3]
            uv_world, front_world = camera.project_world(p_world)
            # the same points as a "model" seen under the pose world_from_target = world_from_camera
            pose = np.r_[camera.center_world, euler_from_rotation(camera.world_from_camera[:3, :3])]
            uv_pop, front_pop = camera.project_population(pose[None], p_cam)
    for uv, front in ((uv_cam, front_cam), (uv_world, front_world), (uv_pop[0], front_pop[0])):
        np.testing.assert_array_equal(front, expect_in_front)
        assert np.all(np.isfinite(uv))
        np.testing.assert_array_equal(uv[~expect_in_front], FAR_AWAY_PX)
        # far away from every pixel of the image
        assert not camera.in_image(uv[~expect_in_front], margin=1000).any()
    np.testing.assert_allclose(uv_world, uv_cam, atol=1e-6)
    np.testing.assert_allclose(uv_pop[0], uv_cam, atol=1e-6)
    assert FAR_AWAY_PX >= 1e5


def test_project_population_mixed_front_and_back():
    rng = np.random.default_rng(6)
    camera = Camera.from_pose(800, 800, 320, 240, distortion=random_distortion(rng))
    # a long rod through the camera: points on both sides of the camera plane
    points = np.stack([np.zeros(41), np.zeros(41), np.linspace(-10, 10, 41)], axis=1)
    poses = np.array([[0.05, -0.03, 0.0, 0.0, 0.0, 0.0], [0.05, -0.03, 0.0, 0.02, -0.01, 0.3]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with np.errstate(all="raise"):
            uv, in_front = camera.project_population(poses, points)
    z = camera.to_camera_frame(poses, points)[..., 2]
    np.testing.assert_array_equal(in_front, z > MIN_DEPTH)
    assert in_front.any() and (~in_front).any()
    assert np.all(np.isfinite(uv))
    np.testing.assert_array_equal(uv[~in_front], FAR_AWAY_PX)
    for n, pose in enumerate(poses):
        front = in_front[n]
        np.testing.assert_allclose(uv[n][front], opencv_projection(camera, pose, points[front]), atol=1e-6)


def test_project_world_consistent_with_project_population():
    rng = np.random.default_rng(7)
    camera = Camera.from_pose(900, 850, 310, 250, distortion=random_distortion(rng),
                              world_from_camera_pose=random_extrinsic_pose(rng))
    points = rng.uniform(-0.5, 0.5, (30, 3))
    poses = poses_in_front(rng, camera, 6)
    uv_pop, front_pop = camera.project_population(poses, points)
    for n, pose in enumerate(poses):
        T = matrix_from_pose(pose)
        p_world = points @ T[:3, :3].T + T[:3, 3]
        uv, front = camera.project_world(p_world)
        np.testing.assert_allclose(uv, uv_pop[n], rtol=0, atol=1e-9)
        np.testing.assert_array_equal(front, front_pop[n])


def test_project_population_accepts_a_single_pose():
    camera = Camera(500, 500, 320, 240)
    pose = np.array([0.1, 0.2, 5.0, 0.0, 0.0, 0.0])
    points = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]])
    uv, front = camera.project_population(pose, points)
    assert uv.shape == (1, 2, 2) and front.shape == (1, 2)
    np.testing.assert_allclose(uv[0], [[330, 260], [340, 260]], atol=1e-12)


def test_in_image():
    camera = Camera(500, 500, 320, 240, width=640, height=480)
    uv = np.array([[0, 0], [639.9, 479.9], [640, 10], [10, 480], [-0.1, 10], [-5, -5]])
    np.testing.assert_array_equal(camera.in_image(uv), [True, True, False, False, False, False])
    np.testing.assert_array_equal(camera.in_image(uv, margin=10), [True] * 6)


@pytest.mark.parametrize("kwargs, match", [
    (dict(fx=-800.0), "fx"),
    (dict(fx=0.0), "fx"),
    (dict(fy=-1.0), "fy"),
    (dict(fx=np.nan), "fx"),
    (dict(fy=np.inf), "fy"),
    (dict(cx=np.nan), "cx"),
    (dict(cy=np.inf), "cy"),
    (dict(width=0), "width"),
    (dict(height=-480), "height"),
    (dict(distortion=np.zeros(4)), "distortion"),
    (dict(distortion=np.zeros(8)), "distortion"),
    (dict(distortion=[0.1, np.nan, 0, 0, 0]), "distortion"),
    (dict(world_from_camera=np.eye(3)), "world_from_camera"),
    (dict(world_from_camera=np.eye(4)[:3]), "world_from_camera"),
    (dict(world_from_camera=np.where(np.eye(4) == 1, np.nan, 0.0)), "world_from_camera"),
])
def test_constructor_validation(kwargs, match):
    args = dict(fx=800.0, fy=800.0, cx=320.0, cy=240.0)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        Camera(**args)


def test_constructor_normalises_arrays():
    camera = Camera(800, 800, 320, 240, distortion=[[0.1, 0.01, 0.0, 0.0, 0.0]], world_from_camera=np.eye(4).tolist())
    assert camera.distortion.shape == (5,) and camera.distortion.dtype == float
    assert isinstance(camera.world_from_camera, np.ndarray) and camera.world_from_camera.shape == (4, 4)
