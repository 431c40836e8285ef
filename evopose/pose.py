"""Pose parametrisation: ``s = (x, y, z, roll, pitch, yaw)`` as ``world_from_target``.

Convention (DESIGN.md §2): ``p_world = R @ p_target + t`` with
``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (fixed axes, ROS REP-103), which is
scipy's ``Rotation.from_euler("xyz", [roll, pitch, yaw])``. This is the paper's
``s = (Tx, Ty, Tz, alpha, beta, gamma)``.

Every function is vectorised over leading axes so that a whole population of
poses is converted in one call.
"""

from __future__ import annotations

import numpy as np

PARAM_NAMES: tuple[str, ...] = ("x", "y", "z", "roll", "pitch", "yaw")
ANGLE_PARAMS: tuple[int, ...] = (3, 4, 5)


def rotation_from_euler(rpy: np.ndarray) -> np.ndarray:
    """Rotation matrices ``Rz(yaw) Ry(pitch) Rx(roll)``.

    Parameters
    ----------
    rpy : array, shape (..., 3)
        Roll, pitch, yaw in radians.

    Returns
    -------
    array, shape (..., 3, 3)
    """
    rpy = np.asarray(rpy, dtype=float)
    if rpy.shape[-1] != 3:
        raise ValueError(f"expected (..., 3) roll/pitch/yaw, got shape {rpy.shape}")
    cr, sr = np.cos(rpy[..., 0]), np.sin(rpy[..., 0])
    cp, sp = np.cos(rpy[..., 1]), np.sin(rpy[..., 1])
    cy, sy = np.cos(rpy[..., 2]), np.sin(rpy[..., 2])
    R = np.empty(rpy.shape[:-1] + (3, 3))
    R[..., 0, 0] = cy * cp
    R[..., 0, 1] = cy * sp * sr - sy * cr
    R[..., 0, 2] = cy * sp * cr + sy * sr
    R[..., 1, 0] = sy * cp
    R[..., 1, 1] = sy * sp * sr + cy * cr
    R[..., 1, 2] = sy * sp * cr - cy * sr
    R[..., 2, 0] = -sp
    R[..., 2, 1] = cp * sr
    R[..., 2, 2] = cp * cr
    return R


def euler_from_rotation(R: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rotation_from_euler`.

    Parameters
    ----------
    R : array, shape (..., 3, 3)

    Returns
    -------
    array, shape (..., 3)
        Roll in [-pi, pi], pitch in [-pi/2, pi/2], yaw in [-pi, pi]. At the
        gimbal lock (pitch = +-pi/2) roll is set to 0.
    """
    R = np.asarray(R, dtype=float)
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"expected (..., 3, 3) rotation matrices, got shape {R.shape}")
    cp = np.hypot(R[..., 0, 0], R[..., 1, 0])
    pitch = np.arctan2(-R[..., 2, 0], cp)
    regular = cp > 1e-9
    roll = np.where(regular, np.arctan2(R[..., 2, 1], R[..., 2, 2]), 0.0)
    yaw = np.where(regular, np.arctan2(R[..., 1, 0], R[..., 0, 0]),
                   np.arctan2(-R[..., 0, 1], R[..., 1, 1]))
    return np.stack([roll, pitch, yaw], axis=-1)


def matrix_from_pose(s: np.ndarray) -> np.ndarray:
    """Homogeneous ``world_from_target`` transforms.

    Parameters
    ----------
    s : array, shape (..., 6)
        ``(x, y, z, roll, pitch, yaw)``.

    Returns
    -------
    array, shape (..., 4, 4)
    """
    s = np.asarray(s, dtype=float)
    if s.shape[-1] != 6:
        raise ValueError(f"expected (..., 6) poses (x, y, z, roll, pitch, yaw), got shape {s.shape}")
    T = np.zeros(s.shape[:-1] + (4, 4))
    T[..., :3, :3] = rotation_from_euler(s[..., 3:])
    T[..., :3, 3] = s[..., :3]
    T[..., 3, 3] = 1.0
    return T


def pose_from_matrix(T: np.ndarray) -> np.ndarray:
    """Inverse of :func:`matrix_from_pose`; ``T`` has shape (..., 4, 4) -> (..., 6)."""
    T = np.asarray(T, dtype=float)
    if T.shape[-2:] != (4, 4):
        raise ValueError(f"expected (..., 4, 4) transforms, got shape {T.shape}")
    return np.concatenate([T[..., :3, 3], euler_from_rotation(T[..., :3, :3])], axis=-1)


def invert_transform(T: np.ndarray) -> np.ndarray:
    """Inverse of rigid transforms ``a_from_b`` -> ``b_from_a``, shape (..., 4, 4)."""
    T = np.asarray(T, dtype=float)
    if T.shape[-2:] != (4, 4):
        raise ValueError(f"expected (..., 4, 4) transforms, got shape {T.shape}")
    out = np.zeros_like(T)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def quaternion_from_euler(rpy: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(x, y, z, w)`` with ``w >= 0``; rpy shape (..., 3) -> (..., 4)."""
    rpy = np.asarray(rpy, dtype=float)
    if rpy.shape[-1:] != (3,):
        raise ValueError(f"expected (..., 3) roll/pitch/yaw, got shape {rpy.shape}")
    hr, hp, hy = rpy[..., 0] / 2, rpy[..., 1] / 2, rpy[..., 2] / 2
    cr, sr = np.cos(hr), np.sin(hr)
    cp, sp = np.cos(hp), np.sin(hp)
    cy, sy = np.cos(hy), np.sin(hy)
    q = np.stack([
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    ], axis=-1)
    return np.where(q[..., 3:4] < 0, -q, q)


def rotation_angle(R_a: np.ndarray, R_b: np.ndarray) -> np.ndarray:
    """Geodesic angle (radians) between rotations, shapes (..., 3, 3) -> (...)."""
    R_rel = np.einsum("...ji,...jk->...ik", np.asarray(R_a, float), np.asarray(R_b, float))
    cos = (np.trace(R_rel, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.arccos(np.clip(cos, -1.0, 1.0))


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Wrap angles to [-pi, pi)."""
    return (np.asarray(a, float) + np.pi) % (2 * np.pi) - np.pi


def random_rotations(n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` rotations drawn uniformly on SO(3) as roll/pitch/yaw, shape (n, 3)."""
    q = rng.standard_normal((n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = q.T
    R = np.empty((n, 3, 3))
    R[:, 0, 0] = 1 - 2 * (y * y + z * z)
    R[:, 0, 1] = 2 * (x * y - z * w)
    R[:, 0, 2] = 2 * (x * z + y * w)
    R[:, 1, 0] = 2 * (x * y + z * w)
    R[:, 1, 1] = 1 - 2 * (x * x + z * z)
    R[:, 1, 2] = 2 * (y * z - x * w)
    R[:, 2, 0] = 2 * (x * z - y * w)
    R[:, 2, 1] = 2 * (y * z + x * w)
    R[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return euler_from_rotation(R)
