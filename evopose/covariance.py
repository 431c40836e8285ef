"""What the matched points say about a pose: the mutual pairs (eq. 1's distance, one to one) and the covariance
of a pose ``s = (x, y, z, roll, pitch, yaw)`` at an optimum (issue 11).

The covariance is the Gauss-Newton one of the matched point residuals over all views (eq. 4: view ``k``
weighted by its ``W_k``), ``s^2 (J^T W J)^-1``, with ``s^2`` the residual variance; the search box and the
eq. (3) constraints enter as a uniform prior (:func:`covariance`). Both act on the Euler angles, so it is
computed over ``s`` and then expressed in the ROS ``PoseWithCovariance`` convention (docs/protocol.md,
"Covariance"): metres and radians, the rotation block over small rotations about the fixed X, Y, Z axes
(:func:`fixed_axis_covariance`), the one convention of the solver's output, ``PoseEstimate`` and the ROS
messages. :mod:`evopose.trust` builds the verdict ``confident`` on it, with pose differences in the same
coordinates (:func:`deviation`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from geometry import rotation_from_euler, rotvec_from_rotation

from .fitness import POINT_NOISE_PX, PoseObjective, matches

#: Central-difference steps of the projection Jacobian: metres (x, y, z), radians (roll, pitch, yaw).
JACOBIAN_STEP = np.array([1e-4, 1e-4, 1e-4, 1e-5, 1e-5, 1e-5])
#: Smallest residual variance used (pixels^2): the expected point noise. A tighter fit of a handful of pairs is
#: luck (or a pose that chose its pairs), not evidence of a more precise estimate.
MIN_RESIDUAL_VARIANCE = POINT_NOISE_PX ** 2


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
        img_nn, _, mod_nn, mod_d2 = matches(proj, view.points, objective.labels(k))
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


def fixed_axis_jacobian(rpy: np.ndarray) -> np.ndarray:
    """``d omega / d (roll, pitch, yaw)``, shape (..., 3, 3): the small rotation ``omega`` about the fixed X, Y, Z
    axes (``R(rpy + d) = exp([omega]x) R(rpy)`` to first order) of an Euler increment ``d``.

    With ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (docs/protocol.md) a yaw increment turns about Z, a pitch increment
    about ``Rz e_y`` and a roll increment about ``Rz Ry e_x``: the columns of the Jacobian.
    """
    rpy = np.asarray(rpy, float)
    cp, sp = np.cos(rpy[..., 1]), np.sin(rpy[..., 1])
    cy, sy = np.cos(rpy[..., 2]), np.sin(rpy[..., 2])
    J = np.zeros(rpy.shape[:-1] + (3, 3))
    J[..., 0, 0], J[..., 1, 0], J[..., 2, 0] = cy * cp, sy * cp, -sp
    J[..., 0, 1], J[..., 1, 1] = -sy, cy
    J[..., 2, 2] = 1.0
    return J


def fixed_axis_covariance(euler: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """A covariance (6, 6) of ``(x, y, z, roll, pitch, yaw)`` increments at ``pose`` (6,) in the ROS convention:
    ``T Sigma T^T`` with ``T = diag(I, J)``, ``J`` = :func:`fixed_axis_jacobian`; not finite stays inf-filled."""
    euler = np.asarray(euler, float)
    if not np.all(np.isfinite(euler)):
        return np.full((6, 6), np.inf)
    T = np.eye(6)
    T[3:, 3:] = fixed_axis_jacobian(np.asarray(pose, float).reshape(6)[3:])
    out = T @ euler @ T.T
    return 0.5 * (out + out.T)


def deviation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """How pose ``a`` differs from ``b`` (shapes (..., 6)) in the coordinates of the covariance: ``a - b`` in
    position, and the rotation vector of ``R_a R_b^T`` (a rotation about the fixed axes, radians, at most pi)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    a, b = np.broadcast_arrays(a, b)
    out = np.empty(a.shape)
    out[..., :3] = a[..., :3] - b[..., :3]
    relative = rotation_from_euler(a[..., 3:]) @ np.swapaxes(rotation_from_euler(b[..., 3:]), -1, -2)
    out[..., 3:] = rotvec_from_rotation(relative)
    return out


