"""The image-guided starts' moment match, compiled: each start's position moved so that its projected model covers
the image points (:func:`evopose.init.align_to_view`, which draws the targets and calls this).

A weak-perspective match per pose (its attitude kept): the lower median of the usable projected model points'
``u`` and ``v`` is shifted onto the target centre, and the depth of the model's centroid scaled by the projected
spread (the lower median distance to that centre) over the target spread; ``iterations`` times, as the projection
moves. A pose with fewer than two usable points, a spread of half a pixel or less, or its centroid behind the camera
is left where it is. The arithmetic is that of the NumPy formulation it replaced (tests/test_align_kernel.py holds it
as the reference); a search makes 400-800 starts a generation, and array operations on them cost more than their
arithmetic (1.9 ms a generation against 0.6 ms compiled, BENCHMARKS.md "Where a solve's time goes").

Array conventions as :mod:`evopose.projection`'s; ``wfc`` (4, 4) is ``world_from_camera`` (the inverse of ``cfw``).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .kernel_abi import FASTMATH
from .projection import project_pose, rotation_into


@nb.njit(cache=True, fastmath=FASTMATH, nogil=True)
def _lower_median(values, n):  # pragma: no cover - compiled
    """The lower median of ``values[:n]`` (n >= 1), sorting them in place (insertion: a model's tens of points, no
    allocation)."""
    for i in range(1, n):
        x = values[i]
        j = i - 1
        while j >= 0 and values[j] > x:
            values[j + 1] = values[j]
            j -= 1
        values[j + 1] = x
    return values[(n - 1) // 2]


@nb.njit(cache=True, fastmath=FASTMATH, nogil=True)
def align_positions(poses, model, normals, use_normals, intr, cfw, wfc, centroid, target_centre, target_spread,
                    iterations):  # pragma: no cover - compiled
    """Move each pose's position (``poses`` (N, 6), written in place) so its projection's robust centre lies at
    ``target_centre`` (N, 2) pixels and its robust spread is ``target_spread`` (N,) pixels; ``centroid`` (3,) is the
    model's centroid in the target frame, kept on the ray through the new centre."""
    N = poses.shape[0]
    M = model.shape[0]
    u = np.empty(M)
    v = np.empty(M)
    usable = np.empty(M, np.bool_)
    buf = np.empty(M)
    R = np.empty((3, 3))
    scratch_r = np.empty((3, 3))
    scratch_rc = np.empty((3, 3))
    fx, fy, cx, cy = intr[0], intr[1], intr[2], intr[3]
    for n in range(N):
        rotation_into(poses[n, 3], poses[n, 4], poses[n, 5], R)
        rcx = R[0, 0] * centroid[0] + R[0, 1] * centroid[1] + R[0, 2] * centroid[2]
        rcy = R[1, 0] * centroid[0] + R[1, 1] * centroid[1] + R[1, 2] * centroid[2]
        rcz = R[2, 0] * centroid[0] + R[2, 1] * centroid[1] + R[2, 2] * centroid[2]
        for _ in range(iterations):
            project_pose(poses[n], model, normals, use_normals, intr, cfw, u, v, usable, scratch_r, scratch_rc)
            count = 0
            for m in range(M):
                if usable[m]:
                    buf[count] = u[m]
                    count += 1
            if count < 2:
                break  # the pose does not move, so the next iteration would see the same
            cu = _lower_median(buf, count)
            count = 0
            for m in range(M):
                if usable[m]:
                    buf[count] = v[m]
                    count += 1
            cv = _lower_median(buf, count)
            count = 0
            for m in range(M):
                if usable[m]:
                    buf[count] = np.sqrt((u[m] - cu) ** 2 + (v[m] - cv) ** 2)
                    count += 1
            spread = _lower_median(buf, count)
            wx, wy, wz = poses[n, 0] + rcx, poses[n, 1] + rcy, poses[n, 2] + rcz
            z = cfw[2, 0] * wx + cfw[2, 1] * wy + cfw[2, 2] * wz + cfw[2, 3]
            if not (spread > 0.5 and z > 0.0):
                break
            x = cfw[0, 0] * wx + cfw[0, 1] * wy + cfw[0, 2] * wz + cfw[0, 3]
            y = cfw[1, 0] * wx + cfw[1, 1] * wy + cfw[1, 2] * wz + cfw[1, 3]
            new_u = target_centre[n, 0] + (fx * x / z + cx - cu)
            new_v = target_centre[n, 1] + (fy * y / z + cy - cv)
            new_z = z * spread / target_spread[n]
            px, py = (new_u - cx) / fx * new_z, (new_v - cy) / fy * new_z
            poses[n, 0] = wfc[0, 0] * px + wfc[0, 1] * py + wfc[0, 2] * new_z + wfc[0, 3] - rcx
            poses[n, 1] = wfc[1, 0] * px + wfc[1, 1] * py + wfc[1, 2] * new_z + wfc[1, 3] - rcy
            poses[n, 2] = wfc[2, 0] * px + wfc[2, 1] * py + wfc[2, 2] * new_z + wfc[2, 3] - rcz


__all__ = ["align_positions"]
