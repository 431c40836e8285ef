"""Solving a pose problem: :func:`solve` from scratch, :func:`track` a sequence (eq. 2), and the :class:`Solution`.

Both run :func:`evopose.loop.evolve`, the one generation loop: :func:`solve` with the global search
(:class:`evopose.search.EvoPose`), :func:`track` with one warm-started generation
(:class:`evopose.local.LocalSearch`) and, when the fit is lost, a new search.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from geometry import matrix_from_pose, pose_from_matrix

from .fitness import Match, PoseObjective
from .local import LocalSearch
from .loop import Evaluator, Run, evolve
from .mixture import mixture_covariance
from .neighbours import nearest_other
from .options import SearchOptions
from .problem import PoseProblem, View
from .refine import TRACK_HARD_SCHEDULE, TRACK_SCHEDULE, annealing, refine
from .robust_fit import robust_fit
from .search import EvoPose
from .trust import (MAX_CONFIDENT_ROTATION_SIGMA, Confidence, assess, checked_in_time, converged, imprecise,
                    track_confidence)
from .uncertainty import TrackReference, rotation_sigma
from .weights import rule_weights

#: Final polish of the best pose: hard nearest-neighbour steps (accepted only when the fitness drops).
POLISH_SCHEDULE = annealing(1, hard=6, start=1.0)
#: Other basins of the final population that are polished and compared with the best (:func:`evopose.trust.assess`).
RIVALS = 8
#: Repeated displacement directions of the model tried as rivals (:func:`shifted_rivals`; each with both signs).
SHIFT_DIRECTIONS = 2
#: Share of the model's marks whose nearest neighbour lies along one displacement for it to count as repeated.
REPEATED_SHARE = 0.2
#: Share of ``time_budget`` the verdict may take after the search (polishing the rivals); past it, not confident.
VERDICT_GRACE = 0.1


@dataclass
class Solution:
    """Result of :func:`solve` or :func:`track`.

    Attributes
    ----------
    pose : array, shape (6,)
        ``world_from_target`` as ``(x, y, z, roll, pitch, yaw)``.
    fitness : float
        Eq. (4) of the best individual.
    view_terms : array, shape (V,)
        Each view's term ``d^(k)`` at the best pose.
    view_weights : array, shape (V,)
        Weights in force at the end (the step rule may have set some to 0).
    generations : int
    evaluations : int
        Projections of the model (fitness evaluations, screening, and the 6 Jacobian
        columns of every refinement step): the budget to compare with other optimisers.
    seconds : float
    converged : bool
        The search stopped because it judged the pose good (consensus, stall, threshold or a confident verdict on a
        common basin, not a budget running out), its match is good and no distinct pose it found fits about as well
        (runner-up margin at least :attr:`evopose.trust.ConfidenceRules.converged_margin`). For :func:`track`: the fit
        held.
        Unlike ``confident``, a statement about the search, not calibrated against the truth.
    stop_reason : str
    history : list of float
        Best fitness per generation.
    from_hint : bool
        A hint (or a descendant of one) reached the best basin.
    reinitialised : bool
        (track) the fit was lost and the search started over.
    covariance : array, shape (6, 6)
        Covariance of the pose in the ROS ``PoseWithCovariance`` convention (docs/protocol.md, "Covariance":
        metres, then radians of small rotations about the fixed X, Y, Z axes) from the fitness landscape at the
        pose (:func:`evopose.uncertainty.covariance`); inf-filled when not computable.
    confident : bool
        In the right basin with high probability: enough marks matched one to one, a tight fit, and no distinct
        pose found by the search fits nearly as well (:func:`evopose.trust.assess`; for :func:`track`, see
        there). A verdict on the answer, calibrated against the truth in ``benchmarks/bench_confidence.py``
        (precision >= 97 % at both image scales, absent targets confident <= 1 %).
    confidence : Confidence or None
        What the verdict rests on (matches, margin over the runner-up basin, the reason when not confident).
    precise : bool (property)
        The covariance places the pose within the target's own size: a pose to act on is converged, confident and
        precise (one camera at the paper's scale is confident, not precise).
    track_reference : TrackReference or None
        (track) The confident frames of the track so far fused into one pose, which the next frame's pose is
        gated against (:func:`evopose.trust.track_confidence`). A frame that jumped away from it is set
        aside (not confident) and the track stands: the next frame starts from its pose too, and is confident
        again if it lies where the track is (at most ``ConfidenceRules.track_set_aside`` such frames in a row).
        None when the track broke otherwise: the next frame starts from this pose and covariance.
    """

    pose: np.ndarray
    fitness: float
    view_terms: np.ndarray
    view_weights: np.ndarray
    generations: int
    evaluations: int
    seconds: float
    converged: bool
    stop_reason: str
    history: list
    from_hint: bool = False
    reinitialised: bool = False
    covariance: np.ndarray = field(default_factory=lambda: np.full((6, 6), np.inf))
    confident: bool = False
    confidence: Confidence | None = field(default=None, repr=False)
    problem: PoseProblem | None = field(default=None, repr=False)
    options: SearchOptions | None = field(default=None, repr=False)
    track_reference: TrackReference | None = field(default=None, repr=False)

    def with_(self, **changes) -> "Solution":
        return replace(self, **changes)

    @property
    def precise(self) -> bool:
        """The covariance places the pose within the target's own size (:func:`evopose.trust.imprecise`
        under the options' rules): what, beside ``converged`` and ``confident``, makes a pose good to act on."""
        if self.problem is None:
            return False
        rules = (self.options or SearchOptions()).confidence
        return not imprecise(self.problem.model.points, self.covariance, rules)


def _rng(seed: int | np.random.Generator | None) -> np.random.Generator:
    return seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)


