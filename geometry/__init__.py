"""The pose convention, written once: every package of the project imports it from here (docs/design.md §2).

A pose ``s = (x, y, z, roll, pitch, yaw)`` is ``world_from_target``: ``p_world = R @ p_target + t`` with
``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (fixed axes, ROS REP-103), which is scipy's
``Rotation.from_euler("xyz", [roll, pitch, yaw])``. This is the paper's ``s = (Tx, Ty, Tz, alpha, beta, gamma)``.
Quaternions are ``(x, y, z, w)`` with ``w >= 0`` (ROS order). Angles are radians, positions metres.

Every function is vectorised over leading axes (a whole population in one call) unless it says otherwise, and
needs only numpy: the compiled projection (:mod:`evopose.projection`) compiles :func:`rotation_entries` itself,
so the rotation is typed out in this one place. ``tests/test_geometry_copies.py`` fails on a copy elsewhere.
"""

from __future__ import annotations

import numpy as np

PARAM_NAMES: tuple[str, ...] = ("x", "y", "z", "roll", "pitch", "yaw")
ANGLE_PARAMS: tuple[int, ...] = (3, 4, 5)


def rotation_entries(roll, pitch, yaw):
    """The nine entries of ``Rz(yaw) Ry(pitch) Rx(roll)``, row-major, for scalars or arrays of one shape.

    Plain numpy on purpose: :mod:`evopose.projection` compiles this very function with numba.
    """
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    return (cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr,
            sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr,
            -sp, cp * sr, cp * cr)


def rotation_entry_derivatives(roll, pitch, yaw):
    """The entries of ``d R / d roll``, ``d R / d pitch`` and ``d R / d yaw`` of :func:`rotation_entries`'s ``R``: three
    tuples of nine, row-major, for scalars or arrays of one shape (constant zeros as 0.0).

    Plain numpy on purpose: :mod:`evopose.projection` compiles this very function with numba (the refinement's
    analytic Jacobian)."""
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    d_roll = (0.0, cy * sp * cr + sy * sr, sy * cr - cy * sp * sr,
              0.0, sy * sp * cr - cy * sr, -sy * sp * sr - cy * cr,
              0.0, cp * cr, -cp * sr)
    d_pitch = (-cy * sp, cy * cp * sr, cy * cp * cr,
               -sy * sp, sy * cp * sr, sy * cp * cr,
               -cp, -sp * sr, -sp * cr)
    d_yaw = (-sy * cp, -(sy * sp * sr + cy * cr), cy * sr - sy * sp * cr,
             cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr,
             0.0, 0.0, 0.0)
    return d_roll, d_pitch, d_yaw


def rotation_from_euler(rpy: np.ndarray) -> np.ndarray:
    """Rotation matrices ``Rz(yaw) Ry(pitch) Rx(roll)``: rpy (..., 3) radians -> (..., 3, 3)."""
    rpy = np.asarray(rpy, dtype=float)
    if rpy.shape[-1:] != (3,):
        raise ValueError(f"expected (..., 3) roll/pitch/yaw, got shape {rpy.shape}")
    entries = rotation_entries(rpy[..., 0], rpy[..., 1], rpy[..., 2])
    return np.stack(entries, axis=-1).reshape(rpy.shape[:-1] + (3, 3))


