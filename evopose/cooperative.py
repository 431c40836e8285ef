"""Cooperative localization (paper §III): one vehicle's estimator fed by what its team shares.

A :class:`CooperativeEstimator` keeps the tracking state of one vehicle and, per camera frame,
combines whatever the team provides:

* several views — its own image points and team-mates' feature sets, each with its camera (eq. 4);
* external knowledge of some parameters — an IMU attitude, a laser distance — held within
  ``[C - eps, C + eps]`` (eq. 3, :class:`Knowledge`);
* team-mates' full poses (hints), which enter the search as individuals; selection on the own
  views discards those that do not fit (§III, last paragraph).

The first pose is found by the global search of :func:`evopose.solve` (:class:`evopose.search.EvoPose`), run
in time slices so that a vehicle keeps its camera rate; later frames are tracked (eq. 2) from the last pose.
Between frames :meth:`CooperativeEstimator.generation` runs one small generation on the latest views —
the best so far, its mutated children and any newly arrived hints, refined and selected
(:class:`evopose.local.LocalSearch` through :func:`evopose.loop.evolve`, the loop :func:`evopose.solve`
uses) — so an agent can publish a new best (a hint) many times per camera frame, as in the paper's
Experiment 2(b).
The estimator's memory is one frozen :class:`EstimatorState`; :class:`Cooperation` (frozen: model, box,
options, seed) turns a state and a frame into the next state and an :class:`Estimate`, as the search is ask/tell
(docs/architecture.md, "State has one writer"). :class:`CooperativeEstimator` holds one state for callers that
want an object. Pure numpy: no I/O, no Zenoh.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from geometry import pose_difference

from .fitness import PoseObjective
from .knowledge import Knowledge, constrained_bounds
from .local import LocalSearch
from .loop import Evaluator, Run, evolve
from .options import SearchOptions
from .problem import Bounds, Model, PoseProblem, View
from .refine import TRACK_SCHEDULE
from .search import EvoPose, Told
from .solver import Solution, solution_of, track, turned_rivals
from .estimator_state import Estimate, EstimatorState, SearchInProgress, generator, random_key
from .trust import assess, confirms

#: Fitness values kept in a solution's history by :meth:`CooperativeEstimator.generation` (bounded memory).
HISTORY_KEPT = 256
#: Children of the best per :meth:`CooperativeEstimator.generation`.
GENERATION_CHILDREN = 4
#: Mutation step of those children: fraction of the target's distance (position), radians (angles).
CHILD_STEP_POSITION, CHILD_STEP_ANGLE = 0.002, 0.005


@dataclass(frozen=True, eq=False)
class Cooperation:
    """Solve, then track, the target's pose from the own and the team's data (eq. 1-4 and hints): the transitions
    ``(state, frame) -> (state', Estimate)`` of one vehicle's estimator.

    Real time: :meth:`estimate` and :meth:`generation` take a time budget. A search from scratch that does not
    finish within it is kept in the state and resumed by the next call (on the views it started with, as the
    paper's Experiment 1 searches one snapshot); meanwhile each call returns the best so far (searching). Once the
    search converges, that pose is tracked (eq. 2) onto the newest views.

    Attributes
    ----------
    model : Model
        Target marks in the target frame, shape (M, 3).
    bounds : Bounds
        The operating area (search box), world frame.
    options : SearchOptions
    seed : int
        Seeds every search; a search started at frame ``n`` uses ``(seed, n)``, so two vehicles given the same
        inputs compute the same pose.
    lost_mismatch : float
        Tracking is lost (and the pose searched again) when the share of the visible marks without a one-to-one
        match exceeds this, or the mismatch exceeds :func:`evopose.solver.tracked_mismatch_bound` (this, or the
        previous fit's own plus a rise).
    """

    model: Model
    bounds: Bounds
    options: SearchOptions = field(default_factory=SearchOptions)
    seed: int = 0
    lost_mismatch: float = 0.5

    def problem(self, views: Sequence[View], knowledge: Sequence[Knowledge] = (),
                hints: np.ndarray | None = None) -> PoseProblem:
        """The pose problem of one frame: ``views`` (eq. 4), ``knowledge`` (eq. 3), ``hints`` (H, 6)."""
        hints = np.zeros((0, 6)) if hints is None else np.atleast_2d(np.asarray(hints, float)).reshape(-1, 6)
        return PoseProblem(self.model, tuple(views), constrained_bounds(self.bounds, knowledge), hints)

    def estimate(self, st: EstimatorState, views: Sequence[View], *, knowledge: Sequence[Knowledge] = (),
                 hints: np.ndarray | None = None, frame: int = 0, instant: float | None = None,
                 budget_s: float | None = None,
                 candidates: np.ndarray | None = None, candidate_margin: float = 0.0,
                 generations: int | None = None, clock: Callable[[], float] = time.perf_counter
                 ) -> tuple[EstimatorState, Estimate]:
        """The next state and the pose at one frame from ``views`` (own and team-mates'), ``knowledge``, ``hints``.

        Parameters
        ----------
        views : sequence of View
            At least one; a view's ``weight`` is its W of eq. (4).
        knowledge : sequence of Knowledge
            Eq. (3) constraints known now (e.g. this frame's IMU attitude).
        hints : array (H, 6), optional
            Team-mates' poses received since the last frame.
        frame : int
            Frame number, for the seed of a search from scratch.
        instant : float, optional
            When the views' images were taken, in frame periods (None: ``frame``): eq. (2)'s constant-velocity
            prediction moves by the images' time, so a vehicle processing an instant a tick late predicts the pose
            its team-mates do.
        budget_s : float, optional
            Seconds a search from scratch may run in this call (None: until it stops); tracking is not cut.
        candidates : array (K, 6), optional
            Team-mates' best poses sent with the views (our extension of Experiment 2(a)). The own best and
            these are weighed on this frame's eq. (4) and the fittest is tracked (eq. 2); when that holds, it
            is the estimate, and a search in progress ends. Team-mates given the same views and candidates
            therefore publish the same pose.
        candidate_margin : float
            0: the fittest wins (feature sets: every vehicle must choose the same). > 0 (hints): a candidate
            whose mismatch on the own views is within this of the own best's is preferred, because the own
            views cannot tell them apart and the team-mate, seeing from elsewhere, can: so no vehicle stays in
            a wrong basin that its team-mate's pose would fix.
        generations : int, optional
            A search from scratch runs this many generations in this call (``budget_s`` still caps it): slices
            that team-mates with the same views run alike, so their best so far agree too.
        clock : callable () -> float
            The clock, seconds (``time.perf_counter``): deadlines, the search's seconds and the instants a search
            started and first matched closely are read on it. The random streams are the state's (each search's
            ``key``), so the same state, inputs and clock readings give the same estimate and state.
        """
        if not views:
            raise ValueError("estimate needs at least one view")
        problem = self.problem(views, knowledge, hints)
        deadline = None if budget_s is None else clock() + budget_s
        st = replace(st, frame=frame, instant=float(frame if instant is None else instant))
        start = self.start(st, problem, candidates, candidate_margin)
        if start is not None:
            own_last = st.last is not None and st.search is None and np.array_equal(start, st.last.pose)
            previous = (st.last if own_last
                        else self._solution_at(start, problem, self._rivals(st, start, candidates)))
            predicted = self._predicted(st, start)
            extra = problem.hints if predicted is None else np.concatenate([problem.hints, predicted[None]])
            solution = track(previous.with_(pose=start), list(views), problem=problem, options=self.options,
                             seed=np.random.default_rng([self.seed, frame]), lost_mismatch=self.lost_mismatch,
                             hints=extra if len(extra) else None, search_when_lost=False)
            if not own_last and (st.last is None or not confirms(start, st.last.covariance, st.last.pose)):
                # the track jumped (a team-mate's or a search's pose elsewhere than the own track, under its
                # covariance): a confirming search in progress no longer confirms the pose it began beside
                st = st.without_anchor()
            if solution.converged:
                st, solution = self._confirmed(replace(st, search=None), solution, problem, frame, deadline,
                                               generations, clock)
                return self._keep(st, solution, problem, False, clock())
            if st.search is None:  # lost: search again, with the lost pose as a hint
                st = replace(st.without_anchor(), last=None)
                problem = problem.with_hints(np.concatenate([problem.hints, solution.pose[None]]))
        if st.search is None:
            optimiser = self._optimiser(problem, generations)
            run = Run(optimiser.start(), Told(0, np.inf, False, None), Evaluator.for_search(problem, self.options),
                      0.0)
            st = replace(st, search=SearchInProgress(optimiser, run, problem, frame, clock(),
                                                     key=random_key(self.seed, frame)))
        else:
            st = replace(st, search=st.search.with_hints(hints))
        return self._advance(st, deadline, problem, generations, clock)

    def _confirmed(self, st: EstimatorState, solution: Solution, problem: PoseProblem, frame: int,
                   deadline: float | None, generations: int | None, clock: Callable[[], float]
                   ) -> tuple[EstimatorState, Solution]:
        """A tracked pose that is not confident (its chain of warm starts broke, or began at a team-mate's best)
        is confirmed by a global search in slices beside the tracking: confident when that search, which sees
        every basin, finds this pose confidently; replaced when it finds another basin confidently."""
        if solution.confident:
            return replace(st, confirm=None), solution
        search = st.confirm
        if search is None:
            optimiser = self._optimiser(problem, generations)
            evaluator = Evaluator.for_search(problem, self.options)
            search = SearchInProgress(optimiser, Run(optimiser.start(), Told(0, np.inf, False, None), evaluator, 0.0),
                                      problem, frame, clock(), anchor=np.array(solution.pose),
                                      key=random_key(self.seed, frame, 2))
        until = None if generations is None else search.run.told.generation + generations
        rng = generator(search.key)
        run = evolve(search.optimiser, search.run.state, search.run.evaluator, deadline=deadline,
                     elapsed_before=search.run.seconds, until_generation=until, time_budget=self.options.time_budget,
                     rng=rng, clock=clock)
        if not run.finished:
            return replace(st, confirm=replace(search, run=run, key=rng.bit_generator.state)), solution
        st = replace(st, confirm=None)
        found = solution_of(search.problem, self.options, run, run.seconds)
        if not (found.converged and found.confident):
            return st, solution
        if search.anchor is not None and confirms(found.pose, found.covariance, search.anchor):
            # the pose tracked then, and tracked since without a break: confident again
            return st, solution.with_(confident=True, confidence=found.confidence, track_reference=None)
        # the target's motion since the search began, where the track since then is one chain (else none: tracking
        # from the found pose takes up what the target moved in the meantime)
        moved = np.zeros(6) if search.anchor is None else pose_difference(solution.pose, search.anchor)
        relocated = track(found.with_(pose=found.pose + moved), list(problem.views), problem=problem,
                          options=self.options,
                          seed=np.random.default_rng([self.seed, frame, 3]), lost_mismatch=self.lost_mismatch,
                          search_when_lost=False)
        return st, (relocated if relocated.converged else solution)

    def _optimiser(self, problem: PoseProblem, generations: int | None) -> EvoPose:
        """The global search of ``problem``. In slices of a fixed number of ``generations`` (team-mates with the same
        views: :meth:`estimate`) it stops at the starts ``min_starts`` asks for, not earlier when settled
        (:meth:`evopose.search.EvoPose.settled`): their searches, seeded apart, must end in the same slice to
        begin their tracks from the same weighed pose. At 4 generations a frame none ends in its first (249 starts,
        fewer than 256); a settled stop ends one team-mate's there and not the other's, and each then publishes its
        own track (tests/test_paper_scale.py: 0 of 20 frames the same). The slices are generations, not time, so an
        earlier stop would save no frame time there."""
        return EvoPose(problem, self.options if generations is None else replace(self.options, settled_supporters=0))

    @staticmethod
    def _predicted(st: EstimatorState, start: np.ndarray) -> np.ndarray | None:
        """Eq. (2) with a constant-velocity guess: ``start`` moved on by the motion between the last two converged
        estimates to the state's :attr:`~EstimatorState.instant`, for a target that moves between frames (None
        without two of them)."""
        if st.motion is None or st.instant <= st.motion[0]:
            return None
        return start + st.motion[1] * (st.instant - st.motion[0])

    def start(self, st: EstimatorState, problem: PoseProblem, candidates: np.ndarray | None,
              margin: float = 0.0) -> np.ndarray | None:
        """The pose to track from: the fittest (eq. 4 of ``problem``) of the own best and ``candidates``; without
        candidates, the last pose while tracking, else None. Ties go to the lexicographically smallest pose,
        so every vehicle with the same inputs chooses the same. With ``margin`` > 0 the fittest candidate wins
        over the own best when its mismatch is at most ``margin`` higher."""
        tracking = None if st.last is None or st.search is not None else np.array(st.last.pose)
        if candidates is None or not np.size(candidates):
            return tracking
        pool = np.atleast_2d(np.asarray(candidates, float)).reshape(-1, 6)
        pool = problem.bounds.project(pool[np.all(np.isfinite(pool), axis=1)])
        own = st.current_best
        if not len(pool):
            return tracking
        objective = PoseObjective(problem, self.options.fitness, self.options.tau)
        fitness = objective(pool)
        best = pool[np.lexsort((*pool.T[::-1], fitness))[0]]
        if own is None:
            return best
        own_fitness, best_fitness = float(objective(own[None])[0]), float(np.min(fitness))
        if margin > 0:
            own_mismatch, best_mismatch = objective.mismatch(own_fitness), objective.mismatch(best_fitness)
            if own_mismatch is not None and best_mismatch <= own_mismatch + margin:
                return best
            return best if best_fitness < own_fitness else own
        both = np.concatenate([own[None], pool])
        return both[np.lexsort((*both.T[::-1], np.concatenate([[own_fitness], fitness])))[0]]

    def _solution_at(self, pose: np.ndarray, problem: PoseProblem, rivals: np.ndarray | None = None) -> Solution:
        """A stand-in previous solution at ``pose`` (a team-mate's best) for :func:`track`, with its confidence
        judged on ``problem`` against ``rivals`` (K, 6): the other candidates and the own search's basins, and its
        half-turned twins (:func:`evopose.solver.turned_rivals`)."""
        objective = PoseObjective(problem, self.options.fitness, self.options.tau)
        fitness = float(objective(pose[None])[0])
        # a near-symmetric body's half-turned twins are a candidate's first rivals: a team-mate's best, taken before
        # any search of the own, has no other basin to be judged against, and a wrong twin would be sure
        twins = turned_rivals(objective, pose)
        rivals = twins if rivals is None or not len(rivals) else np.concatenate([rivals, twins])
        confidence = assess(objective, pose, rivals, self.options.confidence)
        return Solution(pose=np.array(pose), fitness=fitness, view_terms=objective.view_terms(pose[None])[0],
                        view_weights=objective.weights.copy(), generations=0, evaluations=0, seconds=0.0,
                        converged=False, stop_reason="candidate", history=[fitness], problem=problem,
                        options=self.options, covariance=confidence.covariance.matrix,
                        confident=confidence.confident, confidence=confidence)

    @staticmethod
    def _rivals(st: EstimatorState, start: np.ndarray, candidates: np.ndarray | None) -> np.ndarray:
        """Other answers to weigh a start against: the other candidates and the own search's population."""
        rivals = [np.zeros((0, 6))]
        if candidates is not None and np.size(candidates):
            rivals.append(np.atleast_2d(np.asarray(candidates, float)).reshape(-1, 6))
        if st.search is not None and len(st.search.run.state.population):
            rivals.append(np.asarray(st.search.run.state.population, float))
        pool = np.concatenate(rivals)
        return pool[np.any(np.abs(pool - start) > 1e-9, axis=1)]

    def _advance(self, st: EstimatorState, deadline: float | None, current: PoseProblem | None,
                 generations: int | None = None, clock: Callable[[], float] = time.perf_counter
                 ) -> tuple[EstimatorState, Estimate]:
        """Resume the search in progress until ``deadline`` (or for ``generations``); a finished converged search is
        tracked onto ``current``."""
        search = st.search
        close_at = search.close_at

        def watch(state) -> None:
            nonlocal close_at
            if close_at is None and self.options.is_close(state.best_match):
                close_at = clock()

        until = None if generations is None else search.run.told.generation + generations
        rng = generator(search.key)
        run = evolve(search.optimiser, search.run.state, search.run.evaluator, on_generation=watch,
                     deadline=deadline, elapsed_before=search.run.seconds, until_generation=until,
                     time_budget=self.options.time_budget, rng=rng, clock=clock)
        solution = solution_of(search.problem, self.options, run, run.seconds)
        if not run.finished:
            st = replace(st, search=replace(search, run=run, close_at=close_at, key=rng.bit_generator.state))
            return st, Estimate(solution, self._mismatch_in(solution), False, None)
        st = replace(st, search=None)
        if not solution.converged:
            return self._keep(st, solution, search.problem, True, None)
        if current is not None and current is not search.problem:  # a frame later: onto the newest views
            tracked = track(solution, list(current.views), problem=current, options=self.options,
                            seed=np.random.default_rng([self.seed, search.frame, 1]),
                            lost_mismatch=self.lost_mismatch, search_when_lost=False)
            if tracked.converged:
                solution = tracked.with_(generations=solution.generations, history=solution.history,
                                         from_hint=solution.from_hint)
        return self._keep(st, solution, current or search.problem, True, close_at)

    def generation(self, st: EstimatorState, hints: np.ndarray | None = None, budget_s: float | None = None,
                   clock: Callable[[], float] = time.perf_counter) -> tuple[EstimatorState, Estimate | None]:
        """Improve the estimate between frames; no estimate before the first one.

        With a search from scratch in progress: resume it for up to ``budget_s`` (hints join its population).
        Otherwise one generation on the last frame's views: the best, mutated children and ``hints`` (H, 6),
        refined; the fittest becomes the best if it is better.
        """
        if st.search is not None:
            st = replace(st, search=st.search.with_hints(hints))
            deadline = clock() + (budget_s if budget_s is not None else 0.0)
            return self._advance(st, deadline, None, clock=clock)
        if st.last is None or st.evaluator is None:
            return st, None
        bounds = st.last.problem.bounds if st.last.problem is not None else self.bounds
        local = LocalSearch(bounds, children=GENERATION_CHILDREN, child_step=(CHILD_STEP_POSITION, CHILD_STEP_ANGLE))
        state = local.start(st.last.pose, st.best_fitness)
        if hints is not None and np.size(hints):
            state = local.inject(state, hints)
        run = evolve(local, state, st.evaluator, rng=np.random.default_rng([self.seed, 1, st.idle]))
        st = replace(st, idle=st.idle + 1)
        if run.told.improved:
            best = run.state
            last = st.last.with_(pose=np.array(best.best_pose), fitness=best.best_fitness,
                                 view_terms=st.evaluator.objective.view_terms(best.best_pose[None])[0],
                                 from_hint=best.best_from_hint, generations=st.last.generations + 1,
                                 history=[*st.last.history[-HISTORY_KEPT + 1:], best.best_fitness])
            st = replace(st, last=last, best_fitness=best.best_fitness)
        return st, Estimate(st.last, self._mismatch(st, st.last.pose), False)

    def _mismatch_in(self, solution: Solution) -> float:
        """The mismatch of an unfinished search's best under its own problem."""
        objective = PoseObjective(solution.problem, self.options.fitness, self.options.tau)
        mismatch = objective.mismatch(objective(np.atleast_2d(solution.pose))[0])
        return 1.0 if mismatch is None else float(np.clip(mismatch, 0.0, 1.0))

    def _keep(self, st: EstimatorState, solution: Solution, problem: PoseProblem, solved: bool,
              close_at: float | None) -> tuple[EstimatorState, Estimate]:
        objective = PoseObjective(solution.problem or problem, self.options.fitness, self.options.tau)
        if len(solution.view_weights) == objective.n_views and np.any(solution.view_weights > 0):
            objective = objective.with_weights(solution.view_weights)  # the step rule's (eq. 4)
        st = replace(st, evaluator=Evaluator(objective, exploit=(TRACK_SCHEDULE,)),
                     best_fitness=float(objective(np.atleast_2d(solution.pose))[0]))
        mismatch = self._mismatch(st, solution.pose)
        st = st.with_motion(solution if solution.converged else None)
        if solution.converged:
            st = replace(st, last=solution)
        else:
            st = replace(st, last=None, evaluator=None)
        return st, Estimate(solution, mismatch, solved, close_at)

    @staticmethod
    def _mismatch(st: EstimatorState, pose: np.ndarray) -> float:
        """:attr:`Estimate.mismatch` of ``pose`` under the last frame's objective (1 when it cannot be judged)."""
        objective = st.evaluator.objective if st.evaluator is not None else None
        mismatch = None if objective is None else objective.mismatch(objective(np.atleast_2d(pose))[0])
        return 1.0 if mismatch is None else float(np.clip(mismatch, 0.0, 1.0))


class CooperativeEstimator:
    """A :class:`Cooperation` with its one :class:`EstimatorState`, for callers that want an object (tests, the
    warm-up, benchmarks): each call replaces :attr:`state` whole. The vehicle keeps the state itself
    (:func:`agents.vehicle.step.step`)."""

    def __init__(self, model: Model, bounds: Bounds, options: SearchOptions | None = None, *, seed: int = 0,
                 lost_mismatch: float = 0.5) -> None:
        self.rules = Cooperation(model, bounds, options or SearchOptions(), seed, lost_mismatch)
        self.state = EstimatorState()

    @property
    def options(self) -> SearchOptions:
        return self.rules.options

    @property
    def searching(self) -> bool:
        return self.state.searching

    @property
    def current_best(self) -> np.ndarray | None:
        return self.state.current_best

    def problem(self, views: Sequence[View], knowledge: Sequence[Knowledge] = (),
                hints: np.ndarray | None = None) -> PoseProblem:
        return self.rules.problem(views, knowledge, hints)

    def reset(self) -> None:
        """Forget the last pose and any search in progress: the next frame is searched from scratch."""
        self.state = EstimatorState()

    def estimate(self, views: Sequence[View], **kwargs) -> Estimate:
        """:meth:`Cooperation.estimate` on the held state."""
        self.state, estimate = self.rules.estimate(self.state, views, **kwargs)
        return estimate

    def generation(self, hints: np.ndarray | None = None, budget_s: float | None = None) -> Estimate | None:
        """:meth:`Cooperation.generation` on the held state."""
        self.state, estimate = self.rules.generation(self.state, hints, budget_s)
        return estimate

    def _start(self, problem: PoseProblem, candidates: np.ndarray | None, margin: float = 0.0) -> np.ndarray | None:
        return self.rules.start(self.state, problem, candidates, margin)


__all__ = ["Cooperation", "CooperativeEstimator", "Estimate", "EstimatorState", "Knowledge", "constrained_bounds"]