def solve(problem: PoseProblem, options: SearchOptions | None = None,
          seed: int | np.random.Generator | None = None, *, initial: np.ndarray | None = None,
          hint_source: Callable[[], np.ndarray | None] | None = None,
          on_generation: Callable | None = None) -> Solution:
    """Find the pose of the model in the views (EvoPose, eq. 1-4).

    Parameters
    ----------
    problem : PoseProblem
    options : SearchOptions, optional
    seed : int or numpy Generator, optional
        The same seed reproduces the same result exactly.
    initial : array (K, 6), optional
        Poses for the first generation.
    hint_source : callable () -> array (H, 6) or None, optional
        Polled once per generation for hints that arrived meanwhile (agents pass their inbox).
    on_generation : callable (EvoPoseState) -> None, optional
        Called after every generation (progress, Fig. 6 curves).
    """
    t0 = time.perf_counter()
    options = options or SearchOptions()
    evo = EvoPose(problem, options)
    state, evaluator, rng = evo.start(initial), Evaluator.for_search(problem, options), _rng(seed)
    while True:  # paused once for a verdict on a common best basin (EvoPose.ready): it may end the search
        run = evolve(evo, state, evaluator, hint_source=hint_source, on_generation=on_generation, rng=rng,
                     time_budget=options.time_budget, elapsed_before=time.perf_counter() - t0, pause=evo.ready)
        if run.finished:
            return solution_of(problem, options, run, time.perf_counter() - t0)
        judged = solution_of(problem, options, run, time.perf_counter() - t0, stop_reason="judged", confident_only=True)
        if judged is not None and settles_search(judged):
            return judged
        state, evaluator = evo.judged(run.state), run.evaluator


def settles_search(judged: Solution) -> bool:
    """Whether the verdict ``judged`` on a search's best, taken while its basin is a common one (reached from a few of
    the first starts: :meth:`evopose.search.EvoPose.ready`), ends the search ("judged"): it is confident, and precise
    where its views can make it so. One weighted view far from a small target knows its range only to a metre
    whatever the search does; a confident, imprecise pose of two is a floor not yet found (two assignments compete
    where a later start finds a floor 1 % lower, the covariance a thousandth as wide: tests/test_uncertainty.py's
    two-camera problem).

    An unsure verdict lets the search run on by its rules, whatever the reason: an ambiguous best (a rival within
    the margin) may be beaten, and so may one of few matches or a loose fit (the paper's scale and the boxes: a
    wrong basin reached from 5-7 of the first 96 starts, left for the right one a few generations later). Chosen on
    bench_confidence's problems of seed 101, each search's verdict replayed at every generation (BENCHMARKS.md,
    "When a search may end on a verdict")."""
    confidence = judged.confidence
    if confidence is None or not confidence.confident:
        return False
    return int(np.count_nonzero(judged.view_weights > 0)) < 2 or judged.precise


