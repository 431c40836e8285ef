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
the best so far, its mutated children and any newly arrived hints, refined and selected — so an agent
can publish a new best (a hint) many times per camera frame, as in the paper's Experiment 2(b).
Pure numpy: no I/O, no Zenoh.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from .fitness import PoseObjective
from .pose import PARAM_NAMES
from .problem import Bounds, Model, PoseProblem, View
from .refine import TRACK_SCHEDULE, refine
from .search import SearchOptions, Solution
from .solver import solve, track

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
    quality : float
        Match quality in [0, 1], 1 best: one minus the mean normalised view term (robust fitness).
    solved : bool
        The pose was searched from scratch (first frame, or tracking was lost).
    good_after_s : float or None
        Seconds into this estimate at which the best individual was first *good* — the paper's "time to
        a good pose": fitness under a threshold (here the search's confident match quality, or almost
        every visible mark matched one to one). A search goes on after that to confirm the pose.
    """

    solution: Solution
    quality: float
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
    lost_quality : float
        Tracking is lost (and the pose searched again) when the match quality drops under ``1 - lost_quality``.
    """

    def __init__(self, model: Model, bounds: Bounds, options: SearchOptions | None = None, *, seed: int = 0,
                 lost_quality: float = 0.5) -> None:
        self.model, self.bounds = model, bounds
        self.options = options or SearchOptions()
        self.seed, self.lost_quality = seed, lost_quality
        self.last: Solution | None = None
        self._objective: PoseObjective | None = None
        self._best_fitness = np.inf  # of ``last`` under ``_objective``
        self._rng = np.random.default_rng([seed, 1])

    def reset(self) -> None:
        """Forget the last pose: the next frame is searched from scratch."""
        self.last, self._objective = None, None

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
                             seed=np.random.default_rng([self.seed, frame]), lost_quality=self.lost_quality,
                             hints=problem.hints if len(problem.hints) else None)
            solved = solution.stop_reason != "tracked"
            good_after = solution.seconds if solution.converged else None
        else:
            scale = PoseObjective(problem, self.options.fitness, self.options.tau).fitness_scale()
            good_after = None

            def watch(state) -> None:
                nonlocal good_after
                if good_after is None and self._good_now(state.best_fitness, state.best_unmatched, scale):
                    good_after = time.perf_counter() - t0
                if on_generation is not None:
                    on_generation(state)

            solution = solve(problem, self.options, seed=np.random.default_rng([self.seed, frame]),
                             hint_source=hint_source, on_generation=watch)
            solved = True
            if not solution.converged:
                good_after = None
        return self._keep(solution, problem, solved, good_after)

    def _good_now(self, fitness: float, unmatched: float, scale: float | None) -> bool:
        o = self.options
        return scale is None or fitness <= o.confident_quality * scale or unmatched <= o.confident_unmatched

    def generation(self, hints: np.ndarray | None = None) -> Estimate | None:
        """One generation on the last frame's views: the best, mutated children and ``hints`` (H, 6), refined;
        the fittest becomes the best. None before the first estimate."""
        if self.last is None or self._objective is None:
            return None
        best = np.asarray(self.last.pose, float)
        scale = np.r_[np.full(3, CHILD_STEP_POSITION * max(np.linalg.norm(best[:3]), 1.0)),
                      np.full(3, CHILD_STEP_ANGLE)]
        children = best + self._rng.standard_normal((GENERATION_CHILDREN, 6)) * scale
        parts = [best[None], children]
        if hints is not None and np.size(hints):
            parts.append(np.atleast_2d(np.asarray(hints, float)).reshape(-1, 6))
        bounds = self.last.problem.bounds if self.last.problem is not None else self.bounds
        candidates = bounds.project(np.concatenate(parts))
        fitness = self._objective(candidates)
        candidates, fitness = refine(self._objective, candidates, fitness, TRACK_SCHEDULE)
        i = int(np.argmin(fitness))
        if fitness[i] < self._best_fitness:
            self._best_fitness = float(fitness[i])
            solution = self.last.with_(pose=candidates[i], fitness=float(fitness[i]),
                                       view_terms=self._objective.view_terms(candidates[i][None])[0],
                                       from_hint=i > GENERATION_CHILDREN,
                                       generations=self.last.generations + 1,
                                       history=[*self.last.history[-HISTORY_KEPT + 1:], float(fitness[i])])
            self.last = solution
        return Estimate(self.last, self._quality(self.last.pose), False)

    def _keep(self, solution: Solution, problem: PoseProblem, solved: bool, good_after: float | None) -> Estimate:
        self._objective = PoseObjective(solution.problem or problem, self.options.fitness, self.options.tau)
        if len(solution.view_weights) == self._objective.n_views and np.any(solution.view_weights > 0):
            self._objective.weights = np.asarray(solution.view_weights, float).copy()  # the step rule's (eq. 4)
        self._best_fitness = float(self._objective(np.atleast_2d(solution.pose))[0])
        quality = self._quality(solution.pose)
        self.last = solution if solution.converged else None
        if self.last is None:
            self._objective = None
        return Estimate(solution, quality, solved, good_after)

    def _quality(self, pose: np.ndarray) -> float:
        objective = self._objective
        if objective is None:
            return 0.0
        terms = objective.view_terms(np.atleast_2d(pose))[0]
        w = objective.base_weights
        return float(np.clip(1.0 - np.sum(w * terms / objective.taus) / np.sum(w), 0.0, 1.0))


__all__ = ["CooperativeEstimator", "Estimate", "Knowledge", "constrained_bounds"]
