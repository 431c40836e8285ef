"""Honest confidence (issue 11): how uncertain an estimate is, and whether it is the one right answer.

An estimate of ``s = (x, y, z, roll, pitch, yaw)`` gets

* a **covariance** (6, 6) in the convention of ROS ``PoseWithCovariance`` (docs/protocol.md, "Covariance":
  metres, then small rotations about the fixed X, Y, Z axes in radians), from the fitness
  landscape at the optimum (:func:`evopose.covariance.covariance`): the Gauss-Newton normal matrix ``J^T W J``
  of the matched point residuals over all views (eq. 4: view ``k`` weighted by its ``W_k``), scaled by the
  residual variance ``s^2 = sum r^2 / (2m - n_free)``; the matched points are the mutual nearest neighbours
  within tau of eq. (1)'s distance. The search box and the eq. (3) constraints enter as a uniform prior (a
  parameter held in ``[C - eps, C + eps]``: at most ``eps^2 / 3``; a fixed one: 0; a periodic angle: none);
* a verdict **confident** (:func:`assess`): enough marks matched one to one, a fit as tight as point noise
  allows, and no *distinct* pose, found by the search itself, that fits nearly as well. Distinct: outside the
  estimate's own uncertainty (a Mahalanobis distance over ``distinct_sigmas``), on other pairs of marks and
  image points, and not the same image (a symmetry of the model is one answer). "Nearly as well":
  ``(S_alt - S_best) / s^2``, twice a log-likelihood ratio of the truncated sums of squares
  (:func:`sum_of_squares`).

:class:`ConfidenceRules` holds the thresholds, calibrated by ``benchmarks/bench_confidence.py --seed 2026``
against the truth on seeded problems at the telephoto and the paper's image scale (and reported on other seeds).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from geometry import euler_from_rotation, rotation_from_euler

from .covariance import (CovarianceEstimate, Matches, covariance, deviation, in_box_second_moment, mutual_matches,
                         projection_jacobian, untruncated_variance)
from .fitness import POINT_NOISE_PX, PoseObjective

__all__ = ["Confidence", "ConfidenceRules", "CovarianceEstimate", "Matches", "assess", "covariance", "deviation",
           "imprecise", "in_box_second_moment", "mahalanobis", "mutual_matches", "projection_jacobian",
           "rotation_sigma", "same_image", "shared_pairs", "sum_of_squares", "track_confidence", "TrackReference",
           "untruncated_variance"]


@dataclass(frozen=True)
class ConfidenceRules:
    """When an estimate is called confident (:func:`assess`); calibrated in ``benchmarks/bench_confidence.py``.

    Attributes
    ----------
    min_pairs : int
        Mutual matches (over all weighted views) needed at least.
    max_unmatched : float
        Largest share of the visible marks without a mutual match (:meth:`Matches.unmatched`). 0.4 suited drawn
        marks; on camera frames at the paper's scale the contrast front-end finds ~70 % of the marks and labels
        ~80 % of those right, so the right pose of two cameras leaves 40-50 % of its marks unmatched (Cycles
        frames, BENCHMARKS.md). At 0.5 the seeded absent targets stay good on <= 1 % (``bench_confidence``):
        a wrong basin that matches half the marks by chance is also imprecise or ambiguous.
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
        (tracking) The new pose must lie within this Mahalanobis distance of the track's fused pose
        (:class:`TrackReference`), under the sum of its covariance, the new pose's and the motion allowance...
    track_motion : tuple of 6 floats
        ...``diag(track_motion^2)``, added per frame: the 1-sigma change of each coordinate from one frame to the
        next (metres, then radians about the fixed X, Y, Z axes). The default, 0.1 m and 0.1 rad, suits any
        vehicle at a few m/s filmed at 10 fps; a target model file that says how its target moves
        (``motion``, docs/design.md "Tracking") sets it per frame: the Pioneer does
        not tilt, and a frame that takes a neighbouring basin 10 deg away in roll is no longer let through.
    track_set_aside : int
        A tracked frame that jumped is set aside, not confident, and the track stands for the next frame (which
        also starts from the track's pose); after this many such frames in a row it does not.
    converged_margin : float
        :attr:`evopose.solver.Solution.converged` also needs the runner-up worse by this margin (a search that
        stopped with a distinct pose about as good has not settled anything).
    max_position_sigma : float
        (:func:`imprecise`, not part of ``confident``) Largest 1-sigma position uncertainty (the covariance's worst
        direction) as a share of the target's extent (the diagonal of its marks' bounding box): a good pose is
        right to within the target's own size at three sigmas. One camera 30 m from a 44 cm robot finds the right
        basin but knows its range only to 0.4-1 m (the paper's Table II: H1 alone 2.3 m off in Z); two cameras
        know it to 1-3 cm.
    max_rotation_sigma : float
        Largest 1-sigma rotation uncertainty (radians, the worst axis): 5 deg. (At the paper's scale two cameras
        leave 2-3 deg: marks 3-5 px apart.) What a frame must know to be fused into the published track.
    max_published_rotation_sigma : float
        (:class:`evopose.pose_filter.PoseFilter`) The published track is good only once its fused rotation is
        known to this (1 sigma, radians, the worst axis); inf (the default): any track a precise frame joined. A
        target model file's ``good_within`` sets it to half its rotation, so that a good pose lies within it at two
        sigmas: the Pioneer's 5 deg gives 2.5 deg. One frame at the paper's scale knows its rotation only to 3-4
        deg, precise enough to fuse, not to publish alone: on the low-sun Cycles frames the first of a track was
        5.2 deg off at 1.5 of its sigmas (benchmarks/bench_photoreal_tracking.py).
    """

    min_pairs: int = 7
    max_unmatched: float = 0.5
    max_residual_px: float = 3.0 * POINT_NOISE_PX
    margin: float = 12.0
    distinct_sigmas: float = 4.0
    same_pairs: float = 0.5
    track_sigmas: float = 4.0
    track_motion: tuple[float, float, float, float, float, float] = (0.1, 0.1, 0.1, 0.1, 0.1, 0.1)
    track_set_aside: int = 3
    converged_margin: float = 4.0
    max_position_sigma: float = 1.0 / 3.0
    max_rotation_sigma: float = float(np.deg2rad(5.0))
    max_published_rotation_sigma: float = float("inf")


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
        far = mahalanobis(deviation(alternatives, pose), cov.matrix) > rules.distinct_sigmas
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


def imprecise(marks: np.ndarray, cov: np.ndarray, rules: ConfidenceRules = ConfidenceRules()) -> bool:
    """Whether a pose with covariance ``cov`` (6, 6) is too uncertain to act on, though perhaps in the right basin:
    the worst direction's position sigma over ``rules.max_position_sigma`` of the target's extent (the diagonal of
    its ``marks`` (M, 3) bounding box), or the worst rotation sigma over ``rules.max_rotation_sigma``. One camera
    far from a small target (the paper's H1 or H2 alone) finds the right basin but not its range. True when the
    covariance is not finite."""
    cov = np.asarray(cov, float)
    if not np.all(np.isfinite(cov)):
        return True
    extent = float(np.linalg.norm(np.ptp(marks, axis=0))) if len(marks) else 0.0
    position = float(np.sqrt(max(np.linalg.eigvalsh(cov[:3, :3]).max(), 0.0)))
    return position > rules.max_position_sigma * extent or rotation_sigma(cov) > rules.max_rotation_sigma


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
        if len(ua):  # each mark within tolerance of the other pose's nearest (k-d trees: no K x K matrix)
            a_to_b, _ = cKDTree(ub).query(ua, distance_upper_bound=tolerance * (1 + 1e-9))
            if not np.all(np.isfinite(a_to_b)):
                return False
            b_to_a, _ = cKDTree(ua).query(ub, distance_upper_bound=tolerance * (1 + 1e-9))
            if not np.all(np.isfinite(b_to_a)):
                return False
    return True


@dataclass(frozen=True, eq=False)
class TrackReference:
    """Eq. (2)'s chain of confident tracked frames as one estimate of the target's pose, for the tracking gate.

    Each confident frame's pose is fused in by its covariance (a Kalman update), and between frames the fused
    pose's covariance grows by the motion allowance (``ConfidenceRules.track_motion``: a random walk). A single
    frame at the paper's scale knows its rotation to 2-5 deg (marks 3-5 px apart), so a frame that takes a
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
        ``K = P (P + C)^+`` applied to :func:`deviation`, the rotation part turned about the fixed axes."""
        P, C = self.covariance, np.asarray(cov, float)
        gain = P @ np.linalg.pinv(P + C, rcond=1e-12, hermitian=True)
        step = gain @ deviation(pose, self.pose)
        rotation = Rotation.from_rotvec(step[3:]).as_matrix() @ rotation_from_euler(self.pose[3:])
        fused = np.concatenate([self.pose[:3] + step[:3], euler_from_rotation(rotation)])
        cov_fused = (np.eye(6) - gain) @ P
        return TrackReference(fused, 0.5 * (cov_fused + cov_fused.T), self.frames + 1, 0)


def track_confidence(expected: TrackReference | None, previous_confident: bool, current: Confidence,
                     pose: np.ndarray, rules: ConfidenceRules = ConfidenceRules()) -> Confidence:
    """Confidence of a warm-started estimate (eq. 2), which has no population of other basins to compare with.

    Confident when the previous estimate was, the new pose (6,) is still matched well (``current``, from
    :func:`assess` without alternatives, passes the match rules) and it lies within ``rules.track_sigmas`` of where
    the track ``expected`` it (the confident frames since the last search fused, :class:`TrackReference`, already
    :meth:`~TrackReference.predicted` by a frame's motion ``rules.track_motion``), under that covariance plus the
    current one. The
    runner-up margin is not re-examined: the previous verdict carries over while the fit holds and stays
    where the track has been, give or take the motion the target can make.
    """
    cov = current.covariance
    reason = current.reason if current.reason != "ambiguous" else ""
    if not reason and (not previous_confident or expected is None):
        reason = "previous not confident"
    if not reason:
        if mahalanobis(deviation(pose, expected.pose), expected.covariance + cov.matrix)[0] > rules.track_sigmas:
            reason = "jumped"
    return Confidence(reason == "", cov, current.n_pairs, current.unmatched, current.margin, current.runner_up,
                      reason, current.sum_of_squares, current.runner_up_sum_of_squares)
