"""Cooperative localization (paper §III): one vehicle's estimator fed by what its team shares.

A :class:`CooperativeEstimator` keeps the tracking state of one vehicle and, per camera frame,
combines whatever the team provides:

* several views — its own image points and team-mates' feature sets, each with its camera (eq. 4);
* external knowledge of some parameters — an IMU attitude, a laser distance — held within
  ``[C - eps, C + eps]`` (eq. 3, :class:`Knowledge`);
* team-mates' full poses (hints), which enter the search as individuals; selection on the own
  views discards those that do not fit (§III, last paragraph).

The first pose is found by :func:`evopose.solve`; later frames are tracked (eq. 2) from the last pose.
Between frames :meth:`CooperativeEstimator.generation` runs one small generation on the latest views —
the best so far, its mutated children and any newly arrived hints, refined and selected
(:class:`evopose.local.LocalSearch` through :func:`evopose.loop.evolve`, the loop :func:`evopose.solve`
uses) — so an agent can publish a new best (a hint) many times per camera frame, as in the paper's
Experiment 2(b).
Pure numpy: no I/O, no Zenoh.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from .fitness import PoseObjective
from .local import LocalSearch
from .loop import Evaluator, evolve
from .options import SearchOptions
from .pose import PARAM_NAMES
from .problem import Bounds, Model, PoseProblem, View
from .refine import TRACK_SCHEDULE
from .solver import Solution, solve, track

#: Fitness values kept in a solution's history by :meth:`CooperativeEstimator.generation` (bounded memory).
HISTORY_KEPT = 256
#: Children of the best per :meth:`CooperativeEstimator.generation`.
GENERATION_CHILDREN = 4
#: Mutation step of those children: fraction of the target's distance (position), radians (angles).
CHILD_STEP_POSITION, CHILD_STEP_ANGLE = 0.002, 0.005


@dataclass(frozen=True)
class Knowledge:
    """External knowledge of one parameter (eq. 3): ``s_k`` is ``value`` within ``tolerance`` (0 fixes it).

    ``name`` is one of ``x, y, z, roll, pitch, yaw``; metres or radians.
    """

    name: str
    value: float
    tolerance: float = 0.0

    def __post_init__(self) -> None:
        if self.name not in PARAM_NAMES:
            raise ValueError(f"knowledge of {self.name!r}: expected one of {', '.join(PARAM_NAMES)}")
        if not np.isfinite(self.value) or not np.isfinite(self.tolerance) or self.tolerance < 0:
            raise ValueError(f"knowledge of {self.name}: value and tolerance must be finite, tolerance >= 0")


def constrained_bounds(bounds: Bounds, knowledge: Sequence[Knowledge]) -> Bounds:
    """``bounds`` narrowed by every piece of ``knowledge`` (eq. 3)."""
    for k in knowledge:
        bounds = bounds.constrained(k.name, k.value, k.tolerance)
    return bounds


@dataclass(frozen=True)
class Estimate:
    """One frame's result of :class:`CooperativeEstimator`.

    Attributes
    ----------
    solution : Solution
        ``solution.pose`` is ``world_from_target`` ``(x, y, z, roll, pitch, yaw)``, shape (6,).
    mismatch : float
        :attr:`evopose.fitness.Match.mismatch` of the pose in [0, 1], 0 best: eq. (4) with the weights in
        force over its value when nothing matches (robust fitness; 1 when it cannot be judged).
    solved : bool
        The pose was searched from scratch (first frame, or tracking was lost).
    good_after_s : float or None
        Seconds into this estimate at which the best individual was first *good* — the paper's "time to
        a good pose": fitness under a threshold (here the search's confident mismatch, or almost
        every visible mark matched one to one). A search goes on after that to confirm the pose.
    """

    solution: Solution
    mismatch: float
    solved: bool
    good_after_s: float | None = None

    @property
    def pose(self) -> np.ndarray:
        return self.solution.pose

    @property
    def good(self) -> bool:
        return bool(self.solution.converged)


class CooperativeEstimator:
    """Solve, then track, the target's pose from the own and the team's data (eq. 1-4 and hints).

    Parameters
    ----------
    model : Model
        Target marks in the target frame, shape (M, 3).
    bounds : Bounds
        The operating area (search box), world frame.
    options : SearchOptions, optional
    seed : int
        Seeds every search; frame ``n`` uses ``(seed, n)``, so two vehicles given the same inputs
        compute the same pose.
    lost_mismatch : float
        Tracking is lost (and the pose searched again) when the mismatch exceeds this.
    """

    def __init__(self, model: Model, bounds: Bounds, options: SearchOptions | None = None, *, seed: int = 0,
                 lost_mismatch: float = 0.5) -> None:
        self.model, self.bounds = model, bounds
        self.options = options or SearchOptions()
        self.seed, self.lost_mismatch = seed, lost_mismatch
        self.last: Solution | None = None
        #: how the last frame's views evaluate candidates between frames (its objective: the last eq. 4 weights)
        self._evaluator: Evaluator | None = None
        self._best_fitness = np.inf  # of ``last`` under ``_evaluator.objective``
        self._rng = np.random.default_rng([seed, 1])

    def reset(self) -> None:
        """Forget the last pose: the next frame is searched from scratch."""
        self.last, self._evaluator = None, None

    def problem(self, views: Sequence[View], knowledge: Sequence[Knowledge] = (),
                hints: np.ndarray | None = None) -> PoseProblem:
        """The pose problem of one frame: ``views`` (eq. 4), ``knowledge`` (eq. 3), ``hints`` (H, 6)."""
        hints = np.zeros((0, 6)) if hints is None else np.atleast_2d(np.asarray(hints, float)).reshape(-1, 6)
        return PoseProblem(self.model, tuple(views), constrained_bounds(self.bounds, knowledge), hints)

    def estimate(self, views: Sequence[View], *, knowledge: Sequence[Knowledge] = (),
                 hints: np.ndarray | None = None, frame: int = 0,
                 hint_source: Callable[[], np.ndarray | None] | None = None,
                 on_generation: Callable | None = None) -> Estimate:
        """The pose at one frame from ``views`` (own and team-mates'), ``knowledge`` and ``hints``.

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
        hint_source : callable () -> array (H, 6) or None, optional
            Polled every generation of a search from scratch for hints that arrive meanwhile.
        on_generation : callable (EvoPoseState) -> None, optional
            Called after every generation of a search from scratch (to publish each new best).
        """
        if not views:
            raise ValueError("estimate needs at least one view")
        problem = self.problem(views, knowledge, hints)
        t0 = time.perf_counter()
        if self.last is not None:
            solution = track(self.last, list(views), problem=problem, options=self.options,
                             seed=np.random.default_rng([self.seed, frame]), lost_mismatch=self.lost_mismatch,
                             hints=problem.hints if len(problem.hints) else None)
            solved = solution.stop_reason != "tracked"
            good_after = solution.seconds if solution.converged else None
        else:
            good_after = None

            def watch(state) -> None:
                nonlocal good_after
                if good_after is None and self.options.is_confident(state.best_match):
                    good_after = time.perf_counter() - t0
                if on_generation is not None:
                    on_generation(state)

            solution = solve(problem, self.options, seed=np.random.default_rng([self.seed, frame]),
                             hint_source=hint_source, on_generation=watch)
            solved = True
            if not solution.converged:
                good_after = None
        return self._keep(solution, problem, solved, good_after)

    def generation(self, hints: np.ndarray | None = None) -> Estimate | None:
        """One generation on the last frame's views: the best, mutated children and ``hints`` (H, 6), refined;
        the fittest becomes the best if it is better. None before the first estimate."""
        if self.last is None or self._evaluator is None:
            return None
        bounds = self.last.problem.bounds if self.last.problem is not None else self.bounds
        local = LocalSearch(bounds, self._rng, children=GENERATION_CHILDREN,
                            child_step=(CHILD_STEP_POSITION, CHILD_STEP_ANGLE))
        state = local.start(self.last.pose, self._best_fitness)
        if hints is not None and np.size(hints):
            state = local.inject(state, hints)
        run = evolve(local, state, self._evaluator)
        if run.told.improved:
            best = run.state
            self._best_fitness = best.best_fitness
            self.last = self.last.with_(pose=np.array(best.best_pose), fitness=best.best_fitness,
                                        view_terms=self._evaluator.objective.view_terms(best.best_pose[None])[0],
                                        from_hint=best.best_from_hint, generations=self.last.generations + 1,
                                        history=[*self.last.history[-HISTORY_KEPT + 1:], best.best_fitness])
        return Estimate(self.last, self._mismatch(self.last.pose), False)

    def _keep(self, solution: Solution, problem: PoseProblem, solved: bool, good_after: float | None) -> Estimate:
        objective = PoseObjective(solution.problem or problem, self.options.fitness, self.options.tau)
        if len(solution.view_weights) == objective.n_views and np.any(solution.view_weights > 0):
            objective = objective.with_weights(solution.view_weights)  # the step rule's (eq. 4)
        self._evaluator = Evaluator(objective, exploit=(TRACK_SCHEDULE,))
        self._best_fitness = float(objective(np.atleast_2d(solution.pose))[0])
        mismatch = self._mismatch(solution.pose)
        self.last = solution if solution.converged else None
        if self.last is None:
            self._evaluator = None
        return Estimate(solution, mismatch, solved, good_after)

    def _mismatch(self, pose: np.ndarray) -> float:
        """:attr:`Estimate.mismatch` of ``pose`` under the last frame's objective (1 when it cannot be judged)."""
        objective = self._evaluator.objective if self._evaluator is not None else None
        mismatch = None if objective is None else objective.mismatch(objective(np.atleast_2d(pose))[0])
        return 1.0 if mismatch is None else float(np.clip(mismatch, 0.0, 1.0))


__all__ = ["CooperativeEstimator", "Estimate", "Knowledge", "constrained_bounds"]
