"""Local refinement of candidate poses: annealed soft matching (EM-ICP) then hard matching (ICP).

Each step linearises the projection (finite-difference Jacobian, whole population at once)
and takes one damped Gauss–Newton step on reprojection residuals between projected model
points and image points:

* ``soft`` steps weigh every pair by ``exp(-d^2 / 2 sigma^2)``, normalised per image
  point and per model point with an outlier slack (EM-ICP, in the spirit of SoftPOSIT).
  ``sigma`` shrinks from about the feature spacing to a fraction of it, which widens the
  basin of attraction far beyond that of nearest-neighbour matching;
* ``hard`` steps match nearest neighbours in both directions (the two terms of the
  robust fitness) within a gate and only accept steps that lower the fitness.

Fixed parameters (eq. 3 with zero tolerance) never move, and every step is projected
back into the search box, so eq. (3) holds throughout. The result is never worse than
the input (per individual, by the objective's fitness).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from .fitness import PoseObjective, project_into_view
from .kernels import accumulate_normal_equations, accumulate_soft_normal_equations

#: Finite-difference steps for the Jacobian: metres for x, y, z; radians for the angles.
FD_STEP = np.array([1e-5, 1e-5, 1e-5, 1e-6, 1e-6, 1e-6])
#: Outlier slack of the soft matching: a pair at 2.5 sigma weighs as much as "no match".
SOFT_OUTLIER = float(np.exp(-0.5 * 2.5**2))
#: Soft kernel width at the start of annealing, as a fraction of the view's image spread,
#: and at its end, as a fraction of tau.
SIGMA_START, SIGMA_END = 0.5, 0.5


SOFT_CFG = {"normals": True, "img": 0.5, "mod": 0.5}


def _normal_equations(objective: PoseObjective, poses: np.ndarray, kind: str, scale: float):
    """``H = sum w J^T J`` (N, 6, 6) and ``g = sum w J^T r`` (N, 6) over the weighted views."""
    N = len(poses)
    free = objective.problem.bounds.free
    H = np.zeros((N, 6, 6))
    g = np.zeros((N, 6))
    eye = np.eye(6)
    perturbed = np.concatenate([poses] + [poses + FD_STEP[d] * eye[d] for d in range(6)])
    model = objective.problem.model
    for k, view in enumerate(objective.problem.views):
        w_view = objective.weights[k]
        if w_view == 0:
            continue
        proj = project_into_view(model, view, perturbed, use_normals=objective.kind == "robust" and SOFT_CFG["normals"] if kind=="soft" else objective.kind == "robust")
        uv_all = proj.uv.reshape(7, N, -1, 2)
        uv, usable = uv_all[0], proj.usable[:N]
        J = np.stack([(uv_all[1 + d] - uv) / FD_STEP[d] for d in range(6)], axis=-1)  # (N, M, 2, 6)
        J[..., ~free] = 0.0
        px = np.ascontiguousarray(view.points[:, 0])
        py = np.ascontiguousarray(view.points[:, 1])
        tau = float(objective.taus[k])
        if kind == "soft":
            sigma = soft_sigma(objective.spreads[k], tau, scale)
            accumulate_soft_normal_equations(np.ascontiguousarray(uv), J, usable, px, py, sigma,
                                             SOFT_OUTLIER, SOFT_CFG["img"]*float(w_view), SOFT_CFG["mod"]*float(w_view), H, g)
        else:
            accumulate_normal_equations(np.ascontiguousarray(uv), J, usable, px, py, (scale * tau) ** 2,
                                        float(w_view), H, g)
    return H, g


def soft_sigma(spread: float, tau: float, t: float) -> float:
    """Kernel width at annealing time ``t`` in [0, 1]: geometric from half the view's spread to tau / 2."""
    start = max(SIGMA_START * spread, SIGMA_END * tau)
    return float(start * (SIGMA_END * tau / start) ** t)


def annealing(steps: int, hard: int = 2) -> tuple[tuple[str, float], ...]:
    """A schedule of ``steps`` soft steps from wide to narrow, then ``hard`` polishing steps."""
    return tuple(("soft", float(t)) for t in np.linspace(0.0, 1.0, steps)) + (("hard", 1.0),) * hard


def _damped_step(H: np.ndarray, g: np.ndarray, lam: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Levenberg–Marquardt step ``-(H + lam diag(H))^-1 g`` with fixed parameters held, (N, 6)."""
    diag = np.einsum("nii->ni", H)
    A = H + (lam[:, None] * diag + 1e-12)[:, :, None] * np.eye(6)
    A[:, ~free, :] = 0.0
    A[:, :, ~free] = 0.0
    A[:, ~free, ~free] = 1.0
    g = np.where(free, g, 0.0)
    try:
        return -np.linalg.solve(A, g[..., None])[..., 0]
    except np.linalg.LinAlgError:  # a degenerate individual: fall back to the pseudo-inverse
        return -np.einsum("nij,nj->ni", np.linalg.pinv(A), g)


def refine(objective: PoseObjective, poses: np.ndarray, fitness: np.ndarray | None = None,
           schedule: Sequence[tuple[str, float]] | None = None,
           damping: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """Improve poses by annealed soft then hard matching.

    Parameters
    ----------
    objective : PoseObjective
    poses : array, shape (N, 6)
    fitness : array, shape (N,), optional
        Current eq. (4) fitness of ``poses`` (computed when absent).
    schedule : sequence of (kind, scale)
        ``("soft", t)``: EM-ICP step with the kernel width at annealing time ``t`` (:func:`soft_sigma`);
        ``("hard", s)``: nearest-neighbour step with gate ``s * tau``, accepted only if the fitness drops.
    damping : float
        Initial Levenberg–Marquardt damping (relative to diag(H)).

    Returns
    -------
    poses : array, shape (N, 6)
        Never worse than the input, always inside the search box.
    fitness : array, shape (N,)
    """
    schedule = annealing(12) if schedule is None else schedule
    bounds = objective.problem.bounds
    start = bounds.project(np.atleast_2d(poses))
    start_fit = objective(start) if fitness is None else np.asarray(fitness, float)
    free = bounds.free
    poses = start.copy()
    fit = None  # fitness of `poses`, known only after the first hard step
    lam = np.full(len(poses), damping)
    for kind, scale in schedule:
        H, g = _normal_equations(objective, poses, kind, scale)
        candidates = bounds.project(poses + _damped_step(H, g, lam, free))
        if kind == "soft":
            poses = candidates
            continue
        if fit is None:
            fit = objective(poses)
        cand_fit = objective(candidates)
        better = cand_fit <= fit
        poses[better] = candidates[better]
        fit[better] = cand_fit[better]
        lam = np.where(better, lam * 0.3, lam * 10.0).clip(1e-6, 1e4)
    if fit is None:
        fit = objective(poses)
    worse = fit > start_fit
    poses[worse] = start[worse]
    fit[worse] = start_fit[worse]
    return poses, fit


#: Tracking: the previous pose is close, so start the annealing late.
TRACK_SCHEDULE: tuple[tuple[str, float], ...] = (("soft", 0.8), ("soft", 1.0), ("hard", 1.5), ("hard", 1.0), ("hard", 1.0))
