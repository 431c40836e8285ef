"""Local refinement of candidate poses: Levenberg–Marquardt on nearest-neighbour matches (an ICP step).

Each step matches every image point to its nearest projected model point and every
visible model point to its nearest image point (the two directions of the robust
fitness), keeps the pairs closer than a gate, and takes one damped Gauss–Newton step
on their squared reprojection residuals, for the whole population at once. The gate
shrinks from a few ``tau`` to ``tau`` so that a start some way off is pulled in and the
last steps see only inliers. Fixed parameters (eq. 3 with zero tolerance) do not move
and every step is projected back into the search box, so eq. (3) holds throughout.
A step that worsens an individual's fitness is rejected (and its damping raised).
"""

from __future__ import annotations

import numpy as np

from .fitness import PoseObjective, project_into_view
from .kernels import chamfer_matches

#: Finite-difference steps for the Jacobian: metres for x, y, z; radians for the angles.
FD_STEP = np.array([1e-5, 1e-5, 1e-5, 1e-6, 1e-6, 1e-6])
#: Gate (in units of each view's tau) at successive steps; the last value repeats.
GATE_SCHEDULE = (3.0, 2.0, 1.0)


def _normal_equations(objective: PoseObjective, poses: np.ndarray, gate_scale: float):
    """Accumulate ``H = sum w J^T J`` (N, 6, 6) and ``g = sum w J^T r`` (N, 6) over the weighted views."""
    N = len(poses)
    free = objective.problem.bounds.free
    H = np.zeros((N, 6, 6))
    g = np.zeros((N, 6))
    perturbed = np.concatenate([poses] + [poses + FD_STEP[d] * np.eye(6)[d] for d in range(6)])
    model = objective.problem.model
    for k, view in enumerate(objective.problem.views):
        w_view = objective.weights[k]
        if w_view == 0:
            continue
        proj = project_into_view(model, view, perturbed, use_normals=objective.kind == "robust")
        uv_all = proj.uv.reshape(7, N, -1, 2)
        uv, usable = uv_all[0], proj.usable[:N]
        J = np.stack([(uv_all[1 + d] - uv) / FD_STEP[d] for d in range(6)], axis=-1)  # (N, M, 2, 6)
        J[..., ~free] = 0.0
        pts = view.points
        img_nn, img_d2, mod_nn, mod_d2 = chamfer_matches(
            np.ascontiguousarray(uv[..., 0]), np.ascontiguousarray(uv[..., 1]), usable,
            np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]))
        gate2 = (gate_scale * objective.taus[k]) ** 2
        rows = np.arange(N)[:, None]
        # image -> model pairs (eq. 1 direction)
        ok_a = (img_nn >= 0) & (img_d2 < gate2)
        j_a = np.maximum(img_nn, 0)
        r_a = uv[rows, j_a] - pts[None]                           # (N, P, 2)
        J_a = J[rows, j_a]                                         # (N, P, 2, 6)
        w_a = ok_a * (w_view * 0.5 / len(pts))
        # model -> image pairs
        ok_b = usable & (mod_nn >= 0) & (mod_d2 < gate2)
        r_b = uv - pts[np.maximum(mod_nn, 0)]                      # (N, M, 2)
        n_usable = np.maximum(usable.sum(axis=1, keepdims=True), 1)
        w_b = ok_b * (w_view * 0.5 / n_usable)
        for w, Jp, r in ((w_a, J_a, r_a), (w_b, J, r_b)):
            H += np.einsum("np,npci,npcj->nij", w, Jp, Jp)
            g += np.einsum("np,npci,npc->ni", w, Jp, r)
    return H, g


def refine(objective: PoseObjective, poses: np.ndarray, fitness: np.ndarray | None = None,
           steps: int = 4, gate_schedule: tuple[float, ...] = GATE_SCHEDULE,
           damping: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """Improve poses by damped Gauss–Newton steps on nearest-neighbour matches.

    Parameters
    ----------
    objective : PoseObjective
    poses : array, shape (N, 6)
    fitness : array, shape (N,), optional
        Current eq. (4) fitness of ``poses`` (computed when absent).
    steps : int
    gate_schedule : tuple of float
        Gate in units of tau per step; the last value repeats.
    damping : float
        Initial Levenberg–Marquardt damping (relative to diag(H)).

    Returns
    -------
    poses : array, shape (N, 6)
        Never worse than the input, always inside the search box.
    fitness : array, shape (N,)
    """
    bounds = objective.problem.bounds
    poses = bounds.project(np.atleast_2d(poses))
    fitness = objective(poses) if fitness is None else np.asarray(fitness, float).copy()
    free = bounds.free
    lam = np.full(len(poses), damping)
    eye = np.eye(6)
    for it in range(steps):
        gate = gate_schedule[min(it, len(gate_schedule) - 1)]
        H, g = _normal_equations(objective, poses, gate)
        diag = np.einsum("nii->ni", H)
        A = H + (lam[:, None] * diag + 1e-12)[:, :, None] * eye
        A[:, ~free, :] = 0.0
        A[:, :, ~free] = 0.0
        A[:, ~free, ~free] = 1.0
        g[:, ~free] = 0.0
        try:
            delta = -np.linalg.solve(A, g[..., None])[..., 0]
        except np.linalg.LinAlgError:  # a degenerate individual: fall back to the pseudo-inverse
            delta = -np.einsum("nij,nj->ni", np.linalg.pinv(A), g)
        candidates = bounds.project(poses + delta)
        cand_fit = objective(candidates)
        better = cand_fit <= fitness
        poses[better] = candidates[better]
        fitness[better] = cand_fit[better]
        lam = np.where(better, lam * 0.3, lam * 10.0).clip(1e-6, 1e4)
    return poses, fitness