@dataclass(frozen=True, eq=False)
class CovarianceEstimate:
    """The Gauss-Newton covariance at an optimum and what it rests on.

    Attributes
    ----------
    matrix : array, shape (6, 6)
        The covariance in the ROS ``PoseWithCovariance`` convention (docs/protocol.md): position in metres, then
        small rotations about the fixed X, Y, Z axes in radians; inf-filled when not computable (fewer residuals
        than free parameters, or a singular normal matrix).
    residual_variance : float
        ``s^2`` per pixel coordinate (pixels^2); inf when not computable.
    dof : int
        ``2m - n_free``.
    euler : array, shape (6, 6)
        The same over increments of ``(x, y, z, roll, pitch, yaw)``, the parameters the box and eq. (3) bound
        (a fixed one has variance 0 here); ``matrix`` is :func:`fixed_axis_covariance` of it.
    """

    matrix: np.ndarray
    residual_variance: float
    dof: int
    euler: np.ndarray | None = None

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
    return CovarianceEstimate(np.full((6, 6), np.inf), np.inf, 0, np.full((6, 6), np.inf))


def covariance(objective: PoseObjective, pose: np.ndarray, matches: Matches | None = None) -> CovarianceEstimate:
    """Covariance of ``pose`` (6,) from the matched residuals and the box / eq. (3) priors, computed over the
    Euler parameters (``euler``) and given in the ROS convention (``matrix``, :func:`fixed_axis_covariance`).

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
        return CovarianceEstimate(np.zeros((6, 6)), 0.0, dof, np.zeros((6, 6)))
    if dof < 1:
        return _unknown()
    J = projection_jacobian(objective, pose, matches)[use][:, :, free]  # (m, 2, n_free)
    r = matches.residuals[use]
    w = w[use]
    tau2 = float(np.sum(w * objective.taus[matches.view[use]] ** 2) / np.sum(w))
    s2 = max(untruncated_variance(float(np.sum(w[:, None] * r ** 2)) / dof, tau2), MIN_RESIDUAL_VARIANCE)
    normal = np.einsum("m,mai,maj->ij", w, J, J)
    return from_information(objective, pose, normal / s2, s2, dof)


def from_information(objective: PoseObjective, pose: np.ndarray, information: np.ndarray, residual_variance: float,
                     dof: int) -> CovarianceEstimate:
    """The :class:`CovarianceEstimate` of ``pose`` (6,) whose points give ``information`` (n_free, n_free) about
    the free parameters (e.g. ``J^T W J / s^2``), with the box / eq. (3) priors of :func:`covariance` added: the
    likelihood truncated to the box (:func:`in_box_second_moment`), or the Gaussian stand-in ``12 / width^2`` where
    that cannot be sampled; inf-filled when the result is singular."""
    bounds = objective.problem.bounds
    free = bounds.free
    width = bounds.width[free]
    prior = np.where(bounds.periodic[free], 0.0, 12.0 / np.maximum(width, 1e-300) ** 2)
    total = information + np.diag(prior)
    try:
        if not np.all(np.isfinite(total)) or np.linalg.cond(total) > 1e12:
            return _unknown()
        inner = np.linalg.inv(total)
    except np.linalg.LinAlgError:
        return _unknown()
    box = in_box_second_moment(np.asarray(pose, float).reshape(6)[free], information + 0.01 * np.diag(prior),
                               bounds.lo[free], bounds.hi[free], bounds.periodic[free])
    inner = 0.5 * (inner + inner.T) if box is None else box
    full = np.zeros((6, 6))
    full[np.ix_(free, free)] = inner
    return CovarianceEstimate(fixed_axis_covariance(full, pose), residual_variance, dof, full)


#: Samples of the likelihood drawn by :func:`in_box_second_moment`, and how many must fall in the box.
BOX_SAMPLES, MIN_IN_BOX = 16384, 512


@lru_cache(maxsize=8)
def _standard_normal(n: int) -> np.ndarray:
    """The fixed draws of :func:`in_box_second_moment`, shape (BOX_SAMPLES, n), read-only (drawn once)."""
    z = np.random.default_rng(0).standard_normal((BOX_SAMPLES, n))
    z.flags.writeable = False
    return z


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
    bounded = ~np.asarray(periodic, bool)
    sigma = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    if np.all((estimate - 4 * sigma >= lo)[bounded] & (estimate + 4 * sigma <= hi)[bounded]):
        return 0.5 * (cov + cov.T)  # the box is 4 sigma away: the truncation changes nothing that matters
    samples = estimate + _standard_normal(len(estimate)) @ chol.T
    inside = np.all((samples[:, bounded] >= lo[bounded]) & (samples[:, bounded] <= hi[bounded]), axis=1)
    if np.count_nonzero(inside) < MIN_IN_BOX:
        return None
    d = samples[inside] - estimate
    return d.T @ d / len(d)
