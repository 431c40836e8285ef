"""Camera files: ROS ``camera_info`` YAML (camera_calibration_parsers) or a ``sensor_msgs/msg/CameraInfo`` message,
the problem file's camera, a camera pose.

A ROS calibration file, as ``camera_calibration`` and ``camera_calibration_parsers`` write it::

    image_width: 640
    image_height: 480
    camera_name: left
    camera_matrix: {rows: 3, cols: 3, data: [fx, 0, cx, 0, fy, cy, 0, 0, 1]}
    distortion_model: plumb_bob
    distortion_coefficients: {rows: 1, cols: 5, data: [k1, k2, p1, p2, k3]}
    rectification_matrix: {rows: 3, cols: 3, data: [1, 0, 0, 0, 1, 0, 0, 0, 1]}
    projection_matrix: {rows: 3, cols: 4, data: [...]}

EvoPose projects raw (unrectified) image points through ``K`` and the plumb_bob coefficients, so the
rectification and projection matrices are checked for shape and otherwise unused (they describe the rectified
image of a stereo pair). Every file is read by the project's one bounded reader
(:func:`scenarios.documents.read_mapping`) and a bad field is one :class:`ProblemFileError` line.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from evopose import Camera
from scenarios.camera_info_file import CameraInfoSpec, MatrixSpec
from scenarios.documents import FullPoseSpec, read_mapping, validate

from agents.problem.problem_file import CameraSpec, ProblemFileError

def is_camera_info(document: dict[str, Any]) -> bool:
    """Whether a camera file's mapping is a ROS ``camera_info`` (it names ``camera_matrix``)."""
    return "camera_matrix" in document


def read_camera_info(path: str | Path) -> Camera:
    """The camera of a ROS ``camera_info`` YAML file, world frame = camera frame.

    Raises
    ------
    ProblemFileError
        One line naming the file and the offending field.
    """
    document = read_mapping(path, ProblemFileError)
    return validate(CameraInfoSpec, document, path, ProblemFileError).to_camera()


def camera_info_document(message: Any) -> dict[str, Any]:
    """The calibration-file mapping of a ``sensor_msgs/msg/CameraInfo`` message (any object with its fields ``width,
    height, distortion_model, d, k, r, p``), so that a message is checked exactly as a file is.

    An empty ``d`` is no distortion (uncalibrated or rectified cameras publish ``d = []``, often with an empty
    model); otherwise the model and its coefficients are taken as sent and must be plumb_bob's five.
    """
    d = [float(v) for v in np.asarray(message.d, float).reshape(-1)]
    document: dict[str, Any] = {
        "image_width": int(message.width), "image_height": int(message.height),
        "camera_matrix": {"rows": 3, "cols": 3, "data": [float(v) for v in np.asarray(message.k, float).reshape(-1)]},
        "distortion_model": str(message.distortion_model) if d or message.distortion_model else "plumb_bob",
        "rectification_matrix": {"rows": 3, "cols": 3, "data": [float(v) for v in np.asarray(message.r).reshape(-1)]},
        "projection_matrix": {"rows": 3, "cols": 4, "data": [float(v) for v in np.asarray(message.p).reshape(-1)]}}
    if d:
        document["distortion_coefficients"] = {"rows": 1, "cols": len(d), "data": d}
    return document


def camera_from_camera_info_message(message: Any, name: str) -> Camera:
    """The camera of a ``sensor_msgs/msg/CameraInfo`` message, world frame = camera frame; ``name`` (the topic)
    begins the error line. A non-zero ``d`` is kept as the camera's plumb_bob distortion: EvoPose projects the model
    through it onto the raw image, as with a calibration file (the image points are not undistorted).

    Raises
    ------
    ProblemFileError
        One line naming the offending field (``camera_matrix: fx and fy must be > 0`` for an uncalibrated camera's
        zero ``k``).
    """
    return validate(CameraInfoSpec, camera_info_document(message), name, ProblemFileError).to_camera()


def read_camera_file(path: str | Path) -> Camera:
    """A camera file in either format: ROS ``camera_info`` (when it has ``camera_matrix``) or the problem
    file's camera (``fx, fy, cx, cy, width, height``, optional ``distortion`` and ``world_from_camera``).

    Raises
    ------
    ProblemFileError
        One line naming the file and the offending field.
    """
    document = read_mapping(path, ProblemFileError)
    if is_camera_info(document):
        return validate(CameraInfoSpec, document, path, ProblemFileError).to_camera()
    return validate(CameraSpec, document, path, ProblemFileError).to_camera()


def read_camera_pose(path: str | Path) -> np.ndarray:
    """A static ``world_from_camera`` ``(x, y, z, roll, pitch, yaw)``, shape (6,), metres and radians: the
    problem file's ``world_from_camera`` fields at the top level of a YAML/JSON file.

    Raises
    ------
    ProblemFileError
        One line naming the file and the offending field.
    """
    return validate(FullPoseSpec, read_mapping(path, ProblemFileError), path, ProblemFileError).vector()


__all__ = ["CameraInfoSpec", "MatrixSpec", "camera_from_camera_info_message", "camera_info_document", "is_camera_info",
           "read_camera_file", "read_camera_info", "read_camera_pose"]
