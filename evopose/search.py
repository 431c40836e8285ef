"""The evolutionary search of EvoPose as an explicit ask / tell state machine.

A memetic (mu + lambda) evolution strategy over ``s = (x, y, z, roll, pitch, yaw)``:

* ``ask`` makes offspring by tournament selection, intermediate crossover and
  Gaussian mutation (small and large steps), plus random immigrants from
  :mod:`evopose.init`, plus any pending hint individuals (paper §III);
* the caller refines them (:func:`evopose.refine.refine`, Lamarckian) and evaluates
  eq. (4) (:class:`evopose.fitness.PoseObjective`) outside the optimiser;
* ``tell`` keeps the best ``mu`` distinct individuals (elitist selection: a hint
  that does not fit the own images is discarded like any poor individual).

Every individual carries the id of the independent start it descends from (hints
have negative ids). The search has *converged* when the best pose's basin has been
reached from ``consensus`` independent starts, or its fitness is under
``good_fitness`` (the paper's "good pose" threshold).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
import numpy as np

from .fitness import FitnessKind
from .init import initial_poses
from .pose import rotation_angle, rotation_from_euler, wrap_angle
from .problem import PoseProblem


#: Model x image point pairs at which ``min_starts`` starts suffice; fewer pairs need proportionally more.
REFERENCE_PAIRS = 400
MAX_START_FACTOR = 4.0


@dataclass(frozen=True)
class SearchOptions:
    """Tuning of the search; the defaults solve the benchmark problems.

    Attributes
    ----------
    fitness : "robust" | "paper"
        Robust two-sided bounded distance, or the paper's plain eq. (1).
    tau : float or None
        Truncation distance in pixels (robust fitness); automatic per view when None.
    population : int
        ``mu``, individuals kept between generations.
    offspring : int
        ``lambda``, new individuals per generation.
    immigrants : float
        Fraction of the offspring that are fresh random starts.
    screening : int
        Fresh starts are drawn this many times over and the best by a coarse fitness kept.
    refine_steps : int
        Annealed soft-matching steps of the local refinement per new individual
        (0 gives the paper's plain EA, without refinement).
    max_generations, max_evaluations : int
    time_budget : float or None
        Seconds of wall time.
    good_fitness : float or None
        Stop as soon as the best fitness is at or below this value.
    consensus : int
        Stop when the best basin was reached from this many independent starts (0: never),
        at least ``min_starts`` starts were made, and its match quality (robust fitness over
        the weighted tau: 0 perfect, 1 nothing matched) is at most ``good_quality``.
    good_quality : float
    min_starts : int
        Independent (screened, refined) random starts before the consensus or stall rule may stop
        (times up to 4 when the problem has fewer than ``REFERENCE_PAIRS`` model x image point pairs)...
    confident_quality : float
        ...when the best match quality is at most this, or at most ``confident_unmatched``
        of the best pose's visible marks lack a one-to-one image match; otherwise
    confident_unmatched : float
    min_starts_unsure : int
        starts are needed (a poor best match may be a wrong basin: search longer).
    patience : int
        Stop ("stalled") when the best has not improved for this many generations after ``min_starts``.
    min_generations : int
    view_reject : float or None
        Step-function weight rule of eq. (4): a view whose term exceeds this (fraction of its
        tau for the robust fitness, pixels for the paper's) gets weight 0. None disables it.
    same_position : float
        Two poses are in the same basin when their positions differ by less than this
        fraction of the target distance...
    same_rotation : float
        ...and their rotations by less than this many radians.
    """

    fitness: FitnessKind = "robust"
    tau: float | None = None
    population: int = 32
    offspring: int = 64
    immigrants: float = 0.8
    screening: int = 8
    refine_steps: int = 10
    max_generations: int = 150
    max_evaluations: int = 2_000_000
    time_budget: float | None = None
    good_fitness: float | None = None
    consensus: int = 2
    good_quality: float = 0.5
    min_starts: int = 256
    confident_quality: float = 0.3
    confident_unmatched: float = 0.1
    min_starts_unsure: int = 1024
    patience: int = 6
    min_generations: int = 1
    view_reject: float | None = 0.6
    same_position: float = 0.02
    same_rotation: float = np.deg2rad(3.0)

    def __post_init__(self) -> None:
        if self.screening < 1:
            raise ValueError(f"screening must be >= 1, got {self.screening}")
        if self.population < 2 or self.offspring < 1:
            raise ValueError("population must be >= 2 and offspring >= 1")
        if not 0.0 <= self.immigrants <= 1.0:
            raise ValueError(f"immigrants must be a fraction in [0, 1], got {self.immigrants}")
        if self.refine_steps < 0 or self.max_generations < 1:
            raise ValueError("refine_steps must be >= 0 and max_generations >= 1")


@dataclass
class EvoPoseState:
    """Everything the search knows between generations (visible and copyable).

    Attributes
    ----------
    population : array, shape (mu, 6)
    fitness : array, shape (mu,)
    origin : int array, shape (mu,)
        Independent start each individual descends from (negative: a hint).
    generation : int
    next_origin : int
    best_supporters : set of int
        Independent starts that reached the current best basin.
    history : list of float
        Best fitness after each generation (Fig. 6).
    pending_hints : array, shape (H, 6)
    """

    population: np.ndarray
    fitness: np.ndarray
    origin: np.ndarray
    generation: int = 0
    next_origin: int = 0
    best_supporters: set = field(default_factory=set)
    history: list = field(default_factory=list)
    pending_hints: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    hints_seen: int = 0
    pending_initial: np.ndarray | None = None
    fresh_from: int = 0
    fresh_keep: int = 0
    starts: int = 0
    improved_at: int = 0
    #: share of the best pose's visible marks left unmatched (clutter-blind match quality; 1: unknown)
    best_unmatched: float = 1.0

    @property
    def best_pose(self) -> np.ndarray:
        return self.population[int(np.argmin(self.fitness))].copy()

    @property
    def best_fitness(self) -> float:
        return float(np.min(self.fitness)) if len(self.fitness) else np.inf

    @property
    def best_from_hint(self) -> bool:
        """A hint (or its descendant) reached the best basin."""
        return bool(self.origin[int(np.argmin(self.fitness))] < 0 or any(x < 0 for x in self.best_supporters))


def same_basin(a: np.ndarray, b: np.ndarray, options: SearchOptions, reference_distance: float) -> np.ndarray:
    """Whether poses ``b`` (K, 6) lie in the same basin as pose ``a`` (6,); shape (K,)."""
    b = np.atleast_2d(b)
    dpos = np.linalg.norm(b[:, :3] - a[:3], axis=1)
    drot = rotation_angle(rotation_from_euler(a[3:])[None], rotation_from_euler(b[:, 3:]))
    return (dpos <= options.same_position * max(reference_distance, 1e-6)) & (drot <= options.same_rotation)


class EvoPose:
    """The optimiser: ``state = start(); while not done: ask -> (refine, evaluate) -> tell``.

    Parameters
    ----------
    problem : PoseProblem
    options : SearchOptions
    rng : numpy Generator
    fitness_scale : float, optional
        Fitness of a pose that matches nothing, for the quality test of the stop rule.
    """

    def __init__(self, problem: PoseProblem, options: SearchOptions, rng: np.random.Generator,
                 fitness_scale: float | None = None) -> None:
        self.problem = problem
        #: fitness of a pose that matches nothing (sum of weighted tau); None: quality unknown
        self.fitness_scale = fitness_scale
        self.options = options
        self.rng = rng
        lo, hi = problem.bounds.lo, problem.bounds.hi
        cams = np.array([v.camera.center_world for v in problem.views])
        mid = 0.5 * (lo[:3] + hi[:3])
        self.reference_distance = float(np.min(np.linalg.norm(cams - mid, axis=1))) or 1.0
        width = problem.bounds.width
        # mutation scales: (small, large) steps per parameter, never wider than the box
        pos_small = 0.03 * self.reference_distance
        self.sigma_small = np.minimum(np.r_[[pos_small] * 3, [np.deg2rad(8)] * 3], width / 2)
        self.sigma_large = np.minimum(np.r_[[4 * pos_small] * 3, [np.deg2rad(60)] * 3], width / 2)
        # few image points for many model points: a random start rarely lands in the right basin,
        # but every evaluation is cheap, so ask for more starts (up to MAX_START_FACTOR times)
        n_img = np.mean([len(v.points) for v in problem.views])
        pairs = len(problem.model.points) * n_img
        self.start_factor = float(np.clip(REFERENCE_PAIRS / pairs, 1.0, MAX_START_FACTOR))

    # -- state -------------------------------------------------------------------------
    def start(self, initial: np.ndarray | None = None) -> EvoPoseState:
        """A state whose first ``ask`` returns the initial population (optionally the given poses)."""
        state = EvoPoseState(population=np.zeros((0, 6)), fitness=np.zeros(0), origin=np.zeros(0, int))
        if initial is not None:
            state.pending_initial = self.problem.bounds.project(np.atleast_2d(initial))
        if len(self.problem.hints):
            self.inject(state, self.problem.hints)
        return state

    def inject(self, state: EvoPoseState, hints: np.ndarray) -> None:
        """Queue external full poses (hints) to enter the population at the next ``ask``."""
        hints = np.atleast_2d(np.asarray(hints, float))
        if hints.size:
            state.pending_hints = np.concatenate([state.pending_hints, hints.reshape(-1, 6)])

    # -- ask / tell --------------------------------------------------------------------
    def ask(self, state: EvoPoseState) -> tuple[np.ndarray, np.ndarray]:
        """New candidates and their origins, shapes (K, 6) and (K,).

        Fresh random starts are over-sampled ``options.screening`` times; the caller keeps
        the best :meth:`n_fresh` of them by a coarse fitness (:func:`screen`) before refining.
        Fresh starts are the rows whose origin is >= ``state.fresh_from``.
        """
        o = self.options
        bounds = self.problem.bounds
        rng = self.rng
        parts, origins = [], []
        state.fresh_from, state.fresh_keep = state.next_origin, 0
        if state.generation == 0 and len(state.population) == 0:
            given = state.pending_initial
            n_random = o.population + o.offspring
            if given is not None:
                parts.append(given)
                origins.append(self._new_origins(state, len(given)))
                n_random = max(o.offspring - len(given), 0)
            if n_random:
                state.fresh_from, state.fresh_keep = state.next_origin, n_random
                parts.append(initial_poses(self.problem, n_random * o.screening, rng))
                origins.append(self._new_origins(state, n_random * o.screening))
        else:
            n_imm = int(round(o.immigrants * o.offspring))
            n_children = o.offspring - n_imm
            if n_children:
                children, child_origin = self._children(state, n_children)
                parts.append(children)
                origins.append(child_origin)
            if n_imm:
                state.fresh_from, state.fresh_keep = state.next_origin, n_imm
                parts.append(initial_poses(self.problem, n_imm * o.screening, rng))
                origins.append(self._new_origins(state, n_imm * o.screening))
        if len(state.pending_hints):
            h = bounds.project(state.pending_hints)
            parts.append(h)
            origins.append(-1 - state.hints_seen - np.arange(len(h)))
            state.hints_seen += len(h)
            state.pending_hints = np.zeros((0, 6))
        return np.concatenate(parts), np.concatenate(origins)

    def tell(self, state: EvoPoseState, candidates: np.ndarray, fitness: np.ndarray,
             origins: np.ndarray) -> EvoPoseState:
        """Elitist (mu + lambda) selection of distinct individuals; updates the consensus count."""
        o = self.options
        prev_best = state.best_pose if len(state.population) else None
        pop = np.concatenate([state.population, candidates])
        fit = np.concatenate([state.fitness, fitness])
        org = np.concatenate([state.origin, origins])
        order = np.argsort(fit, kind="stable")
        pop, fit, org = pop[order], fit[order], org[order]
        R_all = rotation_from_euler(pop[:, 3:])
        near = self._basin_mask(pop, R_all)
        # consensus: independent starts whose refined descendants landed in the best basin
        in_best = near(0, np.arange(len(pop)))
        supporters = set(int(x) for x in org[in_best])
        if prev_best is not None and same_basin(pop[0], prev_best[None], o, self.reference_distance)[0]:
            supporters |= state.best_supporters
        # keep distinct individuals: one representative per basin, best first
        keep = np.ones(len(pop), bool)
        kept = 0
        for i in range(len(pop)):
            if not keep[i]:
                continue
            kept += 1
            if kept >= o.population:
                keep[i + 1:] = False
                break
            keep[i + 1:] &= ~near(i, np.arange(i + 1, len(pop)))
        idx = np.nonzero(keep)[0][: o.population]
        state.starts += int(np.count_nonzero(origins >= state.fresh_from)) if state.fresh_keep else 0
        if prev_best is None or fit[0] < state.best_fitness - 1e-9 * max(1.0, abs(state.best_fitness)):
            state.improved_at = state.generation + 1
        state.population, state.fitness, state.origin = pop[idx], fit[idx], org[idx]
        state.best_supporters = supporters
        state.generation += 1
        state.history.append(float(fit[0]))
        return state

    def is_good(self, fitness: float, unmatched: float = 1.0) -> bool:
        """Match quality within ``good_quality`` (always True when the quality is unknown).

        The quality is the fitness over its no-match value, or, when lower, the share of
        visible marks left unmatched (which false image points do not inflate).
        """
        return (self.fitness_scale is None or fitness <= self.options.good_quality * self.fitness_scale
                or unmatched <= self.options.good_quality)

    def is_confident(self, state: EvoPoseState) -> bool:
        """The best match is so good that ``min_starts`` starts suffice (else ``min_starts_unsure``)."""
        o = self.options
        return (self.fitness_scale is None or state.best_fitness <= o.confident_quality * self.fitness_scale
                or state.best_unmatched <= o.confident_unmatched)

    def _basin_mask(self, pop: np.ndarray, R_all: np.ndarray):
        """``near(i, js)``: which of the poses ``js`` share pose ``i``'s basin (rotations precomputed)."""
        pos_tol = self.options.same_position * max(self.reference_distance, 1e-6)
        cos_tol = np.cos(self.options.same_rotation)

        def near(i: int, js: np.ndarray) -> np.ndarray:
            dpos = np.linalg.norm(pop[js, :3] - pop[i, :3], axis=1)
            # trace(R_i^T R_j) = 1 + 2 cos(angle)
            cos = (np.einsum("kl,jkl->j", R_all[i], R_all[js]) - 1.0) / 2.0
            return (dpos <= pos_tol) & (cos >= cos_tol)

        return near

    def stop_reason(self, state: EvoPoseState, evaluations: int, elapsed: float) -> str | None:
        """Why the search should stop now, or None."""
        o = self.options
        if o.good_fitness is not None and state.best_fitness <= o.good_fitness:
            return "good_fitness"
        hinted = any(x < 0 for x in state.best_supporters)
        if (state.generation >= o.min_generations and hinted and o.consensus
                and len(state.best_supporters) >= o.consensus
                and self.is_good(state.best_fitness, state.best_unmatched)):
            return "consensus"  # a team-mate's hint confirmed by the own search: no need for more starts
        needed = (o.min_starts if self.is_confident(state) else o.min_starts_unsure) * self.start_factor
        if state.generation >= o.min_generations and state.starts >= needed:
            if (o.consensus and len(state.best_supporters) >= o.consensus
                    and self.is_good(state.best_fitness, state.best_unmatched)):
                return "consensus"
            if state.generation - state.improved_at >= o.patience:
                return "stalled"
        if state.generation >= o.max_generations:
            return "max_generations"
        if evaluations >= o.max_evaluations:
            return "max_evaluations"
        if o.time_budget is not None and elapsed >= o.time_budget:
            return "time_budget"
        return None

    # -- operators -----------------------------------------------------------------------
    def _new_origins(self, state: EvoPoseState, n: int) -> np.ndarray:
        ids = state.next_origin + np.arange(n)
        state.next_origin += n
        return ids

    def _tournament(self, state: EvoPoseState, n: int) -> np.ndarray:
        a = self.rng.integers(0, len(state.population), n)
        b = self.rng.integers(0, len(state.population), n)
        return np.where(state.fitness[a] <= state.fitness[b], a, b)

    def _children(self, state: EvoPoseState, n: int) -> tuple[np.ndarray, np.ndarray]:
        rng = self.rng
        p1 = self._tournament(state, n)
        p2 = self._tournament(state, n)
        x1, x2 = state.population[p1], state.population[p2]
        # intermediate crossover on a third of the children (angles along the short way round)
        cross = rng.random(n) < 1 / 3
        alpha = rng.random((n, 1))
        diff = x2 - x1
        diff[:, 3:] = wrap_angle(diff[:, 3:])
        children = np.where(cross[:, None], x1 + alpha * diff, x1)
        better_second = state.fitness[p2] < state.fitness[p1]
        origin = np.where(cross & better_second, state.origin[p2], state.origin[p1])
        # Gaussian mutation: mostly small steps, some large ones to hop between basins
        large = rng.random(n) < 0.3
        sigma = np.where(large[:, None], self.sigma_large, self.sigma_small)
        children = children + sigma * rng.standard_normal((n, 6))
        return self.problem.bounds.project(children), origin


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
        Stopped because the pose is good (consensus or threshold), not because a budget ran out.
    stop_reason : str
    history : list of float
        Best fitness per generation.
    from_hint : bool
        A hint (or a descendant of one) reached the best basin.
    reinitialised : bool
        (track) the fit was lost and the search started over.
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
    problem: PoseProblem | None = field(default=None, repr=False)
    options: SearchOptions | None = field(default=None, repr=False)

    def with_(self, **changes) -> "Solution":
        return replace(self, **changes)


GOOD_REASONS = ("good_fitness", "consensus", "stalled")
