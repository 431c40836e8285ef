"""EvoPose on OpenCV's chessboard photographs without correspondences, against cv2.solvePnP as the oracle.

Run from the repository root: ``.venv/bin/python -m examples.chessboard.compare [--seeds 0,1,2]``. Per photo:

- **EvoPose**: exactly what ``evopose solve --image left01.jpg --model examples/chessboard/board.yaml --camera
  examples/chessboard/camera_info.yaml --features corners`` does (:func:`agents.problem.solve.solve_image`):
  Shi-Tomasi corners, the X-junctions kept, unordered and unlabelled, searched against the 54-corner board model;
- **oracle**: ``cv2.solvePnP`` on ``cv2.findChessboardCorners``' *ordered* corners (refined by cornerSubPix) with the
  same calibration: it knows which corner is which, EvoPose does not.

The board's inner corners map onto themselves under a half turn about its normal, so rotations are compared
modulo that symmetry; the translation is the board centre's (the model's origin), which the half turn keeps.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

from agents.problem.camera_info import read_camera_info
from agents.problem.solve import solve_image
from geometry import PARAM_NAMES, pose_from_matrix, rotation_angle, rotation_from_euler

from examples.chessboard.calibrate import HERE, PATTERN, SQUARE, board_points, ordered_corners, photos

BOARD = HERE / "board.yaml"
CAMERA = HERE / "camera_info.yaml"
#: OpenCV's board frame (origin at the first corner) -> the board model's (its centre), metres.
CENTRE = np.array([(PATTERN[0] - 1) / 2 * SQUARE, (PATTERN[1] - 1) / 2 * SQUARE, 0.0])
HALF_TURN = rotation_from_euler(np.array([0.0, 0.0, np.pi]))


def oracle_pose(image: np.ndarray) -> np.ndarray | None:
    """``camera_from_board`` (x, y, z, roll, pitch, yaw) of the board's centre by cv2.solvePnP, or None."""
    corners = ordered_corners(image)
    if corners is None:
        return None
    camera = read_camera_info(CAMERA)
    ok, rvec, tvec = cv2.solvePnP(board_points(), corners, camera.matrix, camera.distortion)
    if not ok:
        return None
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = cv2.Rodrigues(rvec)[0], tvec.ravel()
    shift = np.eye(4)
    shift[:3, 3] = CENTRE
    return pose_from_matrix(T @ shift)


def differences(estimate: np.ndarray, oracle: np.ndarray) -> tuple[float, float]:
    """Rotation difference (deg, modulo the half turn) and distance between the board centres (mm)."""
    R_est, R_ref = rotation_from_euler(estimate[3:]), rotation_from_euler(oracle[3:])
    angles = [rotation_angle(R_est, R_ref @ S) for S in (np.eye(3), HALF_TURN)]
    return float(np.degrees(min(angles))), float(np.linalg.norm(estimate[:3] - oracle[:3]) * 1000)


def compare(path: Path, seed: int) -> dict:
    """One photo: EvoPose's pose, the oracle's, their differences, EvoPose's verdict and time."""
    oracle = oracle_pose(cv2.imread(str(path)))
    result = solve_image(path, BOARD, CAMERA, seed=seed, features="corners")
    estimate = np.array([result["pose"][n] for n in PARAM_NAMES])
    rot, pos = differences(estimate, oracle)
    return {"image": path.name, "seed": seed, "rotation_deg": rot, "translation_mm": pos,
            "distance_mm": float(np.linalg.norm(oracle[:3]) * 1000), "confident": result["confident"],
            "seconds": result["seconds"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0", help="comma-separated search seeds")
    seeds = [int(s) for s in parser.parse_args().seeds.split(",")]
    rows = [compare(path, seed) for seed in seeds for path in photos()]
    print("| image | seed | rotation diff (deg) | translation diff (mm) | board distance (mm) | confident | s |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['image']} | {r['seed']} | {r['rotation_deg']:.2f} | {r['translation_mm']:.1f} | "
              f"{r['distance_mm']:.0f} | {'yes' if r['confident'] else 'no'} | {r['seconds']:.2f} |")
    rot = np.array([r["rotation_deg"] for r in rows])
    pos = np.array([r["translation_mm"] for r in rows])
    print(f"\n{len(rows)} solves: rotation diff median {np.median(rot):.2f} deg, max {rot.max():.2f} deg; "
          f"translation diff < 1 mm on {np.count_nonzero(pos < 1)}, 24-26 mm (one square) on "
          f"{np.count_nonzero((pos > 24) & (pos < 26))}, other {np.count_nonzero((pos >= 1) & ~((pos > 24) & (pos < 26)))}")


if __name__ == "__main__":
    main()
