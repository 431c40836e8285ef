"""What the live view draws, as pure functions: frustum lines, the target model as triangles and spheres, model
points projected into a camera, pose errors, a blank PNG canvas (foxglove message objects are built in ``view``).

Frames and poses follow docs/design.md §2 (``world_from_target``, ``R = Rz Ry Rx``, the OpenCV optical frame).
"""

from __future__ import annotations

import math
import struct
import zlib
from functools import cache

import numpy as np

from agents.bridges.ros_msgs import matrix_from_rpy
from geometry import rotation_error


def frustum_lines(camera, depth: float) -> np.ndarray:
    """Line-list segments (pairs of points, shape (16, 3)) of the camera's view pyramid to ``depth`` metres, in its
    optical frame: apex to the four image corners, and the far rectangle."""
    corners = [((u - camera.cx) / camera.fx * depth, (v - camera.cy) / camera.fy * depth, depth)
               for u, v in ((0, 0), (camera.width, 0), (camera.width, camera.height), (0, camera.height))]
    segments = []
    for i, corner in enumerate(corners):
        segments += [(0.0, 0.0, 0.0), corner, corner, corners[(i + 1) % 4]]
    return np.array(segments)


def mesh_triangles(vertices: np.ndarray, faces, colours: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fan-triangulate convex faces: ``(points (3T, 3), rgba per point (3T, 4), 0-1)`` from BGR 0-255 colours."""
    points, rgba = [], []
    for face, bgr in zip(faces, colours):
        colour = (bgr[2] / 255.0, bgr[1] / 255.0, bgr[0] / 255.0, 1.0)
        for k in range(1, len(face) - 1):
            points += [vertices[face[0]], vertices[face[k]], vertices[face[k + 1]]]
            rgba += [colour] * 3
    return np.array(points, dtype=float).reshape(-1, 3), np.array(rgba, dtype=float).reshape(-1, 4)


def project(points_target: np.ndarray, world_from_target, camera) -> np.ndarray:
    """Pixels ``(N, 2)`` of model points seen by ``camera`` (plumb_bob); points behind it are dropped."""
    r_wt, t_wt = matrix_from_rpy(*world_from_target[3:6]), np.asarray(world_from_target[:3], dtype=float)
    pose_c = camera.world_from_camera
    r_wc, t_wc = matrix_from_rpy(*pose_c[3:6]), np.asarray(pose_c[:3], dtype=float)
    p = (np.asarray(points_target, dtype=float) @ r_wt.T + t_wt - t_wc) @ r_wc
    p = p[p[:, 2] > 1e-6]
    x, y = p[:, 0] / p[:, 2], p[:, 1] / p[:, 2]
    k1, k2, p1, p2, k3 = camera.distortion
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([camera.fx * xd + camera.cx, camera.fy * yd + camera.cy], axis=1)


def pose_errors(estimate, truth) -> tuple[float, float]:
    """``(position error m, rotation error deg)`` between two ``world_from_target`` poses (no model symmetry)."""
    position = float(np.linalg.norm(np.subtract(estimate[:3], truth[:3])))
    return position, math.degrees(float(rotation_error(estimate, truth)))


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


@cache
def blank_png(width: int, height: int, grey: int = 48) -> bytes:
    """A uniform 8-bit greyscale PNG, the canvas feature points are drawn on when no image is shared."""
    rows = (b"\x00" + bytes([grey]) * width) * height
    header = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header) + _chunk(b"IDAT", zlib.compress(rows, 9))
            + _chunk(b"IEND", b""))
