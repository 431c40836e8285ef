"""The last step of a pose estimate: an M-estimate that lets false points go (Tukey's biweight, re-matched).

Eq. (1)'s distance, truncated at tau (:mod:`evopose.fitness`), keeps the search robust to points far from every
mark. It does not stop a false point *within* tau of a projected mark from pulling the pose with the full weight
of a true one. On camera frames at the paper's scale that was most of the error: tau is 4 px there, a mark 2-4
px wide, and about half the image points were not marks (the contrast front-end's precision was 0.49; 0.78 now,
with the mark scorer: ``benchmarks/bench_photoreal_features.py``), many of them the body's own structure a few px
from a mark. Good frames were tilted 5-11 deg by them while their position stayed right to a few cm (9 of 72 good
frames on nine paper-scale Cycles datasets, ``benchmarks/bench_photoreal_tracking.py``; 1 with this fit).
At the pose this fit publishes, a tenth of the pairs are false (119 of 1149 on those good frames), 2.2 px from their marks (median)
against the true pairs' 0.3 px (the same benchmark's pooled line).

So the estimate ends with iteratively re-weighted least squares (IRLS) on the mutual pairs of eq. (1)'s
matching (:func:`evopose.covariance.mutual_matches`, re-matched at every step as ICP does), in two stages:

1. **Sort** the pairs: each weighed by Tukey's biweight ``w(d) = (1 - (d / c)^2)^2`` for ``d < c``, else 0, times
   its view's eq. (4) weight. The cut-off ``c = k(nu) * sigma`` follows the pairs' spread at the pose given
   (:func:`view_cutoffs`: ``sigma`` from their median distance, a 2-D Gaussian's median radius being 1.177
   sigma, at least :data:`MIN_SCALE_PX`; a view whose own pairs spread wider keeps its own). With many pairs
   ``k = TUKEY_C``: a false pair 3 sigma off no longer weighs. With few, the pooled ``sigma`` itself is uncertain
   (its ``nu = 2m - n_free`` residual coordinates) and ``k`` widens as Student's t does (:func:`cutoff_sigmas`): a
   handful of true pairs at 1 px noise (6-13 marks of a box 50 px wide at 20-30 m) had ``sigma`` estimated at half
   its value, the largest true pair cut, and the published pose tilted past the least-squares one (issue 35).
2. **Fit** by least squares the pairs within ``c`` ("trimmed"), ``c`` taken anew at the pose stage 1 settled on,
   where the true pairs agree more tightly. The biweight alone weighs the true pairs down too (by 0.3 at 2 sigma)
   and loses precision on clean points; least squares does not.

Each stage takes Gauss-Newton steps on the free parameters (eq. (3): fixed ones never move), projected back into
the search box, each taken only when it lowers the stage's loss with the pairs matched anew (the loss summed over the
pairs, plus its ceiling for each visible mark without one, per view times its eq. (4) weight; else half the step, a
quarter, or the stage stops): compiled, :func:`evopose.robust_kernel.robust_irls`. It is a local step: it keeps the
basin the search found (:func:`evopose.solver.published`).
"""

from __future__ import annotations

import numpy as np

from .covariance import Matches, mutual_matches
from .fitness import PoseObjective
from .kernel_backend import robust_irls

#: Tukey's cut-off in residual sigmas: a pair 3 sigma from its mark no longer weighs.
TUKEY_C = 3.0
#: Median distance of a 2-D Gaussian residual from zero, in sigmas (sqrt(2 ln 2) = 1.177).
MEDIAN_RADIUS_PER_SIGMA = float(np.sqrt(2 * np.log(2)))
#: Least residual sigma (pixels) the cut-off is scaled from: a sub-pixel centre of a 2-4 px mark (the contrast
#: front-end's true pairs: 0.3-0.5 px per axis), so that a handful of tight pairs does not shut the others out.
MIN_SCALE_PX = 0.35
#: Most iterations, and the step (largest parameter change, metres or radians) under which it has settled.
MAX_ITERATIONS, SETTLED_STEP = 10, 1e-6
#: A whole Gauss-Newton step under this has settled too: the steps shrink quadratically (tracked exp2 frames: 2.3e-3,
#: then 1.1e-5, then 4e-8), so the one it saves would move the pose by ~1e-8, a ten-thousandth of the best
#: published 1-sigma. A shortened step (half or a quarter) converges linearly and keeps :data:`SETTLED_STEP`.
SETTLED_WHOLE_STEP = 1e-4


def residual_scale(distance: np.ndarray, n_free: float = 0, floor: float = MIN_SCALE_PX) -> float:
    """Per-axis sigma (pixels) of pairs whose residual distances are ``distance`` (m,) at a pose fitted to them
    over ``n_free`` parameters: the median radius over that of a 2-D Gaussian, times ``sqrt(2m / (2m - n_free))``
    (the fit took up that share of the noise), at least ``floor``."""
    m = len(distance)
    if 2 * m <= n_free:
        return floor
    return max(float(np.median(distance)) / MEDIAN_RADIUS_PER_SIGMA * np.sqrt(2 * m / (2 * m - n_free)), floor)