def published(objective: PoseObjective, basin: np.ndarray, verdict: Confidence) -> tuple[np.ndarray, Confidence]:
    """The pose (6,) to publish for the basin at ``basin`` (6,) that ``verdict`` judged, and the verdict with the
    covariance of that pose: the basin's pose fitted without the false points within tau
    (:func:`evopose.robust_fit.robust_fit`). Which basin, and how sure, is judged where the search and its
    rivals were polished alike (least squares within tau); the covariance is the published pose's under eq. (1)'s
    marginal likelihood (:func:`evopose.mixture.mixture_covariance`: every image point against every visible mark,
    the noise fitted by EM from the pairs' residual scale): the least-squares one on the nearest pairs takes each
    pair as certain and, at the paper's scale, their residuals as the noise, which they understate."""
    pose, matches = robust_fit(objective, basin)
    cov = mixture_covariance(objective, pose, matches)
    if not cov.ok and verdict.confident:   # no finite covariance for what goes out: not sure of it
        return pose, replace(verdict, covariance=cov, confident=False, reason="no covariance")
    # nor for a pose whose covariance leaves its rotation open (past half a turn): it places the pose in no basin
    if verdict.confident and not rotation_sigma(cov.matrix) <= MAX_CONFIDENT_ROTATION_SIGMA:
        return pose, replace(verdict, covariance=cov, confident=False, reason="unbounded rotation")
    return pose, replace(verdict, covariance=cov)


def solution_of(problem: PoseProblem, options: SearchOptions, run: Run, seconds: float,
                stop_reason: str | None = None, *, confident_only: bool = False) -> Solution | None:
    """The :class:`Solution` of a global search's run (:func:`evopose.loop.evolve` of :class:`EvoPose`): its best
    pose polished; ``converged`` only when the run stopped for a good reason (an unfinished run, stopped at a
    deadline, is not converged). ``stop_reason``: the run's own when None (a paused run's verdict: "judged").
    ``confident_only``: None when the verdict is unsure before the published pose is fitted (that fit and its
    covariance only ever take confidence away: a paused search that runs on needs neither)."""
    t0 = time.perf_counter()
    stop_reason = stop_reason or run.told.stop_reason
    state, objective = run.state, run.evaluator.objective
    pose, fitness = state.best_pose, state.best_fitness
    if options.view_weights == "adaptive" and objective.n_views > 1:  # the graded weights of eq. (4) polish the pose
        objective = objective.with_weights(rule_weights(objective, pose, "adaptive", options.view_reject))
        fitness = float(objective(pose[None])[0])
    deadline = None if options.time_budget is None else t0 + (VERDICT_GRACE + 1) * options.time_budget - seconds
    in_time = deadline is None or time.perf_counter() < deadline
    if options.refine_steps and in_time:  # past the budget's grace the best is returned as found (not confident)
        polished, fit = refine(objective, pose[None], np.array([fitness]), POLISH_SCHEDULE)
        pose, fitness = polished[0], float(fit[0])
    mismatch = objective.mismatch(fitness)
    match = Match(None if mismatch is None else float(mismatch), state.best_match.unmatched)
    rivals, checked = _rivals(state, objective, options, deadline)
    checked = checked and in_time   # past the budget's grace no verdict is sure: no more rivals are polished
    if checked and options.refine_steps:  # repeated structure (the best moved by the model's own spacing) and a
        # near-symmetric body (the best turned half round): basins the population need not hold
        rivals = np.concatenate([rivals, shifted_rivals(objective, pose), turned_rivals(objective, pose)])
    # matches judged on every view with its own weight: a view the step rule dropped still counts against a pose
    # (a wrong basin that fits one view and gave up the other must not look sure)
    confidence = assess(objective, pose, rivals, options.confidence,
                        matches_on=objective.with_weights(objective.base_weights))
    confidence = checked_in_time(confidence, checked)  # the other basins not polished in time: not sure
    if confident_only and not confidence.confident:
        return None
    if options.refine_steps and in_time:
        pose, confidence = published(objective, pose, confidence)
        fitness = float(objective(pose[None])[0])
    terms = objective.view_terms(pose[None])[0]
    return Solution(
        pose=pose, fitness=fitness, view_terms=terms, view_weights=objective.weights.copy(),
        generations=state.generation, evaluations=objective.evaluations, seconds=seconds + time.perf_counter() - t0,
        converged=converged(stop_reason, options.is_acceptable(match), confidence, options.confidence),
        stop_reason=stop_reason or "unfinished",
        history=list(state.history), from_hint=state.best_from_hint, problem=problem, options=options,
        covariance=confidence.covariance.matrix, confident=confidence.confident, confidence=confidence)


