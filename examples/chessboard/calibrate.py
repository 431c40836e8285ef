"""Calibrate the camera of OpenCV's chessboard photographs and write a ROS ``camera_info`` YAML.

Run from the repository root: ``.venv/bin/python -m examples.chessboard.calibrate`` (writes
``examples/chessboard/camera_info.yaml``, committed). ``cv2.findChessboardCorners`` finds the 9 x 6 inner
corners of each photo, ``cv2.cornerSubPix`` refines them, ``cv2.calibrateCamera`` fits the intrinsics and the
plumb_bob distortion (k1, k2, p1, p2, k3). The square size (:data:`SQUARE`) only scales the boards' translations;
the intrinsics do not depend on it.
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
import yaml

HERE = Path(__file__).resolve().parent
IMAGES = HERE / "images"
#: Inner corners of the board: columns x rows (OpenCV's ``patternSize``).
PATTERN = (9, 6)
#: Assumed square side, metres (not published with the photographs; see README.md).
SQUARE = 0.025
SUBPIX = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)


def photos() -> list[Path]:
    """The photographs, in name order: left01.jpg ... left14.jpg (OpenCV ships no left10)."""
    return sorted(IMAGES.glob("left*.jpg"))


def board_points() -> np.ndarray:
    """The inner corners in OpenCV's board frame (origin at the first corner, x along a row, z = 0), (54, 3)."""
    cols, rows = PATTERN
    grid = np.zeros((rows * cols, 3), np.float32)
    grid[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * SQUARE
    return grid


def ordered_corners(image: np.ndarray) -> np.ndarray | None:
    """findChessboardCorners' ordered corners refined by cornerSubPix, (54, 2), or None if the board is not found."""
    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    found, corners = cv2.findChessboardCorners(grey, PATTERN)
    if not found:
        return None
    return cv2.cornerSubPix(grey, corners, (11, 11), (-1, -1), SUBPIX).reshape(-1, 2)


def calibrate(paths: list[Path]) -> tuple[float, np.ndarray, np.ndarray, tuple[int, int]]:
    """RMS reprojection error (px), K (3, 3), distortion (5,) and image size (w, h) from the photos."""
    object_points, image_points, size = [], [], None
    for path in paths:
        image = cv2.imread(str(path))
        size = (image.shape[1], image.shape[0])
        corners = ordered_corners(image)
        if corners is not None:
            object_points.append(board_points())
            image_points.append(corners.astype(np.float32))
    rms, k, dist, _, _ = cv2.calibrateCamera(object_points, image_points, size, None, None)
    return float(rms), k, dist.reshape(-1)[:5], size


def camera_info(k: np.ndarray, dist: np.ndarray, size: tuple[int, int], name: str = "left") -> dict:
    """The ROS camera_info mapping (camera_calibration_parsers' YAML layout) of a monocular camera."""
    projection = np.hstack([k, np.zeros((3, 1))])

    def matrix(m: np.ndarray) -> dict:
        m = np.atleast_2d(m)
        return {"rows": int(m.shape[0]), "cols": int(m.shape[1]), "data": [round(float(v), 6) for v in m.ravel()]}

    return {"image_width": size[0], "image_height": size[1], "camera_name": name, "camera_matrix": matrix(k),
            "distortion_model": "plumb_bob", "distortion_coefficients": matrix(dist.reshape(1, 5)),
            "rectification_matrix": matrix(np.eye(3)), "projection_matrix": matrix(projection)}


def main(out: Path = HERE / "camera_info.yaml") -> None:
    rms, k, dist, size = calibrate(photos())
    text = yaml.safe_dump(camera_info(k, dist, size), sort_keys=False, default_flow_style=None)
    header = (f"# Written by examples/chessboard/calibrate.py from {len(photos())} photographs "
              f"(cv2.calibrateCamera, RMS reprojection error {rms:.3f} px).\n")
    out.write_text(header + text, encoding="utf-8")
    print(f"{out}: fx {k[0, 0]:.2f} fy {k[1, 1]:.2f} cx {k[0, 2]:.2f} cy {k[1, 2]:.2f}, RMS {rms:.3f} px")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else HERE / "camera_info.yaml")
