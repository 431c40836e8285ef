"""How uncertain an estimate is (issue 11): the evidence the verdict of :mod:`evopose.trust` rests on.

An estimate of ``s = (x, y, z, roll, pitch, yaw)`` gets a **covariance** (6, 6) in the convention of ROS
``PoseWithCovariance`` (docs/protocol.md, "Covariance": metres, then small rotations about the fixed X, Y, Z axes in
radians), from the fitness landscape at the optimum (:func:`evopose.covariance.covariance`): the Gauss-Newton normal
matrix ``J^T W J`` of the matched point residuals over all views (eq. 4: view ``k`` weighted by its ``W_k``), scaled
by the residual variance ``s^2 = sum r^2 / (2m - n_free)``; the matched points are the mutual nearest neighbours
within tau of eq. (1)'s distance. The search box and the eq. (3) constraints enter as a uniform prior (a parameter
held in ``[C - eps, C + eps]``: at most ``eps^2 / 3``; a fixed one: 0; a periodic angle: none).

This module measures: the truncated sum of squares (:func:`sum_of_squares`, over a residual variance a negative
log-likelihood), Mahalanobis distances, whether two poses are one answer (:func:`shared_pairs`,
:func:`same_image`) and eq. (2)'s chain of tracked frames fused into one estimate (:class:`TrackReference`).
Whether to trust an estimate is decided from these in one place, :mod:`evopose.trust`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from geometry import euler_from_rotation, rotation_from_euler, rotation_from_rotvec

from .covariance import (CovarianceEstimate, Matches, covariance, deviation, in_box_second_moment, mutual_matches,
                         projection_jacobian, untruncated_variance)
from .fitness import POINT_NOISE_PX, PoseObjective
from .neighbours import nearest_distance

__all__ = ["CovarianceEstimate", "Matches", "covariance", "deviation", "in_box_second_moment", "mahalanobis",
           "mutual_matches", "projection_jacobian", "rotation_sigma", "same_image", "shared_pairs", "sum_of_squares",
           "TrackReference", "untruncated_variance"]


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


def mahalanobis(delta: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """``sqrt(delta^T cov^+ delta)`` for differences (..., 6) in the covariance's coordinates (the ROS convention:
    :func:`evopose.covariance.deviation`); parameters with zero variance are left out, and so are directions
    without variance (a parameter fixed by eq. 3 is one such direction among the fixed-axis rotations).

    inf when the covariance is not finite.
    """
    delta = np.atleast_2d(delta)
    if not np.all(np.isfinite(cov)):
        return np.full(len(delta), np.inf)
    keep = np.diag(cov) > 0
    inv = np.linalg.pinv(cov[np.ix_(keep, keep)], rcond=1e-12, hermitian=True)
    d = delta[:, keep]
    return np.sqrt(np.maximum(np.einsum("ni,ij,nj->n", d, inv, d), 0.0))


def rotation_sigma(cov: np.ndarray) -> float:
    """The worst rotation axis's 1-sigma (radians) of a covariance (6, 6) (nan when it is not finite)."""
    cov = np.asarray(cov, float)
    if not np.all(np.isfinite(cov)):
        return float("nan")
    return float(np.sqrt(max(np.linalg.eigvalsh(cov[3:, 3:]).max(), 0.0)))


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
        if len(ua):  # each mark within tolerance of the other pose's nearest (a sweep: no K x K matrix)
            bound = tolerance * (1 + 1e-9)  # within the tolerance, rounding aside
            if not np.all(nearest_distance(ua, ub) < bound) or not np.all(nearest_distance(ub, ua) < bound):
                return False
    return True


@dataclass(frozen=True, eq=False)
class TrackReference:
    """Eq. (2)'s chain of confident tracked frames as one estimate of the target's pose, for the tracking gate.

    Each confident frame's pose is fused in by its covariance (a Kalman update), and between frames the fused
    pose's covariance grows by the motion allowance (``ConfidenceRules.track_motion``, :mod:`evopose.trust`: a random
    walk). A single frame at the paper's scale knows its rotation to 2-5 deg (marks 3-5 px apart), so a frame that takes a
    neighbouring basin (its points paired with the marks beside their own) can move 10 deg and still lie within
    4 sigma of the last frame; the chain's pose, known to a fraction of that when the target moves little, shows it.

    Attributes
    ----------
    pose : array (6,)
    covariance : array (6, 6)
        In the ROS convention (:func:`evopose.covariance.deviation`'s coordinates).
    frames : int
        Frames fused (1: a single estimate).
    set_aside : int
        Frames since the last one fused that were set aside as jumps (:func:`evopose.solver.track`).
    """

    pose: np.ndarray
    covariance: np.ndarray
    frames: int = 1
    set_aside: int = 0

    @classmethod
    def of(cls, pose: np.ndarray, cov: np.ndarray) -> "TrackReference | None":
        """The reference of one estimate; None when its covariance is not finite."""
        cov = np.asarray(cov, float)
        return cls(np.asarray(pose, float).reshape(6).copy(), cov.copy()) if np.all(np.isfinite(cov)) else None

    def predicted(self, motion: np.ndarray) -> "TrackReference":
        """One frame later: the covariance grown by ``diag(motion^2)`` (motion (6,), 1 sigma per frame)."""
        return TrackReference(self.pose, self.covariance + np.diag(np.asarray(motion, float) ** 2), self.frames,
                              self.set_aside)

    def passed_over(self, most: int) -> "TrackReference | None":
        """This (predicted) reference past a frame set aside as a jump; None after ``most`` of them in a row: the
        track no longer stands for the target."""
        return None if self.set_aside >= most else replace(self, set_aside=self.set_aside + 1)

    def fused(self, pose: np.ndarray, cov: np.ndarray) -> "TrackReference":
        """The reference updated by an estimate ``pose`` (6,) with covariance ``cov`` (6, 6): the Kalman gain
        ``K = P (P + C)^+`` applied to :func:`deviation`, the rotation part turned about the fixed axes. An estimate
        without a finite covariance carries no information (``K = 0``): the reference stands as it is."""
        P, C = self.covariance, np.asarray(cov, float)
        if not np.all(np.isfinite(C)):
            return self
        gain = P @ np.linalg.pinv(P + C, rcond=1e-12, hermitian=True)
        step = gain @ deviation(pose, self.pose)
        rotation = rotation_from_rotvec(step[3:]) @ rotation_from_euler(self.pose[3:])
        fused = np.concatenate([self.pose[:3] + step[:3], euler_from_rotation(rotation)])
        cov_fused = (np.eye(6) - gain) @ P
        return TrackReference(fused, 0.5 * (cov_fused + cov_fused.T), self.frames + 1, 0)
