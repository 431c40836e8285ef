"""The one projection of EvoPose, compiled: ``m_j(s)`` of eq. (1), model point ``j`` seen under pose ``s``.

Pinhole with OpenCV ``plumb_bob`` distortion (docs/design.md §2). Every projection in the package goes
through :func:`pinhole`: :class:`evopose.camera.Camera` (points, populations), the fitness
(:func:`evopose.fitness.project_into_view`) and the local refinement (:mod:`evopose.refine_kernel`).

Array conventions: ``intr`` (9,) = fx, fy, cx, cy, k1, k2, p1, p2, k3; ``cam_from_world`` (4, 4);
a pose ``s`` (6,) = (x, y, z, roll, pitch, yaw) is ``world_from_target`` with ``R = Rz(yaw) Ry(pitch) Rx(roll)``.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from geometry import rotation_entries, rotation_entry_derivatives

from .kernel_abi import FAR_AWAY_PX, FASTMATH, MIN_DEPTH


#: ``R = Rz(yaw) Ry(pitch) Rx(roll)`` as nine scalars: the one convention (:func:`geometry.rotation_entries`), compiled.
_rotation_entries = nb.njit(cache=True, fastmath=FASTMATH, nogil=True)(rotation_entries)
#: ... and its derivatives by the three angles (:func:`geometry.rotation_entry_derivatives`), compiled.
_rotation_entry_derivatives = nb.njit(cache=True, fastmath=FASTMATH, nogil=True)(rotation_entry_derivatives)


@nb.njit(cache=True, fastmath=FASTMATH, nogil=True)
def rotation_into(roll, pitch, yaw, R):  # pragma: no cover - compiled
    """``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)`` into ``R`` (3, 3), as :func:`geometry.rotation_from_euler`."""
    e = _rotation_entries(roll, pitch, yaw)
    R[0, 0], R[0, 1], R[0, 2] = e[0], e[1], e[2]
    R[1, 0], R[1, 1], R[1, 2] = e[3], e[4], e[5]
    R[2, 0], R[2, 1], R[2, 2] = e[6], e[7], e[8]


@nb.njit(cache=True, fastmath=FASTMATH, nogil=True)
def pinhole(X, Y, Z, intr):  # pragma: no cover - compiled
    """Pixel ``(u, v)`` of the optical-frame point ``(X, Y, Z)`` and whether it is in front of the camera.

    Points with ``Z <= MIN_DEPTH`` are not projected: they get ``FAR_AWAY_PX`` and False.
    """
    if Z <= MIN_DEPTH:
        return FAR_AWAY_PX, FAR_AWAY_PX, False
    x = X / Z
    y = Y / Z
    k1, k2, p1, p2, k3 = intr[4], intr[5], intr[6], intr[7], intr[8]
    if k1 != 0.0 or k2 != 0.0 or p1 != 0.0 or p2 != 0.0 or k3 != 0.0:
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xy = x * y
        xd = x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xy
        x = xd
        y = yd
    return intr[0] * x + intr[2], intr[1] * y + intr[3], True


@nb.njit(cache=True, fastmath=FASTMATH, nogil=True)
def project_points(p_cam, intr):  # pragma: no cover - compiled
    """Project optical-frame points (K, 3): pixels (K, 2) and in-front flags (K,)."""
    K = p_cam.shape[0]
    uv = np.empty((K, 2))
    in_front = np.empty(K, np.bool_)
    for k in range(K):
        u, v, ok = pinhole(p_cam[k, 0], p_cam[k, 1], p_cam[k, 2], intr)
        uv[k, 0] = u
        uv[k, 1] = v
        in_front[k] = ok
    return uv, in_front


@nb.njit(cache=True, fastmath=FASTMATH, nogil=True)
def project_pose(s, model, normals, use_normals, intr, cfw, u, v, usable, R, Rc):  # pragma: no cover
    """Project the model (M, 3) under pose ``s`` (6,) into one view: fills ``u``, ``v``, ``usable`` (M,).

    A point is usable when it is in front of the camera and, with ``use_normals``, its normal faces the
    camera. ``R`` and ``Rc`` are (3, 3) scratch arrays.
    """
    rotation_into(s[3], s[4], s[5], R)
    # camera_from_target = cam_from_world @ world_from_target
    for i in range(3):
        for j in range(3):
            Rc[i, j] = cfw[i, 0] * R[0, j] + cfw[i, 1] * R[1, j] + cfw[i, 2] * R[2, j]
    t0 = cfw[0, 0] * s[0] + cfw[0, 1] * s[1] + cfw[0, 2] * s[2] + cfw[0, 3]
    t1 = cfw[1, 0] * s[0] + cfw[1, 1] * s[1] + cfw[1, 2] * s[2] + cfw[1, 3]
    t2 = cfw[2, 0] * s[0] + cfw[2, 1] * s[1] + cfw[2, 2] * s[2] + cfw[2, 3]
    for m in range(model.shape[0]):
        X = Rc[0, 0] * model[m, 0] + Rc[0, 1] * model[m, 1] + Rc[0, 2] * model[m, 2] + t0
        Y = Rc[1, 0] * model[m, 0] + Rc[1, 1] * model[m, 1] + Rc[1, 2] * model[m, 2] + t1
        Z = Rc[2, 0] * model[m, 0] + Rc[2, 1] * model[m, 1] + Rc[2, 2] * model[m, 2] + t2
        pu, pv, ok = pinhole(X, Y, Z, intr)
        if ok and use_normals:
            nx = Rc[0, 0] * normals[m, 0] + Rc[0, 1] * normals[m, 1] + Rc[0, 2] * normals[m, 2]
            ny = Rc[1, 0] * normals[m, 0] + Rc[1, 1] * normals[m, 1] + Rc[1, 2] * normals[m, 2]
            nz = Rc[2, 0] * normals[m, 0] + Rc[2, 1] * normals[m, 1] + Rc[2, 2] * normals[m, 2]
            ok = nx * X + ny * Y + nz * Z < 0.0
        u[m] = pu
        v[m] = pv
        usable[m] = ok


@nb.njit(cache=True, fastmath=FASTMATH, nogil=True)
def pinhole_derivatives(X, Y, Z, intr):  # pragma: no cover - compiled
    """The derivatives of :func:`pinhole`'s pixel ``(u, v)`` by the optical-frame point: ``(du/dX, du/dY, du/dZ,
    dv/dX, dv/dY, dv/dZ)``, distortion included (``Z`` > :data:`MIN_DEPTH`)."""
    iz = 1.0 / Z
    x = X * iz
    y = Y * iz
    # d(xd, yd) / d(x, y): the identity without distortion
    a, b, c, d = 1.0, 0.0, 0.0, 1.0
    k1, k2, p1, p2, k3 = intr[4], intr[5], intr[6], intr[7], intr[8]
    if k1 != 0.0 or k2 != 0.0 or p1 != 0.0 or p2 != 0.0 or k3 != 0.0:
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        slope = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)   # d radial / d r2
        a = radial + 2.0 * x * x * slope + 2.0 * p1 * y + 6.0 * p2 * x
        b = 2.0 * x * y * slope + 2.0 * p1 * x + 2.0 * p2 * y
        c = b
        d = radial + 2.0 * y * y * slope + 6.0 * p1 * y + 2.0 * p2 * x
    fx, fy = intr[0], intr[1]
    # (x, y) by (X, Y, Z): (1/Z, 0, -x/Z) and (0, 1/Z, -y/Z)
    return (fx * a * iz, fx * b * iz, -fx * (a * x + b * y) * iz,
            fy * c * iz, fy * d * iz, -fy * (c * x + d * y) * iz)


@nb.njit(cache=True, fastmath=FASTMATH, nogil=True)
def pose_jacobian(s, model, intr, cfw, usable, free, J):  # pragma: no cover - compiled
    """The derivatives of every usable model point's pixel by the pose ``s`` (6,): ``J`` (M, 2, 6) = d(u, v) / d s,
    zero for a parameter not ``free`` (6,) and for a point not ``usable`` (M,) (:func:`project_pose`'s flags).
    Analytic: ``X = C R(s) p + C t + c`` (``C``, ``c`` the camera's rotation and origin), so d X / d t is a column of
    ``C`` and d X / d angle is ``C (d R / d angle) p``, each then through :func:`pinhole_derivatives`."""
    # R (geometry.rotation_entries) and its derivative by each angle, row-major
    rot = _rotation_entries(s[3], s[4], s[5])
    by_angle = _rotation_entry_derivatives(s[3], s[4], s[5])   # d R / d (roll, pitch, yaw)
    t0 = cfw[0, 0] * s[0] + cfw[0, 1] * s[1] + cfw[0, 2] * s[2] + cfw[0, 3]
    t1 = cfw[1, 0] * s[0] + cfw[1, 1] * s[1] + cfw[1, 2] * s[2] + cfw[1, 3]
    t2 = cfw[2, 0] * s[0] + cfw[2, 1] * s[1] + cfw[2, 2] * s[2] + cfw[2, 3]
    for m in range(model.shape[0]):
        for d in range(6):
            J[m, 0, d] = 0.0
            J[m, 1, d] = 0.0
        if not usable[m]:
            continue
        px, py, pz = model[m, 0], model[m, 1], model[m, 2]
        wx = rot[0] * px + rot[1] * py + rot[2] * pz   # R p
        wy = rot[3] * px + rot[4] * py + rot[5] * pz
        wz = rot[6] * px + rot[7] * py + rot[8] * pz
        X = cfw[0, 0] * wx + cfw[0, 1] * wy + cfw[0, 2] * wz + t0
        Y = cfw[1, 0] * wx + cfw[1, 1] * wy + cfw[1, 2] * wz + t1
        Z = cfw[2, 0] * wx + cfw[2, 1] * wy + cfw[2, 2] * wz + t2
        ux, uy, uz, vx, vy, vz = pinhole_derivatives(X, Y, Z, intr)
        for d in range(6):
            if not free[d]:
                continue
            if d < 3:   # d X / d position: column d of the camera's rotation
                gx, gy, gz = cfw[0, d], cfw[1, d], cfw[2, d]
            else:       # d X / d angle: C (d R / d angle) p
                e = by_angle[d - 3]
                ax = e[0] * px + e[1] * py + e[2] * pz
                ay = e[3] * px + e[4] * py + e[5] * pz
                az = e[6] * px + e[7] * py + e[8] * pz
                gx = cfw[0, 0] * ax + cfw[0, 1] * ay + cfw[0, 2] * az
                gy = cfw[1, 0] * ax + cfw[1, 1] * ay + cfw[1, 2] * az
                gz = cfw[2, 0] * ax + cfw[2, 1] * ay + cfw[2, 2] * az
            J[m, 0, d] = ux * gx + uy * gy + uz * gz
            J[m, 1, d] = vx * gx + vy * gy + vz * gz


@nb.njit(cache=True, fastmath=FASTMATH, nogil=True)
def project_poses(poses, model, normals, use_normals, intr, cfw):  # pragma: no cover - compiled
    """Project the model (M, 3) under every pose (N, 6): ``u``, ``v`` (N, M) pixels and ``usable`` (N, M)."""
    N = poses.shape[0]
    M = model.shape[0]
    u = np.empty((N, M))
    v = np.empty((N, M))
    usable = np.empty((N, M), np.bool_)
    R = np.empty((3, 3))
    Rc = np.empty((3, 3))
    for n in range(N):
        project_pose(poses[n], model, normals, use_normals, intr, cfw, u[n], v[n], usable[n], R, Rc)
    return u, v, usable
