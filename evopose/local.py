"""Warm-started search around a known pose (eq. 2) as the same ask / tell as :class:`evopose.search.EvoPose`.

Once a pose is known, the next frame's pose is near it (paper §II, eq. 2): each generation
re-evaluates the incumbent best, a few small mutations of it and any newly arrived hints
(team-mates' full poses, paper §III), all refined by the caller; the fittest becomes the best
only if it beats the incumbent, so a hint that does not fit the own views is discarded.
:func:`evopose.solver.track` runs one such generation per frame, and
:meth:`evopose.cooperative.CooperativeEstimator.generation` one between frames, both through
:func:`evopose.loop.evolve`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .fitness import Match
from .problem import Bounds
from .search import Ask, Judge, Told


@dataclass(frozen=True, eq=False)
class LocalState:
    """The incumbent best and what is queued for the next generation (immutable).

    Attributes
    ----------
    best_pose : array, shape (6,)
    best_fitness : float
        Eq. (4) of ``best_pose`` (inf when not known yet: any candidate replaces it).
    best_origin : int
        0 for the incumbent and its mutations, negative for a hint.
    pending_hints : array, shape (H, 6)
    hints_seen, generation : int
    history : tuple of float
        Best fitness after each generation.
    best_match : Match
        How well the best matches (judged when it changed).
    """

    best_pose: np.ndarray
    best_fitness: float = np.inf
    best_origin: int = 0
    pending_hints: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    hints_seen: int = 0
    generation: int = 0
    history: tuple = ()
    best_match: Match = Match()

    def __post_init__(self) -> None:
        for a in (self.best_pose, self.pending_hints):
            a.flags.writeable = False

    @property
    def population(self) -> np.ndarray:
        """The incumbent as a population of one, shape (1, 6)."""
        return self.best_pose[None]

    @property
    def best_from_hint(self) -> bool:
        return self.best_origin < 0


class LocalSearch:
    """One or more generations around the incumbent pose.

    Parameters
    ----------
    bounds : Bounds
        Every candidate is brought into the box (eq. 3).
    children : int
        Mutated copies of the incumbent per generation.
    child_step : (float, float)
        Their Gaussian step: fraction of the incumbent's distance from the world origin (position, at least
        1 m), and radians (angles).
    generations : int
        Generations before ``tell`` says stop.
    lost_mismatch : float or None
        With a value, the stop reason says whether the fit held: "tracked" when the best's share of visible
        marks without a one-to-one match is within it and its mismatch within ``lost_fitness_share`` (a bounded
        fitness), else "lost". None: "max_generations".
    lost_fitness_share : float or None
        The largest mismatch of a fit that held (None: ``lost_mismatch``). The mismatch counts false image
        points too, so a caller that knows how much of the image the last pose left unexplained raises it
        (:func:`evopose.solver.track`).
    """

    def __init__(self, bounds: Bounds, *, children: int = 0,
                 child_step: tuple[float, float] = (0.0, 0.0), generations: int = 1,
                 lost_mismatch: float | None = None, lost_fitness_share: float | None = None) -> None:
        self.bounds = bounds
        self.children, self.child_step = int(children), child_step
        self.generations, self.lost_mismatch = int(generations), lost_mismatch
        self.lost_fitness_share = lost_mismatch if lost_fitness_share is None else lost_fitness_share

    def start(self, pose: np.ndarray, fitness: float = np.inf) -> LocalState:
        """The incumbent ``pose`` (6,) with its eq. (4) ``fitness`` (inf when unknown under the current views)."""
        return LocalState(np.array(pose, float).reshape(6), float(fitness))

    def inject(self, state: LocalState, hints: np.ndarray) -> LocalState:
        """Queue hints (H, 6) for the next ``ask``."""
        hints = np.atleast_2d(np.asarray(hints, float))
        if not hints.size:
            return state
        return replace(state, pending_hints=np.concatenate([state.pending_hints, hints.reshape(-1, 6)]))

    def ask(self, state: LocalState, rng: np.random.Generator | None = None) -> tuple[LocalState, Ask]:
        """The incumbent, its mutated children (drawn from ``rng``, needed when ``children`` > 0), then the pending
        hints; shapes (K, 6), origins (K,)."""
        best = state.best_pose
        parts = [best[None]]
        if self.children:
            if rng is None:
                raise ValueError("mutated children need a random generator")
            position, angle = self.child_step
            scale = np.r_[np.full(3, position * max(np.linalg.norm(best[:3]), 1.0)), np.full(3, angle)]
            parts.append(best + rng.standard_normal((self.children, 6)) * scale)
        n_hints = len(state.pending_hints)
        parts.append(state.pending_hints)
        origins = np.r_[np.zeros(1 + self.children, int), -1 - state.hints_seen - np.arange(n_hints)]
        asked = Ask(self.bounds.project(np.concatenate(parts)), origins)
        return replace(state, pending_hints=np.zeros((0, 6)), hints_seen=state.hints_seen + n_hints), asked

    def tell(self, state: LocalState, asked: Ask, poses: np.ndarray, fitness: np.ndarray, *,
             judge: Judge | None = None, evaluations: int = 0, elapsed: float = 0.0) -> tuple[LocalState, Told]:
        """The fittest candidate replaces the incumbent if it is strictly better."""
        i = int(np.argmin(fitness))
        improved = bool(fitness[i] < state.best_fitness)
        if improved:
            match = judge(np.array(poses[i]), float(fitness[i])) if judge is not None else Match()
            state = replace(state, best_pose=np.array(poses[i], float), best_fitness=float(fitness[i]),
                            best_origin=int(asked.origins[i]), best_match=match)
        state = replace(state, generation=state.generation + 1, history=state.history + (state.best_fitness,))
        return state, Told(state.generation, state.best_fitness, improved, self._stop_reason(state))

    def rescore(self, state: LocalState, fitness: np.ndarray, *, judge: Judge | None = None,
                evaluations: int = 0, elapsed: float = 0.0) -> tuple[LocalState, Told]:
        """The objective changed: the incumbent's new fitness (1,)."""
        state = replace(state, best_fitness=float(np.asarray(fitness).reshape(-1)[0]))
        if judge is not None:
            state = replace(state, best_match=judge(state.best_pose, state.best_fitness))
        return state, Told(state.generation, state.best_fitness, False, self._stop_reason(state))

    def _stop_reason(self, state: LocalState) -> str | None:
        if state.generation < self.generations:
            return None
        if self.lost_mismatch is None:
            return "max_generations"
        m = state.best_match
        held = (m.mismatch is not None and m.mismatch <= self.lost_fitness_share
                and m.unmatched <= self.lost_mismatch)
        return "tracked" if held else "lost"
