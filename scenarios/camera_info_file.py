"""ROS camera calibration files (``camera_info`` YAML, camera_calibration_parsers' format, plumb_bob): one schema for
every reader (the agents' ``--camera-info``, a rendered dataset's cameras) and the writer of a camera's file.

EvoPose projects raw (unrectified) image points through ``K`` and the plumb_bob coefficients, so the rectification
and projection matrices are checked for shape and otherwise unused.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Field, model_validator

from evopose import Camera

from .documents import Spec

#: Largest image side accepted, pixels (as the scenarios' intrinsics).
MAX_SIDE = 8192
#: How far ``camera_matrix`` may be from the pinhole form ``[fx 0 cx; 0 fy cy; 0 0 1]`` (the skew and the
#: last row), in its own units: calibration tools write exact zeros and ones.
PINHOLE_TOLERANCE = 1e-9


class MatrixSpec(Spec):
    """A ROS matrix: ``rows`` x ``cols`` numbers in ``data``, row-major."""

    rows: Annotated[int, Field(gt=0, le=16)]
    cols: Annotated[int, Field(gt=0, le=16)]
    data: Annotated[list[float], Field(min_length=1, max_length=256)]

    @model_validator(mode="after")
    def _size(self) -> "MatrixSpec":
        if len(self.data) != self.rows * self.cols:
            raise ValueError(f"data: expected rows x cols = {self.rows * self.cols} numbers, got {len(self.data)}")
        return self

    def shaped(self, rows: int, cols: int, name: str) -> np.ndarray:
        """The matrix as an array (rows, cols); a different shape is an error naming ``name``."""
        if (self.rows, self.cols) != (rows, cols):
            raise ValueError(f"{name}: expected a {rows}x{cols} matrix, got {self.rows}x{self.cols}")
        return np.array(self.data, float).reshape(rows, cols)


class CameraInfoSpec(Spec):
    """A ROS ``camera_info`` calibration file (``sensor_msgs/CameraInfo`` fields, camera_calibration_parsers)."""

    image_width: Annotated[int, Field(gt=0, le=MAX_SIDE)]
    image_height: Annotated[int, Field(gt=0, le=MAX_SIDE)]
    camera_name: str = ""
    camera_matrix: MatrixSpec
    distortion_model: Literal["plumb_bob"] = "plumb_bob"
    distortion_coefficients: MatrixSpec | None = None
    rectification_matrix: MatrixSpec | None = None
    projection_matrix: MatrixSpec | None = None

    @model_validator(mode="after")
    def _pinhole(self) -> "CameraInfoSpec":
        k = self.camera_matrix.shaped(3, 3, "camera_matrix")
        if k[0, 0] <= 0 or k[1, 1] <= 0:
            raise ValueError(f"camera_matrix: fx and fy must be > 0, got {k[0, 0]:g} and {k[1, 1]:g}")
        off = np.abs(np.array([k[0, 1], k[1, 0], k[2, 0], k[2, 1], k[2, 2] - 1.0]))
        if np.any(off > PINHOLE_TOLERANCE):
            raise ValueError("camera_matrix: expected [fx, 0, cx, 0, fy, cy, 0, 0, 1] (no skew), got "
                             f"[{', '.join(f'{v:g}' for v in k.ravel())}]")
        if self.distortion_coefficients is not None:
            d = self.distortion_coefficients
            if min(d.rows, d.cols) != 1 or len(d.data) != 5:
                raise ValueError(f"distortion_coefficients: plumb_bob has 5 coefficients [k1, k2, p1, p2, k3] "
                                 f"in 1 row, got {d.rows}x{d.cols}")
        if self.rectification_matrix is not None:
            self.rectification_matrix.shaped(3, 3, "rectification_matrix")
        if self.projection_matrix is not None:
            self.projection_matrix.shaped(3, 4, "projection_matrix")
        return self

    def to_camera(self, world_from_camera: np.ndarray | None = None) -> Camera:
        """The camera (intrinsics and distortion) with ``world_from_camera`` (4, 4), identity by default."""
        k = np.array(self.camera_matrix.data, float).reshape(3, 3)
        dist = np.zeros(5) if self.distortion_coefficients is None else np.array(self.distortion_coefficients.data)
        return Camera(k[0, 0], k[1, 1], k[0, 2], k[1, 2], self.image_width, self.image_height, dist,
                      np.eye(4) if world_from_camera is None else world_from_camera)


def calibration_document(camera: Camera, name: str = "") -> dict[str, Any]:
    """The ROS calibration-file mapping (camera_calibration_parsers' keys) of a camera's intrinsics: ``K``, plumb_bob
    ``D``, identity ``R`` and ``P = [K | 0]`` (a monocular, unrectified camera)."""
    fx, fy, cx, cy = (float(v) for v in (camera.fx, camera.fy, camera.cx, camera.cy))
    return {"image_width": int(camera.width), "image_height": int(camera.height), "camera_name": name,
            "camera_matrix": {"rows": 3, "cols": 3, "data": [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0]},
            "distortion_model": "plumb_bob",
            "distortion_coefficients": {"rows": 1, "cols": 5,
                                        "data": [float(v) for v in np.asarray(camera.distortion).reshape(5)]},
            "rectification_matrix": {"rows": 3, "cols": 3, "data": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]},
            "projection_matrix": {"rows": 3, "cols": 4,
                                  "data": [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0]}}


__all__ = ["CameraInfoSpec", "MatrixSpec", "calibration_document"]
