"""A chessboard photographed in a cluttered scene: image -> Shi-Tomasi corners -> EvoPose, no correspondences.

The stand-in for the real photographs the issue names: a 10 x 7 board (54 inner corners, 25 mm
squares) drawn by perspective warping into a textured scene with other boxes and checker tiles
whose corners mix with the board's, some board corners hidden by an occluder, seen by one camera and by a stereo pair.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from benchmarks.problems import grid_model, is_success, pose_errors
from evopose import Bounds, Camera, PoseProblem, View, solve
from vision.features import detect_corners, x_junctions
from geometry import matrix_from_pose

SQUARE = 0.025
COLS, ROWS = 9, 6  # inner corners
PX_PER_SQUARE = 40


def board_texture() -> np.ndarray:
    """The board image: (ROWS + 1) x (COLS + 1) squares with a white margin of one square."""
    h, w = (ROWS + 3) * PX_PER_SQUARE, (COLS + 3) * PX_PER_SQUARE
    img = np.full((h, w), 255, np.uint8)
    for r in range(ROWS + 1):
        for c in range(COLS + 1):
            if (r + c) % 2 == 0:
                y, x = (r + 1) * PX_PER_SQUARE, (c + 1) * PX_PER_SQUARE
                img[y:y + PX_PER_SQUARE, x:x + PX_PER_SQUARE] = 0
    return img


def texture_to_target(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Board-texture pixels -> target-frame metres (the grid model's frame: centred, z = 0), shape (K, 3)."""
    x = (u - (COLS + 3) * PX_PER_SQUARE / 2) / PX_PER_SQUARE * SQUARE
    y = (v - (ROWS + 3) * PX_PER_SQUARE / 2) / PX_PER_SQUARE * SQUARE
    return np.stack([x, y, np.zeros_like(x)], axis=1)


def photograph(camera: Camera, world_from_target: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A grey 640 x 480 photo: textured background, clutter boxes, the warped board, an occluder, noise."""
    h, w = camera.height, camera.width
    noise = cv2.GaussianBlur(rng.normal(128, 40, (h // 8, w // 8)).astype(np.float32), (0, 0), 1.5)
    scene = cv2.resize(noise, (w, h), interpolation=cv2.INTER_CUBIC)
    for _ in range(8):  # other objects whose corners are false points
        x, y = rng.integers(0, w - 60), rng.integers(0, h - 60)
        cv2.rectangle(scene, (int(x), int(y)), (int(x + rng.integers(20, 60)), int(y + rng.integers(20, 60))),
                      float(rng.choice([20, 235])), -1)
    for _ in range(10):  # small 2 x 2 checker tiles: X-junctions that are not the board's
        x, y, a = int(rng.integers(20, w - 40)), int(rng.integers(20, h - 40)), int(rng.integers(6, 14))
        scene[y - a:y, x - a:x] = scene[y:y + a, x:x + a] = 15.0
        scene[y - a:y, x:x + a] = scene[y:y + a, x - a:x] = 240.0
    tex = board_texture()
    corners_tex = np.array([[0, 0], [tex.shape[1], 0], [tex.shape[1], tex.shape[0]], [0, tex.shape[0]]], float)
    T = camera.camera_from_world @ matrix_from_pose(world_from_target)
    p_cam = texture_to_target(corners_tex[:, 0], corners_tex[:, 1]) @ T[:3, :3].T + T[:3, 3]
    uv, _ = camera.project_camera_points(p_cam)
    H = cv2.getPerspectiveTransform(corners_tex.astype(np.float32), uv.astype(np.float32))
    warped = cv2.warpPerspective(tex.astype(np.float32), H, (w, h), flags=cv2.INTER_AREA)
    inside = cv2.warpPerspective(np.ones_like(tex, np.float32), H, (w, h)) > 0.5
    scene = np.where(inside, warped, scene)
    # an occluder over one corner of the board
    c = uv.mean(axis=0)
    cv2.circle(scene, (int(uv[0, 0] * 0.6 + c[0] * 0.4), int(uv[0, 1] * 0.6 + c[1] * 0.4)), 25, 90.0, -1)
    scene = cv2.GaussianBlur(scene, (0, 0), 0.8) + rng.normal(0, 3, scene.shape)
    return np.clip(scene, 0, 255).astype(np.uint8)


def _pair(rng: np.random.Generator) -> tuple[list[Camera], np.ndarray]:
    """A left camera (the world frame) and a right one 12 cm beside it; the board 0.6-0.9 m ahead, tilted."""
    f = 620.0
    left = Camera(f, f, 320, 240, 640, 480)
    right = Camera.from_pose(f, f, 320, 240, 640, 480, world_from_camera_pose=[0.12, 0, 0, 0, -0.05, 0])
    tilt = rng.uniform(-0.5, 0.5, 2)
    pose = np.array([rng.uniform(-0.05, 0.1), rng.uniform(-0.05, 0.05), rng.uniform(0.6, 0.9),
                     tilt[0], tilt[1], rng.uniform(-0.4, 0.4)])
    return [left, right], pose


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("n_cameras", [1, 2])
def test_chessboard_photo_is_localised_from_unlabelled_corners(seed, n_cameras):
    rng = np.random.default_rng(seed)
    cameras, truth = _pair(rng)
    model, symmetries = grid_model(cols=COLS, rows=ROWS, square=SQUARE)
    views = []
    for cam in cameras[:n_cameras]:
        photo = photograph(cam, truth, rng)
        found = detect_corners(photo, max_corners=150, quality=0.05, min_distance=8)
        # the board's outline has L-corners one square outside the inner grid: keeping them would make
        # the grid shifted by one row fit as well as the truth; inner corners are X-junctions
        corners = found[x_junctions(photo, found)]
        outline = grid_model(cols=COLS + 2, rows=ROWS + 2, square=SQUARE)[0].points
        ring, _ = cam.project_population(truth[None], outline)
        near_ring = lambda pts: np.count_nonzero(np.min(np.linalg.norm(pts[:, None] - ring[0][None], axis=2), 1) < 2)
        assert near_ring(found) - near_ring(corners) >= 10, "the outline's L-corners were detected, then dropped"
        # the photo really mixes the board's corners with others and misses some of its own
        proj, _ = cam.project_population(truth[None], model.points)
        d = np.linalg.norm(corners[:, None, :] - proj[0][None], axis=2)
        on_board = np.min(d, axis=1) < 2.0
        assert np.count_nonzero(~on_board) >= 4, "the scene must contribute false corners"
        assert np.count_nonzero(np.min(d, axis=0) < 2.0) < len(model.points), "some board corners are hidden"
        views.append(View(cam, corners))
    bounds = Bounds.from_dict({"x": (-1, 1), "y": (-1, 1), "z": (0.2, 3)})
    solution = solve(PoseProblem(model, tuple(views), bounds), seed=seed)
    rot, pos = pose_errors(solution.pose, truth, symmetries, model.points.mean(axis=0))
    assert is_success(rot, pos, float(np.linalg.norm(truth[:3]))), (np.rad2deg(rot), pos)
    assert np.rad2deg(rot) < 2.0 and pos < 0.01  # a close board: the pose is sharp
