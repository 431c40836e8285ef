"""Local refinement of candidate poses: annealed soft matching (EM-ICP) then hard matching (ICP).

Each step linearises the projection and takes one damped Gauss–Newton step on
reprojection residuals between projected model points and image points:

* ``soft`` steps weigh every pair by ``exp(-d^2 / 2 sigma^2)``, normalised per image
  point and per model point with an outlier slack (EM-ICP, in the spirit of SoftPOSIT).
  ``sigma`` shrinks from half the image spread of the points to half of tau, which
  widens the basin of attraction far beyond that of nearest-neighbour matching;
* ``hard`` steps match nearest neighbours in both directions (the two terms of the
  robust fitness) within a gate and are accepted only when the fitness drops.

Fixed parameters (eq. 3 with zero tolerance) never move, and every step is projected
back into the search box, so eq. (3) holds throughout. The result is never worse than
the input (per individual, by the objective's fitness). The loop is compiled
(:mod:`evopose.refine_kernel`).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from .fitness import PoseObjective
from .kernel_backend import is_typed, nearest_row, project_pose, refine_population

#: Outlier slack of the soft matching: a pair at 2.5 sigma weighs as much as "no match".
SOFT_OUTLIER = float(np.exp(-0.5 * 2.5**2))
#: Soft kernel width at the start of annealing, as a fraction of the view's image spread,
#: and at its end, as a fraction of tau.
SIGMA_START, SIGMA_END = 0.5, 0.5
Schedule = Sequence[tuple[str, float]]
#: Step kinds of a schedule: soft matching, hard matching, soft matching of the position alone.
STEP_KINDS = {"soft": 0, "hard": 1, "soft-position": 2}


def soft_sigma(spread: float, tau: float, t: float) -> float:
    """Kernel width at annealing time ``t`` in [0, 1]: geometric from half the view's spread to tau / 2."""
    start = max(SIGMA_START * spread, SIGMA_END * tau)
    return float(start * (SIGMA_END * tau / start) ** t)


def annealing(steps: int, hard: int = 2, start: float = 0.0) -> tuple[tuple[str, float], ...]:
    """``steps`` soft steps from annealing time ``start`` to 1, then ``hard`` polishing steps (gate tau)."""
    return tuple(("soft", float(t)) for t in np.linspace(start, 1.0, steps)) + (("hard", 1.0),) * hard


#: Tracking: the previous pose is close, so the annealing starts half way (a shorter schedule left the pose
#: short of the new minimum on noisy frames: measured on exp1-airship).
TRACK_SCHEDULE = annealing(5, hard=5, start=0.5)
#: Tracking, second try from the same start: nearest-neighbour steps only (a soft step pulled off by a
#: false point is otherwise rejected as a whole and the pose does not move).
TRACK_HARD_SCHEDULE = annealing(0, hard=8)


def refine(objective: PoseObjective, poses: np.ndarray, fitness: np.ndarray | None = None,
           schedule: Schedule | None = None, damping: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """Improve poses by annealed soft then hard matching.

    Parameters
    ----------
    objective : PoseObjective
    poses : array, shape (N, 6)
    fitness : array, shape (N,), optional
        Current eq. (4) fitness of ``poses`` (computed when absent).
    schedule : sequence of (kind, value), optional
        ``("soft", t)``: EM-ICP step with the kernel width at annealing time ``t`` (:func:`soft_sigma`);
        ``("hard", s)``: nearest-neighbour step with gate ``s * tau``, accepted only if the fitness drops.
        Default: :func:`annealing` (10).
    damping : float
        Initial Levenberg–Marquardt damping (relative to diag(H)).

    Returns
    -------
    poses : array, shape (N, 6)
        Never worse than the input, always inside the search box.
    fitness : array, shape (N,)
    """
    schedule = annealing(10) if schedule is None else tuple(schedule)
    bounds = objective.problem.bounds
    poses = np.ascontiguousarray(bounds.project(np.atleast_2d(poses)))
    fitness = objective(poses) if fitness is None else np.array(fitness, dtype=float)
    if not schedule or len(poses) == 0:
        return poses, fitness
    packed = objective.packed
    kinds = np.array([STEP_KINDS[kind] for kind, _ in schedule], np.int64)
    values = np.array([value for _, value in schedule], float)
    sigmas = np.array([[soft_sigma(sp, tau, t) for sp, tau in zip(objective.spreads, objective.taus)]
                       for t in values])
    refine_population(poses, fitness, bounds.lo, bounds.hi, bounds.periodic, bounds.free, packed.model,
                      packed.normals, packed.use_normals, packed.intr, packed.cfw,
                      np.array(objective.weights, dtype=float), np.array(objective.taus, dtype=float),
                      sigmas, packed.pts, packed.pz, packed.mz, packed.offsets, objective.mode, kinds, values,
                      SOFT_OUTLIER, damping)
    # count every projection of the model as an evaluation: 7 per step (pose + 6 Jacobian columns: analytic, counted
    # as the finite differences they replaced, so that budgets compare across versions),
    # one fitness per hard step, and the fitness before the first hard step and at the end
    n_hard = int(np.count_nonzero(kinds == STEP_KINDS["hard"]))
    objective.counter.add(len(poses) * (7 * len(kinds) + n_hard + 2))
    return poses, fitness


def match_residuals(objective: PoseObjective, pose: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The residuals the hard steps pull on, per view, at one pose (6,), as the refinement sees them.

    Uses the refinement's own packed views and compiled projection. For view ``k``: ``image`` (P_k,)
    the distance from each image point to its nearest usable projected model point (inf if none), and
    ``model`` (n_usable,) from each usable model point to its nearest image point. Truncated at tau
    and summed as in eq. (1) (robust: both sides over ``P_k + n_usable``; paper: the image side),
    they give the fitness of the pose.
    """
    packed = objective.packed
    M = len(packed.model)
    u, v, usable = np.empty(M), np.empty(M), np.empty(M, bool)
    s = np.ascontiguousarray(np.asarray(pose, float).reshape(6))
    out = []
    for k in range(objective.n_views):
        project_pose(s, packed.model, packed.normals, packed.use_normals, packed.intr[k], packed.cfw[k], u, v,
                     usable, np.empty((3, 3)), np.empty((3, 3)))
        pts = packed.pts[packed.offsets[k]:packed.offsets[k + 1]]
        P = len(pts)
        img_nn, img_d2 = np.empty(P, np.int64), np.empty(P)
        mod_nn, mod_d2 = np.empty(M, np.int64), np.empty(M)
        pz = packed.pz[packed.offsets[k]:packed.offsets[k + 1]]
        nearest_row(u, v, packed.mz[k], usable, np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]),
                    np.ascontiguousarray(pz), is_typed(packed.mz[k], np.ascontiguousarray(pz)), img_nn, img_d2, mod_nn,
                    mod_d2)
        image = np.where(img_nn >= 0, np.sqrt(img_d2), np.inf)
        out.append((image, np.sqrt(mod_d2[usable])))
    return out