def repeated_displacements(points: np.ndarray, count: int = SHIFT_DIRECTIONS) -> np.ndarray:
    """The model's most repeated nearest-neighbour displacements, shape (<= 2 * count, 3), in the target frame
    and with both signs: a grid's rows and columns. ``points`` (M, 3)."""
    points = np.asarray(points, float)
    if len(points) < 3:
        return np.zeros((0, 3))
    steps = points[nearest_other(points)] - points
    steps = np.where(_sign(steps)[:, None] < 0, -steps, steps)  # d and -d are one direction
    scale = max(float(np.median(np.linalg.norm(steps, axis=1))), 1e-12)
    _, first, counts = np.unique(np.round(steps / (0.05 * scale)).astype(np.int64), axis=0, return_index=True,
                                    return_counts=True)
    order = np.argsort(-counts, kind="stable")[:count]
    order = order[counts[order] >= max(3, REPEATED_SHARE * len(points))]  # a structure: a good share of the marks
    chosen = steps[first[order]]
    return np.concatenate([chosen, -chosen])


def _sign(v: np.ndarray) -> np.ndarray:
    """Sign of each row's first non-zero component (0 for a zero row)."""
    nz = np.abs(v) > 1e-12
    first = np.argmax(nz, axis=1)
    return np.sign(v[np.arange(len(v)), first]) * nz.any(axis=1)


def shifted_rivals(objective: PoseObjective, pose: np.ndarray) -> np.ndarray:
    """The best ``pose`` (6,) moved by each of :func:`repeated_displacements` of the model (rotated into the world)
    and polished, shape (K, 6): where repeated structure (a chessboard's squares seen without its edge) would let a
    shifted pose fit as well, the search's own population need not hold that basin, and the verdict must see it."""
    shifts = repeated_displacements(objective.problem.model.points)
    if not len(shifts):
        return np.zeros((0, 6))
    rotation = matrix_from_pose(np.asarray(pose, float))[:3, :3]
    moved = np.tile(np.asarray(pose, float), (len(shifts), 1))
    moved[:, :3] += shifts @ rotation.T
    polished, _ = refine(objective, moved, None, POLISH_SCHEDULE)
    return polished


def turned_rivals(objective: PoseObjective, pose: np.ndarray) -> np.ndarray:
    """``pose`` (6,) turned half round about each of the target's axes through its marks' centroid, kept in the box
    and polished, shape (3, 6): a near-symmetric body's twins (the Pioneer's box turned half round fits untyped points
    about as well), which a search's population need not hold and a team-mate's best, taken before any search of the
    vehicle's own (:meth:`evopose.cooperative.Cooperation.estimate`), has none to be judged against without."""
    world_from_target = matrix_from_pose(np.asarray(pose, float))
    rotation, centre = world_from_target[:3, :3], objective.problem.model.points.mean(axis=0)
    turned = []
    for axis in np.eye(3):
        half_turn = 2.0 * np.outer(axis, axis) - np.eye(3)   # rotation by pi about the axis
        matrix = np.eye(4)
        matrix[:3, :3] = rotation @ half_turn
        matrix[:3, 3] = world_from_target[:3, 3] + rotation @ centre - matrix[:3, :3] @ centre
        turned.append(pose_from_matrix(matrix))
    polished, _ = refine(objective, objective.problem.bounds.project(np.array(turned)), None, POLISH_SCHEDULE)
    return polished


