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
    good_at : float or None
        The ``time.perf_counter()`` instant at which the best individual was first *good* — for the paper's
        "time to a good pose": fitness under a threshold (here the search's confident mismatch, or almost
        every visible mark matched one to one). A search goes on after that to confirm the pose.
    """

    solution: Solution
    mismatch: float
    solved: bool
    good_at: float | None = None

    @property
    def pose(self) -> np.ndarray:
        return self.solution.pose

    @property
    def good(self) -> bool:
        """Converged (the search's own judgement); the published verdict is :attr:`verdict`."""
        return bool(self.solution.converged)

    @property
    def verdict(self) -> Verdict:
        return verdict(self)


@dataclass(frozen=True)
class Verdict:
    """The one verdict on a pose (docs/design.md §2): ``converged`` (the search judged its best good), ``confident``
    (no distinct pose fits nearly as well: the right basin), ``precise`` (its covariance places it within the
    target's own size, :attr:`evopose.solver.Solution.precise`), ``on_track`` (the published track took it:
    :class:`evopose.pose_filter.PoseFilter`; a frame judged alone leaves it True), ``settled`` (the track it
    joined knows its rotation well enough to publish: ``ConfidenceRules.max_published_rotation_sigma``; True for a
    frame judged alone); ``good`` = all five, what a vehicle publishes and counts. ``in_right_basin`` = converged
    and confident, what a vehicle may offer its team-mates as a hint."""

    converged: bool
    confident: bool
    precise: bool = False
    on_track: bool = True
    settled: bool = True

    @property
    def in_right_basin(self) -> bool:
        return self.converged and self.confident

    @property
    def good(self) -> bool:
        return self.converged and self.confident and self.precise and self.on_track and self.settled

    @property
    def set_aside(self) -> bool:
        """Good on its own, but it jumped off the published track (:class:`evopose.pose_filter.PoseFilter`)."""
        return self.converged and self.confident and self.precise and not self.on_track


def verdict(estimate: "Estimate | None") -> Verdict:
    """The verdict on an estimate (none: neither)."""
    if estimate is None:
        return Verdict(False, False)
    sol = estimate.solution
    return Verdict(bool(sol.converged), bool(getattr(sol, "confident", False)), bool(getattr(sol, "precise", False)))


@dataclass(frozen=True, eq=False)
class _Search:
    """A global search in progress (the first pose, or after tracking was lost), resumed slice by slice."""

    optimiser: EvoPose
    run: Run
    problem: PoseProblem
    frame: int
    #: perf_counter when it started, and when its best was first good (or None)
    started: float
    good_at: float | None = None
    #: a confirming search: the tracked pose at the frame it started (its answer is compared with this)
    anchor: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class EstimatorState:
    """Everything one vehicle's estimator remembers between calls; replaced, never changed.

    Attributes
    ----------
    last : Solution or None
        The pose being tracked (converged), None before the first one or after tracking was lost.
    search, confirm : _Search or None
        A search from scratch in progress; a search confirming a tracked pose that is not confident.
    evaluator : Evaluator or None
        How the last frame's views evaluate candidates between frames (its objective: the last eq. 4 weights).
    best_fitness : float
        Of ``last`` under ``evaluator.objective``.
    frame : int
        The frame last estimated.
    good, motion : tuple or None
        ``(frame, pose (6,))`` of the last good estimate; ``(frame, pose change per frame)`` at it.
    idle : int
        Generations run between frames so far (seeds the next one's mutations).
    """

    last: Solution | None = None
    search: _Search | None = None
    confirm: _Search | None = None
    evaluator: Evaluator | None = None
    best_fitness: float = np.inf
    frame: int = 0
    good: tuple[int, np.ndarray] | None = None
    motion: tuple[int, np.ndarray] | None = None
    idle: int = 0

    @property
    def searching(self) -> bool:
        """A search from scratch is in progress (the estimates are the best so far, not good)."""
        return self.search is not None

    @property
    def current_best(self) -> np.ndarray | None:
        """The own best pose now (6,): the tracked pose, the best so far of a search in progress, or None."""
        if self.search is not None:
            state = self.search.run.state
            return np.array(state.best_pose) if len(state.population) else None
        return None if self.last is None else np.array(self.last.pose)


def _injected(search: _Search, hints: np.ndarray | None) -> _Search:
    if hints is None or not np.size(hints):
        return search
    return replace(search, run=replace(search.run, state=search.optimiser.inject(search.run.state, hints)))


def _remember_motion(st: EstimatorState, solution: Solution | None) -> EstimatorState:
    """The velocity per frame between the last two good estimates (for eq. 2's prediction)."""
    frame, previous = st.frame, st.good
    st = replace(st, good=None if solution is None else (frame, np.array(solution.pose)))
    if solution is None or previous is None or frame <= previous[0]:
        return replace(st, motion=None)
    delta = np.array(solution.pose) - previous[1]
    delta[3:] = wrap_angle(delta[3:])
    return replace(st, motion=(frame, delta / (frame - previous[0])))



__all__ = ["Estimate", "EstimatorState", "Verdict", "verdict"]
