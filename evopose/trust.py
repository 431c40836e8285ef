"""Whether to trust an estimate, and why: the one verdict (docs/design.md §2, "Trust", and its glossary).

Every rule that says whether a pose may be acted on lives here, and each caller reads its answer:

* **confident** (:func:`assess`): enough marks matched one to one, a fit as tight as point noise allows, and no
  *distinct* pose, found by the search itself, that fits nearly as well. Distinct: outside the estimate's own
  uncertainty (a Mahalanobis distance over ``distinct_sigmas``), on other pairs of marks and image points, and not
  the same image (a symmetry of the model is one answer). "Nearly as well": ``(S_alt - S_best) / s^2``, twice a
  log-likelihood ratio of the truncated sums of squares (:func:`evopose.uncertainty.sum_of_squares`). A tracked
  frame, which has no population of rivals, is confident while it stays where its track is
  (:func:`track_confidence`); a search whose rivals were not all polished in time is not (:func:`checked_in_time`); a
  confirming search's confident answer at the tracked pose makes it confident (:func:`confirms`);
* **converged** (:func:`converged`): the search stopped because it judged its best good (consensus, stall or
  threshold, not a budget running out), its match is acceptable and the runner-up fits clearly worse;
* **precise** (:func:`imprecise`): the covariance places the pose within the target's own size;
* the published track's standing (:func:`settled`; :class:`evopose.pose_filter.PoseFilter` fuses the frames):
  a frame fused into a track that knows its rotation well enough, or set aside because it jumped off it;
* and, from all of these and whether a search from scratch is still running, the :class:`Trust` of an estimate
  (:func:`judge`): ``searching``, ``unsure`` (with the reason) or ``good``, what a vehicle publishes and counts.

:class:`ConfidenceRules` holds the thresholds, calibrated by ``benchmarks/bench_confidence.py --seed 2026``
against the truth on seeded problems at the telephoto and the paper's image scale (and reported on other seeds).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal, Protocol

import numpy as np

from .covariance import CovarianceEstimate, covariance, deviation, mutual_matches
from .fitness import POINT_NOISE_PX, PoseObjective
from .uncertainty import TrackReference, mahalanobis, rotation_sigma, same_image, shared_pairs, sum_of_squares

__all__ = ["CONFIRM_SIGMAS", "GOOD_REASONS", "MAX_CONFIDENT_ROTATION_SIGMA", "Confidence", "ConfidenceRules", "Judged",
           "Published", "Standing", "Trust", "TrustLevel", "assess", "confirms", "converged", "imprecise",
           "checked_in_time", "judge", "settled", "track_confidence"]

#: Stop reasons of a search that mean "the pose is good" (as opposed to a budget running out).
GOOD_REASONS = ("good_fitness", "consensus", "stalled", "judged")
#: A confirming search's confident pose within this many sigmas (its covariance) of the tracked one confirms it.
CONFIRM_SIGMAS = 4.0
#: No pose is confident whose published covariance (:func:`evopose.solver.published`) leaves its rotation unknown
#: past half a turn (1 sigma, the worst axis, radians): it places the pose in no basin. bench_confidence's
#: calibration set (seed 2026): 9 such confident answers at the paper's scale, 2 of them wrong (precision 98.7 ->
#: 99.5 %); its judging set (seed 7): 4, 2 wrong (96.1 -> 96.9 %); a fresh set (seed 11): 3, none wrong (98.7 %
#: either way); good answers unchanged on all three (a good pose is precise: 5 deg). A confident answer whose own
#: covariance says its rotation is anywhere would tell a reader two things at once.
MAX_CONFIDENT_ROTATION_SIGMA = float(np.pi)


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
        "ambiguous" (the published pose: also "unbounded rotation", :data:`MAX_CONFIDENT_ROTATION_SIGMA`; for
        tracking "previous not confident", "jumped"; for a search past its time "out of time").
    sum_of_squares, runner_up_sum_of_squares : float
        :func:`evopose.uncertainty.sum_of_squares` of the estimate and of the runner-up (inf when there is none).
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
           rules: ConfidenceRules = ConfidenceRules(), matches_on: PoseObjective | None = None) -> Confidence:
    """Covariance and confidence of ``pose`` (6,) given the search's other basins ``alternatives`` (K, 6).

    The alternatives should be local optima of the same objective (the search's final population, polished):
    the best of them outside ``rules.distinct_sigmas`` of the estimate's covariance is the runner-up. The
    covariance and the margin use ``objective`` (eq. 4 with the weights in force); the match rules (pairs,
    unmatched marks) use ``matches_on`` (default ``objective``): with every view at its own weight, a view the
    step rule dropped still counts its unmatched marks against the pose.
    """
    pose = np.asarray(pose, float).reshape(6)
    matches = mutual_matches(objective, pose)
    cov = covariance(objective, pose, matches)
    s_best = sum_of_squares(objective, pose, matches)
    judged = matches if matches_on is None else mutual_matches(matches_on, pose)
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
              else "loose fit" if fit_variance(matches, int(np.count_nonzero(objective.problem.bounds.free)))
              > rules.max_residual_px ** 2
              else "ambiguous" if margin < rules.margin else "")
    return Confidence(reason == "", cov, n_pairs, unmatched, float(margin), runner_up, reason, s_best, s_alt)


#: A pair whose squared residual exceeds this many times the pairs' robust variance is left out of the loose-fit
#: test: 5 sigmas (a 2-D Gaussian's |r|^2 / sigma^2 is chi-squared with 2 degrees of freedom, past 25 once in 270 000
#: pairs), so a robust variance read from twenty pairs, itself off by tens of percent, leaves out no true pair.
FIT_CUTOFF_CHI2 = 25.0


def fit_variance(matches, n_free: int) -> float:
    """The residual variance per pixel coordinate of the mutual pairs ``matches`` (:class:`Matches`) that the
    loose-fit rule judges, ``n_free`` parameters fitted: over the pairs within :data:`FIT_CUTOFF_CHI2` of their
    robust variance (the median of ``|r|^2`` over ``2 ln 2``). One pair of a point with a mark whose own point was
    not found (13 px off at telephoto, among twenty within 3 px) no longer makes a right pose a loose fit; the
    chance pairs of an absent target, spread throughout, still do (inf: too few pairs)."""
    w = matches.weights[matches.view]
    use = w > 0
    r2, w = np.sum(np.asarray(matches.residuals, float)[use] ** 2, axis=1), w[use]
    if 2 * len(r2) - n_free < 1:
        return np.inf
    keep = r2 <= FIT_CUTOFF_CHI2 * float(np.median(r2)) / (2 * np.log(2))
    dof = 2 * int(np.count_nonzero(keep)) - n_free
    return float(np.sum(w[keep] * r2[keep]) / dof) if dof >= 1 else np.inf


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


def checked_in_time(confidence: Confidence, rivals_checked: bool) -> Confidence:
    """The verdict of a search whose rival basins were (``rivals_checked``) or were not all polished before its
    time budget's grace ran out: an unchecked one is not confident ("out of time")."""
    if not rivals_checked and confidence.confident:
        return replace(confidence, confident=False, reason="out of time")
    return confidence


def converged(stop_reason: str | None, acceptable_match: bool, confidence: Confidence,
              rules: ConfidenceRules = ConfidenceRules()) -> bool:
    """Whether a global search converged: it stopped for one of :data:`GOOD_REASONS`, its best's match is
    ``acceptable_match`` (:meth:`evopose.options.SearchOptions.is_acceptable`) and no distinct pose it found fits
    about as well (runner-up margin at least ``rules.converged_margin``). A statement about the search, not
    calibrated against the truth (``confident`` is)."""
    return stop_reason in GOOD_REASONS and acceptable_match and confidence.margin >= rules.converged_margin


def confirms(found_pose: np.ndarray, found_covariance: np.ndarray, anchor: np.ndarray) -> bool:
    """Whether a confirming search's converged, confident pose ``found_pose`` (6,) with ``found_covariance`` (6, 6)
    is the pose tracked when it began, ``anchor`` (6,): within :data:`CONFIRM_SIGMAS` under that covariance."""
    return bool(mahalanobis(deviation(found_pose, anchor), found_covariance)[0] <= CONFIRM_SIGMAS)


def settled(track_covariance: np.ndarray, most_rotation_sigma: float) -> bool:
    """Whether a published track of ``track_covariance`` (6, 6) knows its rotation well enough for what it
    publishes to be good: its worst rotation 1-sigma within ``most_rotation_sigma`` (radians,
    ``ConfidenceRules.max_published_rotation_sigma``)."""
    return rotation_sigma(track_covariance) <= most_rotation_sigma


#: An estimate's trust: a search from scratch still running (its best so far), not good (and why), or good.
TrustLevel = Literal["searching", "unsure", "good"]
#: What the published track made of a frame: judged alone (no track took it: not good on its own, or no track),
#: fused into a settled track, fused into a track not yet settled, or set aside (it jumped off the track).
Standing = Literal["alone", "fused", "unsettled", "set aside"]


@dataclass(frozen=True)
class Trust:
    """The one verdict on an estimate (:func:`judge`; docs/design.md §2, "Trust").

    Attributes
    ----------
    converged : bool
        The search judged its best good (:func:`converged`; for a tracked frame: the fit held).
    confident : bool
        In the right basin with high probability (:func:`assess`, :func:`track_confidence`).
    precise : bool
        The covariance places the pose within the target's own size (not :func:`imprecise`).
    standing : Standing
        What the published track made of the frame ("alone" when it was judged without one).
    searching : bool
        A search from scratch is still running: the pose is its best so far.
    basin_reason : str
        Why the estimate is not confident (:attr:`Confidence.reason`; "" when it is).
    """

    converged: bool
    confident: bool
    precise: bool = False
    standing: Standing = "alone"
    searching: bool = False
    basin_reason: str = ""

    @property
    def in_right_basin(self) -> bool:
        """Converged and confident, precise or not: what a vehicle may offer as a hint, and the frames whose
        errors an agent's summary averages (the paper's Table II averages such estimates)."""
        return self.converged and self.confident

    @property
    def good(self) -> bool:
        """In the right basin, precise, and not held back by the published track: what a vehicle publishes as
        good and counts."""
        return self.in_right_basin and self.precise and self.standing in ("alone", "fused")

    @property
    def set_aside(self) -> bool:
        """Good on its own, but it jumped off the published track."""
        return self.in_right_basin and self.precise and self.standing == "set aside"

    @property
    def level(self) -> TrustLevel:
        return "good" if self.good else "searching" if self.searching else "unsure"

    @property
    def reason(self) -> str:
        """Why the estimate is not good ("" when it is): the first condition that failed."""
        if self.good:
            return ""
        if self.searching:
            return "searching"
        if not self.converged:
            return "not converged"
        if not self.confident:
            return self.basin_reason or "not confident"
        if not self.precise:
            return "imprecise"
        return "track unsettled" if self.standing == "unsettled" else "set aside"


class Judged(Protocol):
    """What :func:`judge` reads of a solution (:class:`evopose.solver.Solution`)."""

    converged: bool
    confident: bool
    confidence: Confidence | None

    @property
    def precise(self) -> bool: ...


class Published(Protocol):
    """What :func:`judge` reads of the published track's answer (:class:`evopose.pose_filter.FilteredPose`)."""

    on_track: bool
    settled: bool


def judge(solution: Judged | None, *, searching: bool = False, published: Published | None = None) -> Trust:
    """The :class:`Trust` of ``solution`` (None: no estimate), while a search from scratch is ``searching`` or not,
    and once the published track has taken the frame (``published``: what it made of a frame good on its own)."""
    if solution is None:
        return Trust(False, False, searching=searching)
    alone = Trust(bool(solution.converged), bool(solution.confident), bool(solution.precise), "alone", searching,
                  "" if solution.confidence is None else solution.confidence.reason)
    if published is None or not alone.good:
        return alone
    standing: Standing = ("set aside" if not published.on_track else "fused" if published.settled
                          else "unsettled")
    return replace(alone, standing=standing)