def _rivals(state, objective: PoseObjective, options: SearchOptions,
            deadline: float | None = None) -> tuple[np.ndarray, bool]:
    """The best ``RIVALS`` other basins of the final population, polished like the best, shape (K, 6), and
    whether every one was polished before the ``time.perf_counter()`` deadline (one at a time when there is one;
    each on its own, so the result does not depend on it)."""
    order = np.argsort(state.fitness, kind="stable")[1:RIVALS + 1]
    poses, fitness = state.population[order].copy(), state.fitness[order]
    if not (len(poses) and options.refine_steps):
        return poses, True
    if deadline is None:
        return refine(objective, poses, fitness, POLISH_SCHEDULE)[0], True
    for i in range(len(poses)):
        if time.perf_counter() >= deadline:
            return poses, False
        poses[i:i + 1], _ = refine(objective, poses[i:i + 1], fitness[i:i + 1], POLISH_SCHEDULE)
    return poses, True


def pose_mismatch(problem: PoseProblem, pose: np.ndarray, options: SearchOptions | None = None) -> float:
    """:attr:`evopose.fitness.Match.mismatch` of ``pose`` (6,) under the options' bounded fitness ("mutual" when
    they name the paper's unbounded eq. 1): 0 perfect, 1 no match."""
    options = options or SearchOptions()
    objective = PoseObjective(problem, "mutual" if options.fitness == "paper" else options.fitness, options.tau)
    return float(objective.mismatch(objective(np.atleast_2d(pose))[0]))


#: A tracked fit may leave this much more of its eq. (4) unexplained than the previous frame's did (mismatch).
MISMATCH_RISE = 0.2
#: ...and never more than this: most of the image unexplained is a lost fit, whatever came before.
MAX_TRACKED_MISMATCH = 0.75


def tracked_mismatch_bound(previous: Solution, options: SearchOptions, lost_mismatch: float) -> float:
    """The largest mismatch of a frame's tracked fit that still holds (eq. 2): ``lost_mismatch``, or the previous
    fit's own mismatch plus :data:`MISMATCH_RISE` when that is higher, at most :data:`MAX_TRACKED_MISMATCH`.

    The mismatch counts every image point the pose leaves unexplained, the false ones too. A camera image has
    many (the contrast front-end's precision at the paper's scale is ~0.5): the right pose of such a frame
    leaves 0.41-0.61 unexplained while half or more of its marks are matched, and a fixed 0.5 would lose it on 11
    of 20 frames of photoreal-paper-g1-high (``benchmarks/bench_photoreal_tracking.py``; each loss a search of 1-3
    frames, and the two helicopters were good on 11 of 20 frames, now 19, ``bench_photoreal_fleet``). A fit that
    jumped to a wrong pose leaves what the last one explained unexplained: the rise.
    """
    if previous.problem is None or not previous.problem.views:
        return lost_mismatch
    before = pose_mismatch(previous.problem, previous.pose, options)
    if not np.isfinite(before):
        return lost_mismatch
    return float(min(MAX_TRACKED_MISMATCH, max(lost_mismatch, before + MISMATCH_RISE)))


