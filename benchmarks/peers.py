"""The peers EvoPose is measured against, on the same problems.

* :func:`cma_solve` — IPOP-CMA-ES (pycma, ``cma.fmin2`` with restarts and doubling
  population) on the same fitness, the same search box and an evaluation budget; it
  starts from the same image-guided initial poses EvoPose draws (:func:`evopose.init.initial_poses`),
  which is more help than a generic optimiser usually gets.
* :func:`pnp_oracle` — OpenCV ``solvePnP`` given the *true* correspondences, which EvoPose
  never sees: the accuracy floor for the noise in the image points.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import cma
import cv2
import numpy as np

from evopose import PoseObjective
from evopose.fitness import FitnessKind
from evopose.init import initial_poses
from geometry import pose_from_matrix

from .problems import SyntheticProblem


@dataclass
class PeerResult:
    """A peer's answer: pose (6,) world_from_target, wall seconds, fitness evaluations (poses projected)."""

    pose: np.ndarray
    seconds: float
    evaluations: int


def cma_solve(sp: SyntheticProblem, *, budget: int, seed: int, fitness: FitnessKind = "robust") -> PeerResult:
    """IPOP-CMA-ES on eq. (4) with ``fitness``, at most ``budget`` evaluations over all restarts.

    Parameters are scaled to the unit cube of the search box; each restart begins at a fresh
    image-guided initial pose with step sizes of about a tenth of the target distance and 0.6 rad.
    """
    t0 = time.perf_counter()
    problem = sp.problem
    lo, hi = problem.bounds.lo, problem.bounds.hi
    width = np.where(hi > lo, hi - lo, 1.0)
    objective = PoseObjective(problem, fitness)
    rng = np.random.default_rng(seed)

    def to_pose(z: np.ndarray) -> np.ndarray:
        return lo + np.clip(z, 0.0, 1.0) * width

    def parallel(zs: list[np.ndarray]) -> list[float]:
        return list(objective(to_pose(np.asarray(zs))))

    def x0() -> np.ndarray:
        return (initial_poses(problem, 1, rng)[0] - lo) / width

    # step sizes from the image-guided guesses' distance to the first camera (never the true pose)
    guesses = initial_poses(problem, 16, rng)[:, :3]
    distance = float(np.median(np.linalg.norm(guesses - problem.views[0].camera.center_world, axis=1))) or 1.0
    stds = np.r_[[0.1 * distance] * 3, [0.6] * 3] / width
    options = {"bounds": [0.0, 1.0], "maxfevals": budget, "seed": seed + 1, "verbose": -9,
               "CMA_stds": list(stds), "tolfun": 1e-9, "tolx": 1e-9}
    _, es = cma.fmin2(None, x0, 1.0, options, restarts=9, incpopsize=2, parallel_objective=parallel)
    best = es.best.x if es.best.x is not None else x0()
    return PeerResult(to_pose(np.asarray(best)), time.perf_counter() - t0, objective.evaluations)


def pnp_oracle(sp: SyntheticProblem, view_index: int = 0) -> PeerResult:
    """``cv2.solvePnP`` on one view's true correspondences (SQPnP, or IPPE for a planar model), LM-refined."""
    t0 = time.perf_counter()
    view = sp.problem.views[view_index]
    model_idx, image_pts = sp.correspondences[view_index]
    obj = np.ascontiguousarray(sp.problem.model.points[model_idx], dtype=np.float64)
    img = np.ascontiguousarray(image_pts, dtype=np.float64)
    cam = view.camera
    planar = np.ptp(sp.problem.model.points[:, 2]) == 0.0
    flag = cv2.SOLVEPNP_IPPE if planar and len(obj) >= 4 else cv2.SOLVEPNP_SQPNP
    ok, rvec, tvec = cv2.solvePnP(obj, img, cam.matrix, cam.distortion, flags=flag)
    if not ok:
        ok, rvec, tvec = cv2.solvePnP(obj, img, cam.matrix, cam.distortion, flags=cv2.SOLVEPNP_ITERATIVE)
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, cam.matrix, cam.distortion, rvec, tvec)
    camera_from_target = np.eye(4)
    camera_from_target[:3, :3] = cv2.Rodrigues(rvec)[0]
    camera_from_target[:3, 3] = tvec.ravel()
    world_from_target = cam.world_from_camera @ camera_from_target
    return PeerResult(pose_from_matrix(world_from_target), time.perf_counter() - t0, 1)


def pnp_oracle_views(sp: SyntheticProblem) -> PeerResult:
    """The oracle over every view (eq. 4 with true correspondences): :func:`pnp_oracle` on the view with the most
    true marks, then Levenberg-Marquardt on the reprojection residuals of all views together."""
    from scipy.optimize import least_squares

    from evopose.fitness import project_into_view

    t0 = time.perf_counter()
    first = int(np.argmax([len(c[0]) for c in sp.correspondences]))
    start = pnp_oracle(sp, first).pose
    if len(sp.problem.views) == 1:
        return PeerResult(start, time.perf_counter() - t0, 1)
    model = sp.problem.model

    def residuals(s: np.ndarray) -> np.ndarray:
        out = []
        for view, (idx, pts) in zip(sp.problem.views, sp.correspondences):
            uv = project_into_view(model, view, s[None], use_normals=False).uv[0, idx]
            out.append((uv - pts).ravel())
        return np.concatenate(out)

    fit = least_squares(residuals, start, method="lm")
    return PeerResult(fit.x, time.perf_counter() - t0, int(fit.nfev))


__all__ = ["PeerResult", "cma_solve", "pnp_oracle", "pnp_oracle_views"]
