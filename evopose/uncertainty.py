"""Honest confidence (issue 11): how uncertain an estimate is, and whether it is the one right answer.

An estimate of ``s = (x, y, z, roll, pitch, yaw)`` gets

* a **covariance** (6, 6), metres and radians, in the order of ROS ``PoseWithCovariance``, from the fitness
  landscape at the optimum: the Gauss-Newton normal matrix ``J^T W J`` of the matched point residuals over all
  views (eq. 4: view ``k`` weighted by its ``W_k``), scaled by the residual variance
  ``s^2 = sum r^2 / (2m - n_free)``. The matched points are the mutual nearest neighbours within tau of eq. (1)'s
  distance (:func:`mutual_matches`). The search box and the eq. (3) constraints enter as priors: a parameter held
  in ``[C - eps, C + eps]`` is uniform there, variance ``eps^2 / 3``, so it adds ``3 / eps^2`` information; a fixed
  one (eq. 3 with full reliability) has variance 0; a periodic angle gets no prior;
* a verdict **confident** (:func:`assess`): enough marks matched one to one and no *distinct* pose, found by the
  search itself, that fits nearly as well. Distinct means outside the estimate's own uncertainty (a Mahalanobis
  distance over ``distinct_sigmas``); "nearly as well" is measured by the log-likelihood-like statistic
  ``(S_alt - S_best) / s^2`` of the truncated sums of squares (:func:`sum_of_squares`).

:class:`ConfidenceRules` holds the thresholds, calibrated by ``benchmarks/bench_confidence.py`` against the
truth on seeded problems at the telephoto and the paper's image scale.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .fitness import POINT_NOISE_PX, PoseObjective
from .kernels import chamfer_matches
from .pose import wrap_angle

#: Central-difference steps of the projection Jacobian: metres (x, y, z), radians (roll, pitch, yaw).
JACOBIAN_STEP = np.array([1e-4, 1e-4, 1e-4, 1e-5, 1e-5, 1e-5])
#: Smallest residual variance used (pixels^2): the expected point noise. A tighter fit of a handful of pairs is
#: luck (or a pose that chose its pairs), not evidence of a more precise estimate.
MIN_RESIDUAL_VARIANCE = POINT_NOISE_PX ** 2


@dataclass(frozen=True)
class ConfidenceRules:
    """When an estimate is called confident (:func:`assess`); calibrated in ``benchmarks/bench_confidence.py``.

    Attributes
    ----------
    min_pairs : int
        Mutual matches (over all weighted views) needed at least.
    max_unmatched : float
        Largest share of the visible marks without a mutual match (:meth:`Matches.unmatched`).
    max_residual_px : float
        Largest residual sigma ``s`` (pixels) of the matched pairs: a fit looser than a few times the point noise
        matches chance points, not marks (an absent target seen through a wide tau).
    margin : float
        The best distinct alternative must be worse by at least this much of ``(S_alt - S_best) / s^2``
        (:func:`sum_of_squares`, ``s^2`` the residual variance at the estimate: twice a log-likelihood ratio).
    distinct_sigmas : float
        An alternative is distinct when its Mahalanobis distance from the estimate, under the estimate's
        covariance, exceeds this...
    same_pairs : float
        ...and it shares fewer than this share of the estimate's mutual pairs (the same marks on the same image
        points are one basin) and does not show the model the same (:func:`same_image`, a symmetry).
    track_sigmas : float
        (tracking) The new pose must lie within this Mahalanobis distance of the previous one, under the sum of
        both covariances and the motion allowance...
    track_motion : tuple of 6 floats
        ...``diag(track_motion^2)``: the 1-sigma change of each parameter from one frame to the next (metres,
        radians; 0.1 m and 0.1 rad: a vehicle at a few m/s filmed at 10 fps, not a flip).
    converged_margin : float
        :attr:`evopose.solver.Solution.converged` also needs the runner-up worse by this margin (a search that
        stopped with a distinct pose about as good has not settled anything).
    """

    min_pairs: int = 7
    max_unmatched: float = 0.4
    max_residual_px: float = 3.0 * POINT_NOISE_PX
    margin: float = 12.0
    distinct_sigmas: float = 4.0
    same_pairs: float = 0.5
    track_sigmas: float = 4.0
    track_motion: tuple[float, float, float, float, float, float] = (0.1, 0.1, 0.1, 0.1, 0.1, 0.1)
    converged_margin: float = 4.0


@dataclass(frozen=True, eq=False)
class Matches:
    """The mutual nearest pairs within tau of one pose in every view (eq. 1's distance, one to one).

    Attributes
    ----------
    view : int array, shape (m,)
        View of each pair.
    model_index, image_index : int arrays, shape (m,)
    residuals : array, shape (m, 2)
        Projected model point minus image point, pixels.
    n_visible, n_image : int arrays, shape (V,)
        Usable (in front, facing) model points and image points per view.
    weights : array, shape (V,)
        Eq. (4) weights ``W_k`` of the objective, over their mean among the weighted views (1 for one view).
    """

    view: np.ndarray
    model_index: np.ndarray
    image_index: np.ndarray
    residuals: np.ndarray
    n_visible: np.ndarray
    n_image: np.ndarray
    weights: np.ndarray

    @property
    def n_pairs(self) -> int:
        """Mutual pairs in the weighted views."""
        return int(np.count_nonzero(self.weights[self.view] > 0))

    def unmatched(self) -> float:
        """Share of the visible marks without a mutual match, over the weighted views (1 when none is visible)."""
        w = self.weights > 0
        visible = int(self.n_visible[w].sum())
        return 1.0 - self.n_pairs / visible if visible else 1.0


def _normalised_weights(objective: PoseObjective) -> np.ndarray:
    w = np.asarray(objective.weights, float)
    positive = w[w > 0]
    return w / positive.mean() if len(positive) else w


def mutual_matches(objective: PoseObjective, pose: np.ndarray) -> Matches:
    """:class:`Matches` of ``pose`` (6,) under ``objective``'s views and truncation distances ``tau_k``."""
    pose = np.asarray(pose, float).reshape(1, 6)
    views, models, images, residuals = [], [], [], []
    n_visible, n_image = [], []
    for k, view in enumerate(objective.problem.views):
        proj = objective.project(k, pose)
        px, py = np.ascontiguousarray(view.points[:, 0]), np.ascontiguousarray(view.points[:, 1])
        img_nn, _, mod_nn, mod_d2 = chamfer_matches(proj.u, proj.v, proj.usable, px, py)
        usable = proj.usable[0]
        m = np.nonzero(usable & (mod_d2[0] < objective.taus[k] ** 2))[0]
        m = m[img_nn[0, mod_nn[0, m]] == m]
        p = mod_nn[0, m]
        views.append(np.full(len(m), k))
        models.append(m)
        images.append(p)
        residuals.append(np.stack([proj.u[0, m] - px[p], proj.v[0, m] - py[p]], axis=1))
        n_visible.append(int(np.count_nonzero(usable)))
        n_image.append(len(view.points))
    objective.counter.add(1)
    return Matches(np.concatenate(views).astype(int), np.concatenate(models).astype(int),
                   np.concatenate(images).astype(int), np.concatenate(residuals).reshape(-1, 2),
                   np.array(n_visible), np.array(n_image), _normalised_weights(objective))


def sum_of_squares(objective: PoseObjective, pose: np.ndarray, matches: Matches | None = None) -> float:
    """Truncated sum of squares of ``pose`` (6,): ``sum_k W_k [sum_pairs |r|^2 + tau_k^2 / 2 * unmatched_k]``.

    ``unmatched_k`` counts the image points and the visible marks of view ``k`` without a mutual partner within
    tau (each pays ``tau^2 / 2``, half a pair's truncated cost). Half the numerator of the "mutual" fitness
    (:func:`evopose.kernels.mutual_row`), summed over views with the eq. (4) weights (normalised); over a
    residual variance it reads as a negative log-likelihood with an outlier floor.
    """
    matches = mutual_matches(objective, pose) if matches is None else matches
    total = 0.0
    for k in range(objective.n_views):
        w = matches.weights[k]
        if w == 0:
            continue
        mine = matches.view == k
        pairs = int(np.count_nonzero(mine))
        unmatched = matches.n_image[k] + matches.n_visible[k] - 2 * pairs
        total += w * (float(np.sum(matches.residuals[mine] ** 2)) + 0.5 * objective.taus[k] ** 2 * unmatched)
    return total


def projection_jacobian(objective: PoseObjective, pose: np.ndarray, matches: Matches) -> np.ndarray:
    """Derivative of each matched model point's pixel w.r.t. ``s``, shape (m, 2, 6), by central differences."""
    pose = np.asarray(pose, float).reshape(6)
    steps = np.diag(JACOBIAN_STEP)
    probes = np.concatenate([pose + steps, pose - steps])  # (12, 6)
    J = np.zeros((len(matches.view), 2, 6))
    for k in np.unique(matches.view):
        rows = np.nonzero(matches.view == k)[0]
        proj = objective.project(int(k), probes)
        m = matches.model_index[rows]
        du = (proj.u[:6, m] - proj.u[6:, m]) / (2 * JACOBIAN_STEP[:, None])  # (6, m_k)
        dv = (proj.v[:6, m] - proj.v[6:, m]) / (2 * JACOBIAN_STEP[:, None])
        J[rows, 0, :] = du.T
        J[rows, 1, :] = dv.T
        objective.counter.add(len(probes))
    return J


@dataclass(frozen=True, eq=False)
class CovarianceEstimate:
    """The Gauss-Newton covariance at an optimum and what it rests on.

    Attributes
    ----------
    matrix : array, shape (6, 6)
        Covariance of ``(x, y, z, roll, pitch, yaw)``, metres and radians; inf-filled when not computable
        (fewer residuals than free parameters, or a singular normal matrix).
    residual_variance : float
        ``s^2`` per pixel coordinate (pixels^2); inf when not computable.
    dof : int
        ``2m - n_free``.
    """

    matrix: np.ndarray
    residual_variance: float
    dof: int

    @property
    def ok(self) -> bool:
        return bool(np.all(np.isfinite(self.matrix)))

    @property
    def sigmas(self) -> np.ndarray:
        """1-sigma of each parameter, shape (6,)."""
        return np.sqrt(np.clip(np.diag(self.matrix), 0.0, None))


def untruncated_variance(s2: float, tau2: float, iterations: int = 20) -> float:
    """The per-coordinate variance ``sigma^2`` of 2-D Gaussian residuals whose sample, kept only within radius
    ``tau`` (pairs farther away are not matched), has per-coordinate variance ``s2``.

    ``E[|r|^2 | |r| < tau] = 2 sigma^2 g(a)``, ``a = tau^2 / (2 sigma^2)``, ``g(a) = 1 - a e^-a / (1 - e^-a)``;
    solved by fixed-point iteration. Matters at the paper's image scale, where tau is 2-4 sigma (at 2 sigma
    the kept pairs understate the variance by a third). A sample as wide as a uniform disc (``s2 >= tau2 / 4``)
    gives ``tau2``.
    """
    if not (np.isfinite(s2) and tau2 > 0) or s2 <= 0:
        return s2
    if s2 >= 0.25 * tau2:
        return tau2
    sigma2 = s2
    for _ in range(iterations):
        a = tau2 / (2 * sigma2)
        g = 1.0 - a * np.exp(-a) / -np.expm1(-a) if a < 700 else 1.0
        sigma2 = min(s2 / g, tau2)
    return float(sigma2)


def _unknown() -> CovarianceEstimate:
    return CovarianceEstimate(np.full((6, 6), np.inf), np.inf, 0)


def covariance(objective: PoseObjective, pose: np.ndarray, matches: Matches | None = None) -> CovarianceEstimate:
    """Covariance of ``pose`` (6,) from the matched residuals and the box / eq. (3) priors.

    ``Sigma = (J^T W J / s^2 + P)^-1`` over the free parameters, ``W`` the eq. (4) view weights (normalised),
    ``s^2 = sum_pairs W |r|^2 / (2m - n_free)`` corrected for the truncation at tau
    (:func:`untruncated_variance`) and at least :data:`MIN_RESIDUAL_VARIANCE`, and ``P`` the prior
    information ``12 / width^2`` of each non-periodic free parameter (uniform over its interval ``[lo, hi]``,
    ``eps = width / 2``: ``3 / eps^2``). Fixed parameters get variance 0.

    That Gaussian stand-in for the box is used only when the exact one cannot be sampled: the uniform prior
    truncates the likelihood to the box, and the covariance is its second moment about the estimate
    (:func:`in_box_second_moment`). The two differ where it matters at the paper's image scale: the depth
    is so loosely determined that the estimate often sits on a bound of a narrow box (exp2's z in
    [-0.2, 0.5] m); the truth then lies anywhere back inside, not within the stand-in's +-0.2 m.
    """
    matches = mutual_matches(objective, pose) if matches is None else matches
    bounds = objective.problem.bounds
    free = bounds.free
    n_free = int(np.count_nonzero(free))
    w = matches.weights[matches.view]
    use = w > 0
    dof = 2 * int(np.count_nonzero(use)) - n_free
    if n_free == 0:
        return CovarianceEstimate(np.zeros((6, 6)), 0.0, dof)
    if dof < 1:
        return _unknown()
    J = projection_jacobian(objective, pose, matches)[use][:, :, free]  # (m, 2, n_free)
    r = matches.residuals[use]
    w = w[use]
    tau2 = float(np.sum(w * objective.taus[matches.view[use]] ** 2) / np.sum(w))
    s2 = max(untruncated_variance(float(np.sum(w[:, None] * r ** 2)) / dof, tau2), MIN_RESIDUAL_VARIANCE)
    normal = np.einsum("m,mai,maj->ij", w, J, J)
    width = bounds.width[free]
    prior = np.where(bounds.periodic[free], 0.0, 12.0 / np.maximum(width, 1e-300) ** 2)
    information = normal / s2 + np.diag(prior)
    try:
        if np.linalg.cond(information) > 1e12:
            return _unknown()
        inner = np.linalg.inv(information)
    except np.linalg.LinAlgError:
        return _unknown()
    box = in_box_second_moment(np.asarray(pose, float).reshape(6)[free], normal / s2 + 0.01 * np.diag(prior),
                               bounds.lo[free], bounds.hi[free], bounds.periodic[free])
    inner = 0.5 * (inner + inner.T) if box is None else box
    full = np.zeros((6, 6))
    full[np.ix_(free, free)] = inner
    return CovarianceEstimate(full, s2, dof)


#: Samples of the likelihood drawn by :func:`in_box_second_moment`, and how many must fall in the box.
BOX_SAMPLES, MIN_IN_BOX = 16384, 512


def in_box_second_moment(estimate: np.ndarray, information: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                         periodic: np.ndarray) -> np.ndarray | None:
    """Second moment about ``estimate`` (n,) of the Gaussian likelihood ``N(estimate, information^-1)``
    truncated to the box ``[lo, hi]`` (a uniform prior; periodic parameters are not truncated), shape (n, n).

    Monte Carlo with a fixed seed (the same input gives the same covariance); None when fewer than
    ``MIN_IN_BOX`` of ``BOX_SAMPLES`` samples fall in the box (e.g. a narrow eq. 3 constraint), or when the
    information is not positive definite.
    """
    try:
        cov = np.linalg.inv(information)
        chol = np.linalg.cholesky(0.5 * (cov + cov.T))
    except np.linalg.LinAlgError:
        return None
    z = np.random.default_rng(0).standard_normal((BOX_SAMPLES, len(estimate)))
    samples = estimate + z @ chol.T
    bounded = ~np.asarray(periodic, bool)
    inside = np.all((samples[:, bounded] >= lo[bounded]) & (samples[:, bounded] <= hi[bounded]), axis=1)
    if np.count_nonzero(inside) < MIN_IN_BOX:
        return None
    d = samples[inside] - estimate
    return d.T @ d / len(d)


def pose_difference(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a - b`` with the angles wrapped to [-pi, pi); shapes (..., 6)."""
    d = np.asarray(a, float) - np.asarray(b, float)
    d[..., 3:] = wrap_angle(d[..., 3:])
    return d


def mahalanobis(delta: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """``sqrt(delta^T cov^+ delta)`` for differences (..., 6); parameters with zero variance are left out.

    inf when the covariance is not finite.
    """
    delta = np.atleast_2d(delta)
    if not np.all(np.isfinite(cov)):
        return np.full(len(delta), np.inf)
    keep = np.diag(cov) > 0
    inv = np.linalg.pinv(cov[np.ix_(keep, keep)])
    d = delta[:, keep]
    return np.sqrt(np.maximum(np.einsum("ni,ij,nj->n", d, inv, d), 0.0))


@dataclass(frozen=True, eq=False)
class Confidence:
    """:func:`assess`'s verdict on an estimate.

    Attributes
    ----------
    confident : bool
    covariance : CovarianceEstimate
    n_pairs : int
        Mutual matches over the weighted views.
    unmatched : float
        Share of the visible marks without a mutual match.
    margin : float
        ``(S_alt - S_best) / s^2`` of the best distinct alternative (inf when there is none).
    runner_up : array (6,) or None
        That alternative.
    reason : str
        Why not confident ("" when confident): "no covariance", "few matches", "unmatched marks", "loose fit",
        "ambiguous" (and for tracking "previous not confident", "jumped").
    sum_of_squares, runner_up_sum_of_squares : float
        :func:`sum_of_squares` of the estimate and of the runner-up (inf when there is none).
    """

    confident: bool
    covariance: CovarianceEstimate
    n_pairs: int
    unmatched: float
    margin: float = np.inf
    runner_up: np.ndarray | None = None
    reason: str = ""
    sum_of_squares: float = np.nan
    runner_up_sum_of_squares: float = np.inf


def assess(objective: PoseObjective, pose: np.ndarray, alternatives: np.ndarray | None = None,
           rules: ConfidenceRules = ConfidenceRules(), judge: PoseObjective | None = None) -> Confidence:
    """Covariance and confidence of ``pose`` (6,) given the search's other basins ``alternatives`` (K, 6).

    The alternatives should be local optima of the same objective (the search's final population, polished):
    the best of them outside ``rules.distinct_sigmas`` of the estimate's covariance is the runner-up. The
    covariance and the margin use ``objective`` (eq. 4 with the weights in force); the match rules (pairs,
    unmatched marks) use ``judge`` (default ``objective``): with every view at its own weight, a view the
    step rule dropped still counts its unmatched marks against the pose.
    """
    pose = np.asarray(pose, float).reshape(6)
    matches = mutual_matches(objective, pose)
    cov = covariance(objective, pose, matches)
    s_best = sum_of_squares(objective, pose, matches)
    judged = matches if judge is None else mutual_matches(judge, pose)
    n_pairs, unmatched = judged.n_pairs, judged.unmatched()
    s_alt, runner_up = np.inf, None
    if cov.ok and alternatives is not None and len(alternatives):
        alternatives = np.atleast_2d(alternatives)
        far = mahalanobis(pose_difference(alternatives, pose), cov.matrix) > rules.distinct_sigmas
        for alt in alternatives[far]:
            if same_image(objective, pose, alt):
                continue  # a symmetry of the model: no image tells the two apart, they are one answer
            alt_matches = mutual_matches(objective, alt)
            if shared_pairs(matches, alt_matches) >= rules.same_pairs:
                continue  # the same marks on the same image points: one basin, however far the noise moved it
            s = sum_of_squares(objective, alt, alt_matches)
            if s < s_alt:
                s_alt, runner_up = s, alt.copy()
    margin = (s_alt - s_best) / cov.residual_variance if np.isfinite(s_alt) else np.inf
    reason = ("no covariance" if not cov.ok else "few matches" if n_pairs < rules.min_pairs
              else "unmatched marks" if unmatched > rules.max_unmatched
              else "loose fit" if cov.residual_variance > rules.max_residual_px ** 2
              else "ambiguous" if margin < rules.margin else "")
    return Confidence(reason == "", cov, n_pairs, unmatched, float(margin), runner_up, reason, s_best, s_alt)


def shared_pairs(a: Matches, b: Matches) -> float:
    """Share of ``a``'s mutual pairs (view, image point, mark) that ``b`` has too (0 when ``a`` has none)."""
    if not len(a.view):
        return 0.0
    mine = set(zip(a.view.tolist(), a.image_index.tolist(), a.model_index.tolist()))
    theirs = set(zip(b.view.tolist(), b.image_index.tolist(), b.model_index.tolist()))
    return len(mine & theirs) / len(mine)


def same_image(objective: PoseObjective, a: np.ndarray, b: np.ndarray, tolerance: float = POINT_NOISE_PX) -> bool:
    """Whether poses ``a`` and ``b`` (6,) show the model the same in every weighted view: the same number of
    usable marks, each within ``tolerance`` pixels of one of the other pose's (a symmetry of the model, such
    as a chessboard's half turn)."""
    poses = np.stack([np.asarray(a, float), np.asarray(b, float)])
    for k in range(objective.n_views):
        if objective.weights[k] == 0:
            continue
        proj = objective.project(k, poses)
        ua, ub = proj.uv[0][proj.usable[0]], proj.uv[1][proj.usable[1]]
        if len(ua) != len(ub):
            return False
        if len(ua):
            d = np.linalg.norm(ua[:, None, :] - ub[None, :, :], axis=2)
            if max(d.min(axis=0).max(), d.min(axis=1).max()) > tolerance:
                return False
    return True


def track_confidence(previous_pose: np.ndarray, previous_cov: np.ndarray, previous_confident: bool,
                     current: Confidence, pose: np.ndarray, rules: ConfidenceRules = ConfidenceRules()) -> Confidence:
    """Confidence of a warm-started estimate (eq. 2), which has no population of other basins to compare with.

    Confident when the previous estimate was, the new pose (6,) is still matched well (``current``, from
    :func:`assess` without alternatives, passes the match rules) and it moved less than ``rules.track_sigmas``
    under ``previous_cov + current covariance + diag(rules.track_motion^2)``. The runner-up margin is not
    re-examined: the previous verdict carries over while the fit holds and stays within the previous
    uncertainty plus a frame's motion.
    """
    motion = np.asarray(rules.track_motion, float)
    cov = current.covariance
    reason = current.reason if current.reason != "ambiguous" else ""
    if not reason and not previous_confident:
        reason = "previous not confident"
    if not reason:
        gate = np.asarray(previous_cov, float) + cov.matrix + np.diag(np.asarray(motion, float) ** 2)
        if mahalanobis(pose_difference(pose, previous_pose), gate)[0] > rules.track_sigmas:
            reason = "jumped"
    return Confidence(reason == "", cov, current.n_pairs, current.unmatched, current.margin, current.runner_up,
                      reason, current.sum_of_squares, current.runner_up_sum_of_squares)
