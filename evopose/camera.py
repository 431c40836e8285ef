"""Pinhole cameras with OpenCV ``plumb_bob`` distortion, projecting whole populations at once.

Frames (docs/design.md §2): the camera uses the OpenCV optical frame (x right, y down,
z forward); its extrinsic is ``world_from_camera``. A candidate pose is
``world_from_target``, so a model point reaches the image through
``camera_from_target = inv(world_from_camera) @ world_from_target``. The pixels come from the one
compiled projection (:mod:`evopose.projection`), which the fitness and the refinement use too.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from geometry import invert_transform, matrix_from_pose

from .kernel_abi import FAR_AWAY_PX, MIN_DEPTH
from .kernel_backend import project_points, project_poses

__all__ = ["Camera", "FAR_AWAY_PX", "MIN_DEPTH"]


@dataclass(frozen=True, eq=False)
class Camera:
    """A calibrated camera.

    Attributes
    ----------
    fx, fy, cx, cy : float
        Intrinsics in pixels.
    width, height : int
        Image size in pixels.
    distortion : array, shape (5,)
        OpenCV plumb_bob ``[k1, k2, p1, p2, k3]``.
    world_from_camera : array, shape (4, 4)
        Extrinsic transform; identity means the world frame is this camera's frame (paper Fig. 1).
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int = 640
    height: int = 480
    distortion: np.ndarray = field(default_factory=lambda: np.zeros(5))
    world_from_camera: np.ndarray = field(default_factory=lambda: np.eye(4))

    def __post_init__(self) -> None:
        for name in ("fx", "fy"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"camera.{name} must be a positive finite number, got {value}")
        for name in ("cx", "cy"):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"camera.{name} must be finite")
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"camera width/height must be positive, got {self.width}x{self.height}")
        dist = np.asarray(self.distortion, dtype=float).reshape(-1)
        if dist.shape != (5,) or not np.all(np.isfinite(dist)):
            raise ValueError(f"camera.distortion must be 5 finite numbers [k1, k2, p1, p2, k3], got shape {dist.shape}")
        w_from_c = np.asarray(self.world_from_camera, dtype=float)
        if w_from_c.shape != (4, 4) or not np.all(np.isfinite(w_from_c)):
            raise ValueError(f"camera.world_from_camera must be a finite 4x4 transform, got shape {w_from_c.shape}")
        object.__setattr__(self, "distortion", dist)
        object.__setattr__(self, "world_from_camera", w_from_c)
        object.__setattr__(self, "_camera_from_world", invert_transform(w_from_c))
        intrinsics = np.array([self.fx, self.fy, self.cx, self.cy, *dist], float)
        intrinsics.flags.writeable = False
        object.__setattr__(self, "_intrinsics", intrinsics)

    @classmethod
    def from_pose(cls, fx: float, fy: float, cx: float, cy: float, width: int = 640, height: int = 480,
                  distortion=None, world_from_camera_pose=None) -> "Camera":
        """Build a camera whose extrinsic is given as a 6-vector ``(x, y, z, roll, pitch, yaw)``."""
        w_from_c = np.eye(4) if world_from_camera_pose is None else matrix_from_pose(world_from_camera_pose)
        dist = np.zeros(5) if distortion is None else np.asarray(distortion, float)
        return cls(fx, fy, cx, cy, width, height, dist, w_from_c)

    @property
    def camera_from_world(self) -> np.ndarray:
        """Inverse extrinsic, shape (4, 4)."""
        return self._camera_from_world  # type: ignore[attr-defined]

    @property
    def intrinsics(self) -> np.ndarray:
        """``(fx, fy, cx, cy, k1, k2, p1, p2, k3)``, shape (9,), read-only: what the compiled projection takes."""
        return self._intrinsics  # type: ignore[attr-defined]

    @property
    def matrix(self) -> np.ndarray:
        """OpenCV intrinsic matrix K, shape (3, 3)."""
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])

    @property
    def center_world(self) -> np.ndarray:
        """Optical centre in the world frame, shape (3,)."""
        return self.world_from_camera[:3, 3].copy()

    def to_camera_frame(self, poses: np.ndarray, points_target: np.ndarray) -> np.ndarray:
        """Model points of every candidate pose in this camera's optical frame.

        Parameters
        ----------
        poses : array, shape (N, 6)
            ``world_from_target`` candidates.
        points_target : array, shape (M, 3)

        Returns
        -------
        array, shape (N, M, 3)
        """
        camera_from_target = self.camera_from_world @ matrix_from_pose(np.atleast_2d(poses))
        R, t = camera_from_target[:, :3, :3], camera_from_target[:, :3, 3]
        return np.matmul(points_target, np.swapaxes(R, 1, 2)) + t[:, None, :]

    def project_camera_points(self, p_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project points given in the optical frame.

        Parameters
        ----------
        p_cam : array, shape (..., 3)

        Returns
        -------
        uv : array, shape (..., 2)
            Pixels; points with depth below :data:`MIN_DEPTH` get :data:`FAR_AWAY_PX`.
        in_front : bool array, shape (...)
        """
        p_cam = np.asarray(p_cam, dtype=float)
        flat = np.ascontiguousarray(p_cam.reshape(-1, 3))
        uv, in_front = project_points(flat, self.intrinsics)
        return uv.reshape(p_cam.shape[:-1] + (2,)), in_front.reshape(p_cam.shape[:-1])

    def project_population(self, poses: np.ndarray, points_target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project the model under every candidate pose.

        Parameters
        ----------
        poses : array, shape (N, 6)
        points_target : array, shape (M, 3)

        Returns
        -------
        uv : array, shape (N, M, 2)
        in_front : bool array, shape (N, M)
        """
        poses = np.ascontiguousarray(np.atleast_2d(np.asarray(poses, dtype=float)))
        model = np.ascontiguousarray(np.asarray(points_target, dtype=float))
        u, v, in_front = project_poses(poses, model, np.zeros((1, 3)), False, self.intrinsics,
                                       np.ascontiguousarray(self.camera_from_world))
        return np.stack([u, v], axis=-1), in_front

    def project_world(self, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project world points, shape (K, 3) -> uv (K, 2), in_front (K,)."""
        pw = np.asarray(points_world, float)
        p_cam = pw @ self.camera_from_world[:3, :3].T + self.camera_from_world[:3, 3]
        return self.project_camera_points(p_cam)

    def in_image(self, uv: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Whether pixels lie inside the image (with an optional margin), shape (..., 2) -> (...)."""
        return ((uv[..., 0] >= -margin) & (uv[..., 0] < self.width + margin)
                & (uv[..., 1] >= -margin) & (uv[..., 1] < self.height + margin))
