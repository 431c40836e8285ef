"""Unit tests of the geometry module: the (x, y, z, roll, pitch, yaw) world_from_target convention (docs/design.md §2)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from geometry import (
    ANGLE_PARAMS,
    PARAM_NAMES,
    euler_from_rotation,
    invert_transform,
    matrix_from_pose,
    pose_from_matrix,
    quaternion_from_euler,
    random_rotations,
    rotation_angle,
    rotation_from_euler,
    wrap_angle,
)

HALF_PI = np.pi / 2


def random_rpy(rng: np.random.Generator, n: int, pitch_margin: float = 0.0) -> np.ndarray:
    """Roll, yaw uniform in (-pi, pi); pitch uniform in (-pi/2 + margin, pi/2 - margin)."""
    roll = rng.uniform(-np.pi, np.pi, n)
    pitch = rng.uniform(-HALF_PI + pitch_margin, HALF_PI - pitch_margin, n)
    yaw = rng.uniform(-np.pi, np.pi, n)
    return np.stack([roll, pitch, yaw], axis=1)


def random_poses(rng: np.random.Generator, n: int) -> np.ndarray:
    return np.concatenate([rng.uniform(-10, 10, (n, 3)), random_rpy(rng, n)], axis=1)


def assert_rotation_matrices(R: np.ndarray, atol: float = 1e-12) -> None:
    eye = np.broadcast_to(np.eye(3), R.shape)
    np.testing.assert_allclose(np.swapaxes(R, -1, -2) @ R, eye, atol=atol)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=atol)


def test_parameter_names_and_order():
    assert PARAM_NAMES == ("x", "y", "z", "roll", "pitch", "yaw")
    assert [PARAM_NAMES[i] for i in ANGLE_PARAMS] == ["roll", "pitch", "yaw"]


# --- rotation_from_euler -----------------------------------------------------------------------

def test_rotation_from_euler_matches_scipy_xyz():
    rng = np.random.default_rng(1)
    # whole turns on every angle, including pitch beyond +-pi/2 (the formula must hold for any angle)
    rpy = rng.uniform(-2 * np.pi, 2 * np.pi, (500, 3))
    expected = Rotation.from_euler("xyz", rpy).as_matrix()
    np.testing.assert_allclose(rotation_from_euler(rpy), expected, atol=1e-14)


def test_the_rotation_entries_derivatives_are_the_rotations_derivatives():
    """geometry.rotation_entry_derivatives (the refinement's analytic Jacobian) against central differences of
    rotation_from_euler, at random attitudes and at pitch +-90 deg."""
    from geometry import rotation_entry_derivatives

    rng = np.random.default_rng(2)
    angles = [*rng.uniform(-np.pi, np.pi, (6, 3)), np.array([0.4, np.pi / 2, -1.0]), np.array([0.4, -np.pi / 2, 1.0])]
    for rpy in angles:
        got = [np.reshape(np.array(d, float), (3, 3)) for d in rotation_entry_derivatives(*rpy)]
        for axis in range(3):
            h = np.zeros(3)
            h[axis] = 1e-6
            numeric = (rotation_from_euler(rpy + h) - rotation_from_euler(rpy - h)) / 2e-6
            np.testing.assert_allclose(got[axis], numeric, atol=1e-9)


def test_rotation_from_euler_is_rz_ry_rx():
    roll, pitch, yaw = 0.3, -0.7, 2.1

    def rx(a):
        c, s = np.cos(a), np.sin(a)
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])

    def ry(a):
        c, s = np.cos(a), np.sin(a)
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])

    def rz(a):
        c, s = np.cos(a), np.sin(a)
        return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])

    np.testing.assert_allclose(rotation_from_euler([roll, pitch, yaw]), rz(yaw) @ ry(pitch) @ rx(roll),
                               atol=1e-15)
    # single-axis sanity: positive yaw turns x towards y (right-handed, REP-103)
    np.testing.assert_allclose(rotation_from_euler([0, 0, HALF_PI]) @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(rotation_from_euler([HALF_PI, 0, 0]) @ [0, 1, 0], [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(rotation_from_euler([0, HALF_PI, 0]) @ [0, 0, 1], [1, 0, 0], atol=1e-15)


def test_rotation_from_euler_vectorised_over_leading_axes():
    rng = np.random.default_rng(2)
    rpy = rng.uniform(-np.pi, np.pi, (4, 5, 3))
    R = rotation_from_euler(rpy)
    assert R.shape == (4, 5, 3, 3)
    assert_rotation_matrices(R)
    np.testing.assert_array_equal(R[2, 3], rotation_from_euler(rpy[2, 3]))
    assert rotation_from_euler([0.1, 0.2, 0.3]).shape == (3, 3)


# --- euler_from_rotation ---------------------------------------------------------------------

def test_euler_round_trip_away_from_gimbal_lock():
    rng = np.random.default_rng(3)
    rpy = random_rpy(rng, 2000, pitch_margin=1e-3)
    back = euler_from_rotation(rotation_from_euler(rpy))
    assert back.shape == rpy.shape
    # the same numbers come back (roll/yaw compared modulo a full turn, in case of +-pi)
    np.testing.assert_allclose(wrap_angle(back - rpy), 0.0, atol=1e-9)


def test_euler_from_rotation_matches_scipy():
    R = Rotation.random(300, random_state=5)
    expected = R.as_euler("xyz")
    got = euler_from_rotation(R.as_matrix())
    np.testing.assert_allclose(wrap_angle(got - expected), 0.0, atol=1e-9)


def test_euler_from_rotation_ranges_and_any_input_angle():
    rng = np.random.default_rng(6)
    rpy = rng.uniform(-3 * np.pi, 3 * np.pi, (1000, 3))  # outside the principal ranges
    R = rotation_from_euler(rpy)
    back = euler_from_rotation(R)
    assert np.all(np.abs(back[:, 0]) <= np.pi)
    assert np.all(np.abs(back[:, 1]) <= HALF_PI)
    assert np.all(np.abs(back[:, 2]) <= np.pi)
    np.testing.assert_allclose(rotation_from_euler(back), R, atol=1e-10)


@pytest.mark.parametrize("pitch", [HALF_PI, -HALF_PI])
def test_euler_at_gimbal_lock_reproduces_the_matrix(pitch):
    rng = np.random.default_rng(7)
    n = 200
    rpy = np.stack([rng.uniform(-np.pi, np.pi, n), np.full(n, pitch), rng.uniform(-np.pi, np.pi, n)], axis=1)
    R = rotation_from_euler(rpy)
    back = euler_from_rotation(R)
    assert np.all(np.isfinite(back))
    np.testing.assert_allclose(back[:, 1], pitch, atol=1e-7)
    np.testing.assert_array_equal(back[:, 0], 0.0)  # documented: roll set to 0 at the lock
    np.testing.assert_allclose(rotation_from_euler(back), R, atol=1e-12)


@pytest.mark.parametrize("pitch", [HALF_PI, -HALF_PI])
def test_euler_at_gimbal_lock_with_rounded_matrix_entries(pitch):
    """Lock matrices built elsewhere (scipy) carry rounding: |R[2, 0]| is 1 - 2e-16, not exactly 1.

    The recovered angles must still reproduce the matrix to double precision (an ``arcsin`` of
    ``-R[2, 0]`` loses half the digits there, ~1.5e-8 rad; ``arctan2(-R[2, 0], hypot(R[0, 0], R[1, 0]))`` does not).
    """
    rng = np.random.default_rng(7)
    n = 200
    rpy = np.stack([rng.uniform(-np.pi, np.pi, n), np.full(n, pitch), rng.uniform(-np.pi, np.pi, n)], axis=1)
    R_sp = Rotation.from_euler("xyz", rpy).as_matrix()
    back = euler_from_rotation(R_sp)
    np.testing.assert_allclose(back[:, 1], pitch, atol=1e-12)
    np.testing.assert_allclose(rotation_from_euler(back), R_sp, atol=1e-12)


@pytest.mark.parametrize("offset", [1e-4, 1e-6, 1e-8, 1e-10])
def test_euler_near_gimbal_lock_reproduces_the_matrix(offset):
    rng = np.random.default_rng(8)
    n = 200
    sign = rng.choice([-1.0, 1.0], n)
    rpy = np.stack([rng.uniform(-np.pi, np.pi, n), sign * (HALF_PI - offset), rng.uniform(-np.pi, np.pi, n)],
                   axis=1)
    R = rotation_from_euler(rpy)
    np.testing.assert_allclose(rotation_from_euler(euler_from_rotation(R)), R, atol=1e-7)


# --- homogeneous transforms --------------------------------------------------------------------

def test_matrix_from_pose_layout_and_action():
    rng = np.random.default_rng(9)
    s = random_poses(rng, 1)[0]
    T = matrix_from_pose(s)
    assert T.shape == (4, 4)
    np.testing.assert_array_equal(T[3], [0, 0, 0, 1])
    np.testing.assert_array_equal(T[:3, 3], s[:3])
    np.testing.assert_allclose(T[:3, :3], Rotation.from_euler("xyz", s[3:]).as_matrix(), atol=1e-14)
    p_target = rng.normal(size=(10, 3))
    p_world = (T @ np.c_[p_target, np.ones(10)].T).T[:, :3]
    np.testing.assert_allclose(p_world, p_target @ T[:3, :3].T + s[:3], atol=1e-12)


def test_pose_matrix_round_trip():
    rng = np.random.default_rng(10)
    s = random_poses(rng, 1000)
    s[:, 4] = np.clip(s[:, 4], -HALF_PI + 1e-3, HALF_PI - 1e-3)
    back = pose_from_matrix(matrix_from_pose(s))
    np.testing.assert_allclose(back[:, :3], s[:, :3], atol=1e-12)
    np.testing.assert_allclose(wrap_angle(back[:, 3:] - s[:, 3:]), 0.0, atol=1e-9)
    # and the other way: matrix -> pose -> matrix for arbitrary rigid transforms
    T = np.tile(np.eye(4), (300, 1, 1))
    T[:, :3, :3] = Rotation.random(300, random_state=11).as_matrix()
    T[:, :3, 3] = rng.normal(scale=20, size=(300, 3))
    np.testing.assert_allclose(matrix_from_pose(pose_from_matrix(T)), T, atol=1e-10)


def test_pose_functions_vectorised():
    rng = np.random.default_rng(12)
    s = random_poses(rng, 6).reshape(2, 3, 6)
    T = matrix_from_pose(s)
    assert T.shape == (2, 3, 4, 4)
    np.testing.assert_array_equal(T[1, 2], matrix_from_pose(s[1, 2]))
    assert pose_from_matrix(T).shape == (2, 3, 6)


def test_invert_transform():
    rng = np.random.default_rng(13)
    T = matrix_from_pose(random_poses(rng, 50))
    T_inv = invert_transform(T)
    assert T_inv.shape == T.shape
    np.testing.assert_allclose(T_inv, np.linalg.inv(T), atol=1e-12)
    np.testing.assert_allclose(T @ T_inv, np.broadcast_to(np.eye(4), T.shape), atol=1e-12)
    np.testing.assert_allclose(T_inv @ T, np.broadcast_to(np.eye(4), T.shape), atol=1e-12)
    np.testing.assert_allclose(invert_transform(T_inv), T, atol=1e-12)
    # frames: camera_from_target = inv(world_from_camera) @ world_from_target
    world_from_camera, world_from_target = T[0], T[1]
    camera_from_target = invert_transform(world_from_camera) @ world_from_target
    p_target = rng.normal(size=3)
    p_world = world_from_target[:3, :3] @ p_target + world_from_target[:3, 3]
    p_cam = camera_from_target[:3, :3] @ p_target + camera_from_target[:3, 3]
    np.testing.assert_allclose(world_from_camera[:3, :3] @ p_cam + world_from_camera[:3, 3], p_world, atol=1e-12)
    # the input is left alone
    T0 = T.copy()
    invert_transform(T)
    np.testing.assert_array_equal(T, T0)


# --- quaternions -------------------------------------------------------------------------------

def test_quaternion_from_euler_matches_scipy():
    rng = np.random.default_rng(14)
    rpy = rng.uniform(-2 * np.pi, 2 * np.pi, (1000, 3))
    q = quaternion_from_euler(rpy)
    assert q.shape == (1000, 4)
    expected = Rotation.from_euler("xyz", rpy).as_quat()  # (x, y, z, w)
    expected = np.where(expected[:, 3:4] < 0, -expected, expected)
    np.testing.assert_allclose(q, expected, atol=1e-14)
    assert np.all(q[:, 3] >= 0)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-14)
    # the quaternion is the same rotation as the matrix
    np.testing.assert_allclose(Rotation.from_quat(q).as_matrix(), rotation_from_euler(rpy), atol=1e-13)


def test_quaternion_known_values():
    np.testing.assert_allclose(quaternion_from_euler([0, 0, 0]), [0, 0, 0, 1], atol=1e-15)
    h = np.sqrt(0.5)
    np.testing.assert_allclose(quaternion_from_euler([0, 0, HALF_PI]), [0, 0, h, h], atol=1e-15)
    np.testing.assert_allclose(quaternion_from_euler([HALF_PI, 0, 0]), [h, 0, 0, h], atol=1e-15)
    # w < 0 before canonicalisation: a turn of 3 pi/2 about z is -pi/2 about z
    np.testing.assert_allclose(quaternion_from_euler([0, 0, 1.5 * np.pi]), [0, 0, -h, h], atol=1e-15)
    assert quaternion_from_euler(np.zeros((2, 3, 3))).shape == (2, 3, 4)


# --- rotation_angle ----------------------------------------------------------------------------

def test_rotation_angle():
    rng = np.random.default_rng(15)
    n = 500
    R_a = Rotation.random(n, random_state=16)
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    theta = rng.uniform(1e-3, np.pi - 1e-3, n)
    R_b = R_a * Rotation.from_rotvec(axis * theta[:, None])
    A, B = R_a.as_matrix(), R_b.as_matrix()
    np.testing.assert_allclose(rotation_angle(A, B), theta, atol=1e-7)
    np.testing.assert_allclose(rotation_angle(B, A), theta, atol=1e-7)
    # left and right perturbations give the same geodesic angle
    R_c = Rotation.from_rotvec(axis * theta[:, None]) * R_a
    np.testing.assert_allclose(rotation_angle(A, R_c.as_matrix()), theta, atol=1e-7)
    np.testing.assert_allclose(rotation_angle(A, A), 0.0, atol=2e-7)
    assert rotation_angle(A, B).shape == (n,)
    half_turn = rotation_from_euler([0, 0, np.pi])
    assert rotation_angle(np.eye(3), half_turn) == pytest.approx(np.pi, abs=1e-7)
    assert np.ndim(rotation_angle(np.eye(3), half_turn)) == 0


def test_wrap_angle():
    a = np.array([-np.pi, np.pi, 3 * np.pi, -7.0, 0.0, 2 * np.pi + 0.5, -0.5])
    w = wrap_angle(a)
    assert np.all(w >= -np.pi) and np.all(w < np.pi)
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-12)
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-12)
    np.testing.assert_allclose(w[[4, 5, 6]], [0.0, 0.5, -0.5], atol=1e-12)


# --- random_rotations --------------------------------------------------------------------------

def _moment_statistics(R: np.ndarray) -> tuple[float, float]:
    """Largest |mean of R_ij| and largest |mean of R_ij^2 - 1/3|; both ~0 for uniform rotations."""
    return float(np.abs(R.mean(axis=0)).max()), float(np.abs((R ** 2).mean(axis=0) - 1 / 3).max())


def test_random_rotations_uniform_on_so3():
    n = 20000
    rpy = random_rotations(n, np.random.default_rng(17))
    assert rpy.shape == (n, 3)
    assert np.all(np.isfinite(rpy))
    R = rotation_from_euler(rpy)
    assert_rotation_matrices(R, atol=1e-10)
    first, second = _moment_statistics(R)
    # standard errors: 0.0041 (mean) and 0.0021 (second moment) for 20000 samples
    assert first < 0.02
    assert second < 0.012
    # the geodesic angle to the identity has density (1 - cos t) / pi: mean pi/2 + 2/pi
    angle = rotation_angle(np.eye(3), R)
    assert angle.mean() == pytest.approx(np.pi / 2 + 2 / np.pi, abs=0.02)
    # ... and the statistic would catch the naive sampler (uniform Euler angles)
    naive = rotation_from_euler(random_rpy(np.random.default_rng(18), n))
    assert _moment_statistics(naive)[1] > 0.1


def test_random_rotations_seed_reproducible():
    a = random_rotations(100, np.random.default_rng(42))
    b = random_rotations(100, np.random.default_rng(42))
    c = random_rotations(100, np.random.default_rng(43))
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)


# --- shape validation ---------------------------------------------------------------------------

@pytest.mark.parametrize("func, shape", [
    (rotation_from_euler, (2,)),
    (rotation_from_euler, (5, 4)),
    (euler_from_rotation, (3, 4)),
    (euler_from_rotation, (9,)),
    (matrix_from_pose, (3,)),
    (matrix_from_pose, (4, 7)),
    (pose_from_matrix, (3, 3)),
    (pose_from_matrix, (4, 3)),
])
def test_wrong_shapes_raise_value_error(func, shape):
    with pytest.raises(ValueError, match=str(shape).replace("(", r"\(").replace(")", r"\)")):
        func(np.zeros(shape))


@pytest.mark.parametrize("shape", [(3, 3), (5, 5)])
def test_invert_transform_wrong_shape_raises_value_error(shape):
    with pytest.raises(ValueError):
        invert_transform(np.eye(shape[0]))


@pytest.mark.parametrize("shape", [(2,), (10, 4)])
def test_quaternion_from_euler_wrong_shape_raises_value_error(shape):
    with pytest.raises(ValueError):
        quaternion_from_euler(np.zeros(shape))


def test_rotation_angle_wrong_shapes_raise_value_error():
    with pytest.raises(ValueError):
        rotation_angle(np.eye(3), np.eye(4))