def euler_from_rotation(R: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rotation_from_euler`: (..., 3, 3) -> (..., 3).

    Roll in [-pi, pi], pitch in [-pi/2, pi/2], yaw in [-pi, pi]. At the gimbal lock (pitch = +-pi/2) roll is 0.
    """
    R = np.asarray(R, dtype=float)
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"expected (..., 3, 3) rotation matrices, got shape {R.shape}")
    cp = np.hypot(R[..., 0, 0], R[..., 1, 0])
    pitch = np.arctan2(-R[..., 2, 0], cp)
    regular = cp > 1e-9
    roll = np.where(regular, np.arctan2(R[..., 2, 1], R[..., 2, 2]), 0.0)
    yaw = np.where(regular, np.arctan2(R[..., 1, 0], R[..., 0, 0]), np.arctan2(-R[..., 0, 1], R[..., 1, 1]))
    return np.stack([roll, pitch, yaw], axis=-1)


def matrix_from_pose(s: np.ndarray) -> np.ndarray:
    """Homogeneous ``world_from_target`` transforms: s (..., 6) -> (..., 4, 4)."""
    s = np.asarray(s, dtype=float)
    if s.shape[-1:] != (6,):
        raise ValueError(f"expected (..., 6) poses (x, y, z, roll, pitch, yaw), got shape {s.shape}")
    T = np.zeros(s.shape[:-1] + (4, 4))
    T[..., :3, :3] = rotation_from_euler(s[..., 3:])
    T[..., :3, 3] = s[..., :3]
    T[..., 3, 3] = 1.0
    return T


def pose_from_matrix(T: np.ndarray) -> np.ndarray:
    """Inverse of :func:`matrix_from_pose`: (..., 4, 4) -> (..., 6)."""
    T = np.asarray(T, dtype=float)
    if T.shape[-2:] != (4, 4):
        raise ValueError(f"expected (..., 4, 4) transforms, got shape {T.shape}")
    return np.concatenate([T[..., :3, 3], euler_from_rotation(T[..., :3, :3])], axis=-1)


def canonical_pose(s: np.ndarray) -> np.ndarray:
    """The same pose with its canonical roll-pitch-yaw (pitch within +-pi/2, angles wrapped): (..., 6)."""
    return pose_from_matrix(matrix_from_pose(s))


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
    """Unit quaternions ``(x, y, z, w)`` of ``Rz(yaw) Ry(pitch) Rx(roll)``, ``w >= 0``: (..., 3) -> (..., 4)."""
    rpy = np.asarray(rpy, dtype=float)
    if rpy.shape[-1:] != (3,):
        raise ValueError(f"expected (..., 3) roll/pitch/yaw, got shape {rpy.shape}")
    hr, hp, hy = rpy[..., 0] / 2, rpy[..., 1] / 2, rpy[..., 2] / 2
    cr, sr = np.cos(hr), np.sin(hr)
    cp, sp = np.cos(hp), np.sin(hp)
    cy, sy = np.cos(hy), np.sin(hy)
    q = np.stack([sr * cp * cy - cr * sp * sy,
                  cr * sp * cy + sr * cp * sy,
                  cr * cp * sy - sr * sp * cy,
                  cr * cp * cy + sr * sp * sy], axis=-1)
    return np.where(q[..., 3:4] < 0, -q, q)


def euler_from_quaternion(q: np.ndarray) -> np.ndarray:
    """``(roll, pitch, yaw)`` of unit quaternions ``(x, y, z, w)``: (..., 4) -> (..., 3)."""
    q = np.asarray(q, dtype=float)
    if q.shape[-1:] != (4,):
        raise ValueError(f"expected (..., 4) quaternions (x, y, z, w), got shape {q.shape}")
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.stack([roll, pitch, yaw], axis=-1)


def quaternion_from_rotation(R: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(x, y, z, w)``, ``w >= 0``, of rotation matrices: (..., 3, 3) -> (..., 4).

    Shepperd's method: from the trace when it is positive, else from the largest diagonal entry. The operations
    keep the order of the ROS bridges' scalar version, so the CDR golden files stay byte for byte.
    """
    m = np.asarray(R, dtype=float)
    if m.shape[-2:] != (3, 3):
        raise ValueError(f"expected (..., 3, 3) rotation matrices, got shape {m.shape}")
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    d21, d02, d10 = m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]
    s01, s02, s12 = m[..., 0, 1] + m[..., 1, 0], m[..., 0, 2] + m[..., 2, 0], m[..., 1, 2] + m[..., 2, 1]
    trace = m00 + m11 + m22
    with np.errstate(invalid="ignore", divide="ignore"):  # the branches not taken may divide by zero
        s0 = 2.0 * np.sqrt(1.0 + trace)
        s1 = 2.0 * np.sqrt(1.0 + m00 - m11 - m22)
        s2 = 2.0 * np.sqrt(1.0 + m11 - m00 - m22)
        s3 = 2.0 * np.sqrt(1.0 + m22 - m00 - m11)
        q0 = np.stack([d21 / s0, d02 / s0, d10 / s0, 0.25 * s0], -1)
        q1 = np.stack([0.25 * s1, s01 / s1, s02 / s1, d21 / s1], -1)
        q2 = np.stack([s01 / s2, 0.25 * s2, s12 / s2, d02 / s2], -1)
        q3 = np.stack([s02 / s3, s12 / s3, 0.25 * s3, d10 / s3], -1)
    x_largest, y_largest = (m00 > m11) & (m00 > m22), m11 > m22
    q = np.where((trace > 0)[..., None], q0,
                 np.where(x_largest[..., None], q1, np.where(y_largest[..., None], q2, q3)))
    norm = np.sqrt(q[..., 0] * q[..., 0] + q[..., 1] * q[..., 1] + q[..., 2] * q[..., 2] + q[..., 3] * q[..., 3])
    q = q / norm[..., None]
    return np.where(q[..., 3:4] < 0, -q, q)


def rotation_from_quaternion(q: np.ndarray) -> np.ndarray:
    """Rotation matrices of unit quaternions ``(x, y, z, w)`` (either sign): (..., 4) -> (..., 3, 3)."""
    q = np.asarray(q, dtype=float)
    if q.shape[-1:] != (4,):
        raise ValueError(f"expected (..., 4) quaternions, got shape {q.shape}")
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - z * w)
    R[..., 0, 2] = 2 * (x * z + y * w)
    R[..., 1, 0] = 2 * (x * y + z * w)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - x * w)
    R[..., 2, 0] = 2 * (x * z - y * w)
    R[..., 2, 1] = 2 * (y * z + x * w)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


#: Below this angle (radians) the rotation vector's scale comes from its Taylor series (as scipy's ``Rotation``).
SMALL_ROTATION = 1e-3


def rotation_from_rotvec(v: np.ndarray) -> np.ndarray:
    """Rotation matrices of rotation vectors (axis times angle, radians; about fixed axes): (..., 3) -> (..., 3, 3).
    The formulas of scipy's ``Rotation.from_rotvec(v).as_matrix()``, through the unit quaternion."""
    v = np.asarray(v, dtype=float)
    if v.shape[-1:] != (3,):
        raise ValueError(f"expected (..., 3) rotation vectors, got shape {v.shape}")
    angle = np.sqrt(np.sum(v * v, axis=-1))
    small = angle <= SMALL_ROTATION
    with np.errstate(invalid="ignore", divide="ignore"):  # the branch not taken at angle 0
        scale = np.where(small, 0.5 - angle ** 2 / 48 + angle ** 4 / 3840, np.sin(angle / 2) / angle)
    q = np.concatenate([scale[..., None] * v, np.cos(angle / 2)[..., None]], axis=-1)
    return rotation_from_quaternion(q)


def rotvec_from_rotation(R: np.ndarray) -> np.ndarray:
    """Rotation vectors (axis times angle, angle in [0, pi]) of rotation matrices: (..., 3, 3) -> (..., 3). The
    formulas of scipy's ``Rotation.from_matrix(R).as_rotvec()`` from :func:`quaternion_from_rotation`'s
    quaternion (``w >= 0``)."""
    q = quaternion_from_rotation(R)
    xyz, w = q[..., :3], q[..., 3]
    angle = 2 * np.arctan2(np.sqrt(np.sum(xyz * xyz, axis=-1)), w)
    small = angle <= SMALL_ROTATION
    with np.errstate(invalid="ignore", divide="ignore"):  # the branch not taken at angle 0
        scale = np.where(small, 2 + angle ** 2 / 12 + 7 * angle ** 4 / 2880, angle / np.sin(angle / 2))
    return scale[..., None] * xyz


def rotation_angle(R_a: np.ndarray, R_b: np.ndarray) -> np.ndarray:
    """Geodesic angle (radians) between rotations, shapes (..., 3, 3) -> (...)."""
    R_a, R_b = np.asarray(R_a, float), np.asarray(R_b, float)
    if R_a.shape[-2:] != (3, 3) or R_b.shape[-2:] != (3, 3):
        raise ValueError(f"expected (..., 3, 3) rotation matrices, got shapes {R_a.shape} and {R_b.shape}")
    R_rel = np.einsum("...ji,...jk->...ik", R_a, R_b)
    cos = (np.trace(R_rel, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.arccos(np.clip(cos, -1.0, 1.0))


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Wrap angles (radians) to [-pi, pi), any shape."""
    return (np.asarray(a, float) + np.pi) % (2 * np.pi) - np.pi


def angle_difference(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Signed difference ``a - b`` of angles, wrapped to [-pi, pi)."""
    return wrap_angle(np.asarray(a, float) - np.asarray(b, float))


def pose_difference(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a - b`` of poses (..., 6), the angles wrapped to [-pi, pi) (no canonicalisation)."""
    d = np.asarray(a, float) - np.asarray(b, float)
    d[..., 3:] = wrap_angle(d[..., 3:])
    return d


def pose_error(estimate: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """Absolute errors of one pose (6,): x, y, z in metres, roll, pitch, yaw in degrees, ``position`` the
    distance (m)."""
    # the same rotation has two roll-pitch-yaw triples: compare the canonical ones (pitch within +-90 deg)
    estimate, truth = canonical_pose(estimate), canonical_pose(truth)
    d = pose_difference(estimate, truth)
    d[3:] = np.degrees(d[3:])
    out = {n: float(abs(v)) for n, v in zip(PARAM_NAMES, d)}
    out["position"] = float(np.linalg.norm(d[:3]))
    return out


def rotation_error(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Geodesic angle (radians) between the rotations of poses (..., 6) -> (...)."""
    return rotation_angle(rotation_from_euler(np.asarray(estimate, float)[..., 3:6]),
                          rotation_from_euler(np.asarray(truth, float)[..., 3:6]))


def random_rotations(n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` rotations drawn uniformly on SO(3) as roll/pitch/yaw, shape (n, 3)."""
    q = rng.standard_normal((n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return euler_from_rotation(rotation_from_quaternion(q))


__all__ = ["ANGLE_PARAMS", "PARAM_NAMES", "angle_difference", "canonical_pose", "euler_from_quaternion",
           "euler_from_rotation", "invert_transform", "matrix_from_pose", "pose_difference", "pose_error",
           "pose_from_matrix", "quaternion_from_euler", "quaternion_from_rotation", "random_rotations",
           "rotation_angle", "rotation_entries", "rotation_entry_derivatives", "rotation_error", "rotation_from_euler",
           "rotation_from_quaternion", "rotation_from_rotvec", "rotvec_from_rotation", "wrap_angle"]