def track(previous: Solution, new_views: list[View] | tuple[View, ...], *, problem: PoseProblem | None = None,
          options: SearchOptions | None = None, seed: int | np.random.Generator | None = None,
          lost_mismatch: float = 0.5, hints: np.ndarray | None = None, search_when_lost: bool = True) -> Solution:
    """Warm-started pose for the next frame (eq. 2): refine the previous pose on the new views.

    The previous pose (and any hints) is refined locally, both by annealed soft matching and by
    nearest-neighbour steps alone; if the best is then lost (the share of its visible marks without a
    one-to-one match above ``lost_mismatch``, or its mismatch above :func:`tracked_mismatch_bound`; always with
    the paper's unbounded fitness), the
    search re-initialises from scratch with the previous pose as a hint.

    A tracked solution has a covariance from its new views and is ``confident`` when the previous solution
    was, the fit held, the marks are still matched well (the match rules of :func:`evopose.trust.assess`)
    and the pose moved within the previous covariance plus a frame's motion
    (:func:`evopose.trust.track_confidence`); a re-initialised one is judged as :func:`solve` judges.

    Parameters
    ----------
    previous : Solution
        The last frame's solution (carries its problem and options).
    new_views : sequence of View
        This frame's image points.
    problem : PoseProblem, optional
        Replaces the previous problem (e.g. new bounds); its views are replaced by ``new_views``.
    hints : array (H, 6), optional
        Team-mates' poses; the better of previous pose and hints wins.
    search_when_lost : bool
        False: a lost fit is returned as it is (``converged`` False, ``stop_reason`` "lost") instead of
        searched again, for a caller that runs its search in time slices (an agent at its camera rate).
    """
    t0 = time.perf_counter()
    base = problem or previous.problem
    if base is None:
        raise ValueError("track needs the previous solution's problem or an explicit problem")
    options = options or previous.options or SearchOptions()
    prob = base.with_views(new_views)
    # a soft step pulled off by a false point is rejected as a whole: nearest-neighbour steps alone, too
    evaluator = Evaluator(PoseObjective(prob, options.fitness, options.tau),
                          exploit=(TRACK_SCHEDULE, TRACK_HARD_SCHEDULE))
    local = LocalSearch(prob.bounds, lost_mismatch=lost_mismatch,
                        lost_fitness_share=tracked_mismatch_bound(previous, options, lost_mismatch))
    state = local.start(previous.pose)
    if hints is not None and np.size(hints):
        state = local.inject(state, hints)
    # a frame set aside as a jump (below) left the track standing: its pose is a start too
    set_aside = not previous.confident and previous.confidence is not None and previous.confidence.reason == "jumped"
    chained = previous.track_reference if set_aside else None
    if chained is not None:
        state = local.inject(state, chained.pose[None])
    run = evolve(local, state, evaluator)
    tracked = run.told.stop_reason == "tracked"
    if tracked or not search_when_lost:
        best, objective = run.state, run.evaluator.objective
        basin = np.array(best.best_pose)
        # confident only while the fit holds inside the previous uncertainty (no population to find rivals in)
        current = assess(objective, basin, None, options.confidence,
                         matches_on=objective.with_weights(objective.base_weights))
        reference = previous.track_reference or TrackReference.of(previous.pose, previous.covariance)
        expected = None if reference is None else reference.predicted(
            np.asarray(options.confidence.track_motion, float))  # this frame's: a frame's motion on
        chain_holds = (previous.confident or chained is not None) and tracked
        confidence = track_confidence(expected, chain_holds, current, basin, options.confidence)
        pose, confidence = published(objective, basin, confidence)
        if confidence.confident:  # this frame joins the track's pose
            reference = expected.fused(pose, confidence.covariance.matrix)
        elif confidence.reason == "jumped":  # set aside: the track stands
            reference = expected.passed_over(options.confidence.track_set_aside)
        else:
            reference = None
        fitness = float(objective(pose[None])[0])
        terms = objective.view_terms(pose[None])[0]
        return Solution(pose=pose, fitness=fitness, view_terms=terms,
                        view_weights=objective.weights.copy(), generations=0, evaluations=objective.evaluations,
                        seconds=time.perf_counter() - t0, converged=tracked, stop_reason="tracked" if tracked else "lost",
                        history=[best.best_fitness], from_hint=best.best_from_hint, problem=prob, options=options,
                        covariance=confidence.covariance.matrix, confident=confidence.confident,
                        confidence=confidence, track_reference=reference)
    starts = np.atleast_2d(previous.pose)
    if hints is not None and np.size(hints):
        starts = np.concatenate([starts, np.atleast_2d(hints)])
    lost = prob.with_hints(np.concatenate([prob.hints, starts]))
    sol = solve(lost, options, seed)
    return sol.with_(reinitialised=True, seconds=time.perf_counter() - t0)