def cutoff_sigmas(dof: float) -> float:
    """The cut-off in residual sigmas when sigma was estimated from ``dof`` residual coordinates (``2m - n_free``):
    the 2-D pair's squared distance over ``2 sigma^2`` against its F(2, dof) quantile at the tail
    ``alpha = exp(-TUKEY_C^2 / 2)`` that :data:`TUKEY_C` cuts from a 2-D Gaussian with sigma known. F(2, nu)'s
    tail is ``(1 + 2x / nu)^(-nu / 2)``, so ``k = sqrt(nu (alpha^(-2 / nu) - 1))``: :data:`TUKEY_C` as ``nu`` grows
    (3.4 at nu = 20, 4.6 at nu = 6), infinite at ``nu <= 0`` (no redundancy: no pair can be told false)."""
    if dof <= 0:
        return np.inf
    return float(np.sqrt(dof * np.expm1(TUKEY_C ** 2 / dof)))


def view_cutoffs(matches: Matches, n_free: int, taus: np.ndarray | None = None) -> np.ndarray:
    """Each view's cut-off (V,) pixels: :func:`cutoff_sigmas` (for all pairs' residual degrees of freedom) times
    the residual scale (:func:`residual_scale`) of all pairs in ``matches``, or :data:`TUKEY_C` times that of the
    view's own pairs where this is wider. Cameras differ: the true pairs of a blurred or far one spread wider than a
    sharp one's and are not outliers for it; a view's own handful of pairs alone (6-8 at the paper's scale) gives
    too loose an estimate to cut a sharp view tighter. That own scale, taken only where it widens the cut, is not
    widened again for its own few degrees of freedom: on two paper-scale views that let false pairs 4-6 sigma off
    in or out by chance, and two helicopters sharing their features published poses 0.3-0.5 m apart
    (tests/test_dataset_scenario.py). At most the view's ``taus`` (V,) pixels, eq. (1)'s own bound, within which
    every mutual pair lies (all pairs kept)."""
    distance = np.linalg.norm(matches.residuals, axis=1)
    total = max(len(distance), 1)
    pooled = cutoff_sigmas(2 * len(distance) - n_free) * residual_scale(distance, n_free)
    cutoffs = []
    for k in range(len(matches.weights)):
        mine = matches.view == k
        n_mine = n_free * np.count_nonzero(mine) / total
        own = TUKEY_C * residual_scale(distance[mine], n_mine)
        cutoffs.append(max(pooled, own))
    cutoffs = np.array(cutoffs)
    return cutoffs if taus is None else np.minimum(cutoffs, np.asarray(taus, float))


def robust_fit(objective: PoseObjective, pose: np.ndarray,
               iterations: int = MAX_ITERATIONS) -> tuple[np.ndarray, Matches]:
    """The pose (6,) near ``pose`` (6,) fitted to its mutual pairs under ``objective`` (its views, eq. (4)
    weights and tau) without the false ones (see the module's docstring), and its mutual pairs there: the
    biweight finds which pairs are false, then least squares on the rest (the biweight alone down-weighs the true
    pairs too, and is the less precise for it). ``pose`` itself when there are too few pairs for a step (fewer
    weighted coordinates than free parameters)."""
    n_free = int(np.count_nonzero(objective.problem.bounds.free))
    start = np.asarray(pose, float).reshape(6).copy()
    matches = mutual_matches(objective, start)
    if n_free == 0:
        return start, matches
    # the biweight at each view's scale of the pairs as they are sorts them (a false pair 3 of their sigmas off no
    # longer weighs, more with few pairs: cutoff_sigmas); at the pose it settles on, the true pairs agree more
    # tightly, and least squares keeps those within the cut-off of their new scale
    taus = objective.taus
    core = irls_stage(objective, start, matches, True, view_cutoffs(matches, n_free, taus), iterations)
    matches = mutual_matches(objective, core)
    fitted = irls_stage(objective, core, matches, False, view_cutoffs(matches, n_free, taus), iterations)
    return fitted, mutual_matches(objective, fitted)


def irls_stage(objective: PoseObjective, pose: np.ndarray, matches: Matches, tukey: bool, cutoffs: np.ndarray,
               iterations: int = MAX_ITERATIONS) -> np.ndarray:
    """One stage of IRLS (the biweight with ``tukey``, else the trimmed square) at ``cutoffs`` (V,) pixels from
    ``pose`` (6,), whose pairs ``matches`` give eq. (4)'s normalised view weights: the compiled
    :func:`evopose.robust_kernel.robust_irls`. Returns the pose (6,)."""
    bounds, packed = objective.problem.bounds, objective.packed
    fitted = np.array(pose, dtype=float).reshape(6)
    taken = robust_irls(fitted, bounds.lo, bounds.hi, bounds.periodic, bounds.free, packed.model, packed.normals,
                        packed.use_normals, packed.intr, packed.cfw, np.array(matches.weights, dtype=float),
                        np.array(objective.taus, dtype=float), packed.pts, packed.pz, packed.mz, packed.offsets,
                        np.array(cutoffs, dtype=float), tukey, iterations, SETTLED_STEP, SETTLED_WHOLE_STEP)
    # per weighted view, the first matching and each step's pose, Jacobian (counted as the 12 probes of the central
    # differences it replaced, so that budgets compare across versions) and its try re-matched
    objective.counter.add(int(np.count_nonzero(matches.weights > 0)) * (14 * int(taken) + 1))
    return fitted


def robust_pose(objective: PoseObjective, pose: np.ndarray, iterations: int = MAX_ITERATIONS) -> np.ndarray:
    """:func:`robust_fit`'s pose (6,)."""
    return robust_fit(objective, pose, iterations)[0]


__all__ = ["MIN_SCALE_PX", "TUKEY_C", "cutoff_sigmas", "irls_stage", "residual_scale", "robust_fit", "robust_pose",
           "view_cutoffs"]
