"""One vehicle's estimator state and its results (paper §III): frozen values, replaced by each transition of
:class:`evopose.cooperative.Cooperation` (docs/architecture.md, "State has one writer")."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from geometry import wrap_angle

from .loop import Evaluator, Run
from .problem import PoseProblem
from .search import EvoPose
from .solver import Solution


@dataclass(frozen=True)
class Estimate:
    """One frame's result of :class:`evopose.cooperative.Cooperation`; whether to trust it is
    :func:`evopose.trust.judge`'s.

    Attributes
    ----------
    solution : Solution
        ``solution.pose`` is ``world_from_target`` ``(x, y, z, roll, pitch, yaw)``, shape (6,).
    mismatch : float
        :attr:`evopose.fitness.Match.mismatch` of the pose in [0, 1], 0 best: eq. (4) with the weights in
        force over its value when nothing matches (robust fitness; 1 when it cannot be judged).
    solved : bool
        The pose was searched from scratch (first frame, or tracking was lost).
    close_at : float or None
        The ``time.perf_counter()`` instant at which the search's best individual first matched closely
        (:meth:`evopose.options.SearchOptions.is_close`) — for the paper's "time to a good pose": fitness under a
        threshold. A search goes on after that to confirm the pose.
    """

    solution: Solution
    mismatch: float
    solved: bool
    close_at: float | None = None

    @property
    def pose(self) -> np.ndarray:
        return self.solution.pose

    @property
    def converged(self) -> bool:
        """The search's own judgement (:attr:`Solution.converged`); the verdict is :func:`evopose.trust.judge`'s."""
        return bool(self.solution.converged)


def random_key(*seed: int) -> dict:
    """The random stream seeded by ``seed`` as a value: the state of numpy's default bit generator (PCG64), which
    :func:`generator` turns back into a generator at that point of the stream."""
    return np.random.default_rng(list(seed)).bit_generator.state


def generator(key: dict) -> np.random.Generator:
    """A new generator at the point of the stream ``key`` (:func:`random_key`, or a generator's
    ``bit_generator.state`` after it drew): the same key gives the same draws, however often it is used."""
    rng = np.random.Generator(np.random.PCG64())
    rng.bit_generator.state = key
    return rng


@dataclass(frozen=True, eq=False)
class SearchInProgress:
    """A global search in progress (the first pose, after tracking was lost, or confirming a tracked pose), resumed
    slice by slice. A value: the optimiser holds constant rules only, and the search's random stream is ``key``
    (its point after the last slice), so resuming the same value twice gives the same result."""

    optimiser: EvoPose
    run: Run
    problem: PoseProblem
    frame: int
    #: the clock's instant when it started, and when its best first matched closely (or None)
    started: float
    close_at: float | None = None
    #: a confirming search: the tracked pose at the frame it started (its answer is compared with this); None once that
    #: track was lost or replaced (:meth:`EstimatorState.without_anchor`)
    anchor: np.ndarray | None = None
    #: where its random stream stands (:func:`random_key`): each slice draws from :func:`generator` of it
    key: dict | None = None

    def with_hints(self, hints: np.ndarray | None) -> "SearchInProgress":
        """The search with team-mates' poses ``hints`` (H, 6) queued for its next generation."""
        if hints is None or not np.size(hints):
            return self
        return replace(self, run=replace(self.run, state=self.optimiser.inject(self.run.state, hints)))


@dataclass(frozen=True, eq=False)
class EstimatorState:
    """Everything one vehicle's estimator remembers between calls; replaced, never changed.

    Attributes
    ----------
    last : Solution or None
        The pose being tracked (converged), None before the first one or after tracking was lost.
    search, confirm : SearchInProgress or None
        A search from scratch in progress; a search confirming a tracked pose that is not confident.
    evaluator : Evaluator or None
        How the last frame's views evaluate candidates between frames (its objective: the last eq. 4 weights).
    best_fitness : float
        Of ``last`` under ``evaluator.objective``.
    frame : int
        The frame last estimated.
    instant : float
        When that frame's images were taken, in frame periods (eq. 2's motion is per period of the images' time,
        not of the frames an estimator processed: a vehicle that ran a tick late predicts as its team-mates do).
    last_converged, motion : tuple or None
        ``(instant, pose (6,))`` of the last converged estimate; ``(instant, pose change per frame period)`` at it.
    idle : int
        Generations run between frames so far (seeds the next one's mutations).
    """

    last: Solution | None = None
    search: SearchInProgress | None = None
    confirm: SearchInProgress | None = None
    evaluator: Evaluator | None = None
    best_fitness: float = np.inf
    frame: int = 0
    instant: float = 0.0
    last_converged: tuple[float, np.ndarray] | None = None
    motion: tuple[float, np.ndarray] | None = None
    idle: int = 0

    def without_anchor(self) -> "EstimatorState":
        """The state whose confirming search (if any) no longer stands beside a tracked pose: the track it began
        beside was lost or replaced, so the pose it finds is not compared with that one (:attr:`SearchInProgress.anchor`
        None) but tracked onto the newest views (:meth:`evopose.cooperative.Cooperation._confirmed`)."""
        if self.confirm is None or self.confirm.anchor is None:
            return self
        return replace(self, confirm=replace(self.confirm, anchor=None))

    @property
    def searching(self) -> bool:
        """A search from scratch is in progress (the estimates are its best so far: :class:`evopose.trust.Trust`
        ``searching``)."""
        return self.search is not None

    def with_motion(self, solution: Solution | None) -> "EstimatorState":
        """The state remembering ``solution`` (converged, or None) as the last converged estimate, and the velocity
        per frame period between the last two (for eq. 2's prediction), both at :attr:`instant`."""
        instant, previous = self.instant, self.last_converged
        st = replace(self, last_converged=None if solution is None else (instant, np.array(solution.pose)))
        if solution is None or previous is None or instant <= previous[0]:
            return replace(st, motion=None)
        delta = np.array(solution.pose) - previous[1]
        delta[3:] = wrap_angle(delta[3:])
        return replace(st, motion=(instant, delta / (instant - previous[0])))

    @property
    def current_best(self) -> np.ndarray | None:
        """The own best pose now (6,): the tracked pose, the best so far of a search in progress, or None."""
        if self.search is not None:
            state = self.search.run.state
            return np.array(state.best_pose) if len(state.population) else None
        return None if self.last is None else np.array(self.last.pose)


__all__ = ["Estimate", "EstimatorState", "SearchInProgress", "generator", "random_key"]
