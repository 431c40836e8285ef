"""The evolutionary search of EvoPose as a pure ask / tell over an immutable state.

A memetic (mu + lambda) evolution strategy over ``s = (x, y, z, roll, pitch, yaw)``:

* ``ask`` makes offspring by tournament selection, intermediate crossover and
  Gaussian mutation (small and large steps), plus random immigrants from
  :mod:`evopose.init`, plus any pending hint individuals (paper §III);
* the caller screens, refines (:func:`evopose.refine.refine`, Lamarckian) and evaluates
  eq. (4) (:class:`evopose.fitness.PoseObjective`) outside the optimiser;
* ``tell`` keeps the best ``mu`` distinct individuals (elitist selection: a hint
  that does not fit the own images is discarded like any poor individual) and says
  what happened (:class:`Told`: improved or not, and why the search should stop).

:class:`EvoPose` is the only writer of :class:`EvoPoseState`: ``start``, ``inject``, ``ask``,
``tell`` and ``rescore`` each return a new state and leave the old one as it was. What ``ask``
hands to screening and ``tell`` travels in its :class:`Ask` record, not in the state.

Every individual carries the id of the independent start it descends from (hints
have negative ids). The search has *converged* when the best pose's basin has been
reached from ``consensus`` independent starts, or its fitness is under
``good_fitness`` (the paper's "good pose" threshold). The generation loop that drives
it is :func:`evopose.loop.evolve`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from geometry import rotation_angle, rotation_from_euler, wrap_angle

from .fitness import Match
from .init import initial_poses
from .options import SearchOptions
from .problem import PoseProblem

#: Model x image point pairs at which ``min_starts`` starts suffice; fewer pairs need proportionally more.
REFERENCE_PAIRS = 400
MAX_START_FACTOR = 4.0

#: ``judge(pose (6,), fitness) -> Match``: how well the new best matches (the objective's :meth:`match`).
Judge = Callable[[np.ndarray, float], Match]


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a)
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class EvoPoseState:
    """Everything the search knows between generations (visible, immutable: arrays are read-only).

    Attributes
    ----------
    population : array, shape (mu, 6)
    fitness : array, shape (mu,)
    origin : int array, shape (mu,)
        Independent start each individual descends from (negative: a hint).
    generation : int
    next_origin : int
    best_supporters : frozenset of int
        Independent starts that reached the current best basin.
    history : tuple of float
        Best fitness after each generation (Fig. 6).
    pending_hints : array, shape (H, 6)
    hints_seen : int
    pending_initial : array (K, 6) or None
        Given poses for the first ``ask``.
    starts : int
        Independent (screened) random starts told so far.
    improved_at : int
        Generation at which the best fitness last dropped.
    improved_starts : int
        Starts told when the best fitness last dropped (:meth:`EvoPose.settled`).
    best_match : Match
        How well the best individual matches (judged when it changed; unknown before).
    judged : bool
        The search's best was judged (:meth:`EvoPose.ready`, once a search) and the search went on.
    """

    population: np.ndarray
    fitness: np.ndarray
    origin: np.ndarray
    generation: int = 0
    next_origin: int = 0
    best_supporters: frozenset = frozenset()
    history: tuple = ()
    pending_hints: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    hints_seen: int = 0
    pending_initial: np.ndarray | None = None
    starts: int = 0
    improved_at: int = 0
    improved_starts: int = 0
    best_match: Match = Match()
    judged: bool = False

    def __post_init__(self) -> None:
        for name in ("population", "fitness", "origin", "pending_hints", "pending_initial"):
            if getattr(self, name) is not None:
                _frozen(getattr(self, name))

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


@dataclass(frozen=True, eq=False)
class Ask:
    """What :meth:`EvoPose.ask` proposes: candidates to evaluate and what screening and ``tell`` need.

    Attributes
    ----------
    candidates : array, shape (K, 6)
    origins : int array, shape (K,)
        Independent start of each candidate (negative: a hint).
    fresh_from : int
        Fresh random starts are the rows whose origin is >= this...
    fresh_keep : int
        ...and this many of them should be kept by screening (0: there are no fresh starts).
    """

    candidates: np.ndarray
    origins: np.ndarray
    fresh_from: int = 0
    fresh_keep: int = 0

    def __post_init__(self) -> None:
        _frozen(self.candidates)
        _frozen(self.origins)

    @property
    def fresh(self) -> np.ndarray:
        """Bool mask (K,): the fresh random starts."""
        if not self.fresh_keep:
            return np.zeros(len(self.origins), bool)
        return self.origins >= self.fresh_from

    def subset(self, rows: np.ndarray) -> "Ask":
        """The same proposal restricted to ``rows`` (bool mask or indices)."""
        return replace(self, candidates=self.candidates[rows], origins=self.origins[rows])


@dataclass(frozen=True)
class Told:
    """What ``tell`` (or ``rescore``) did.

    Attributes
    ----------
    generation : int
        Generations told so far.
    best_fitness : float
    improved : bool
        The best fitness dropped in this generation.
    stop_reason : str or None
        Why the search should stop now (None: go on).
    """

    generation: int
    best_fitness: float
    improved: bool
    stop_reason: str | None


def same_basin(a: np.ndarray, b: np.ndarray, options: SearchOptions, reference_distance: float) -> np.ndarray:
    """Whether poses ``b`` (K, 6) lie in the same basin as pose ``a`` (6,); shape (K,)."""
    b = np.atleast_2d(b)
    dpos = np.linalg.norm(b[:, :3] - a[:3], axis=1)
    drot = rotation_angle(rotation_from_euler(a[3:])[None], rotation_from_euler(b[:, 3:]))
    return (dpos <= options.same_position * max(reference_distance, 1e-6)) & (drot <= options.same_rotation)


class EvoPose:
    """The optimiser: ``state = start(); loop: state, asked = ask(state, rng) -> evaluate -> state, told = tell(...)``.

    Constant rules, no random stream of its own: ``ask`` draws from the generator it is given (a seed reproduces a
    run exactly), so the same state and generator give the same proposal.

    Parameters
    ----------
    problem : PoseProblem
    options : SearchOptions
    """

    def __init__(self, problem: PoseProblem, options: SearchOptions) -> None:
        self.problem = problem
        self.options = options
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
        state = EvoPoseState(population=np.zeros((0, 6)), fitness=np.zeros(0), origin=np.zeros(0, int),
                             pending_initial=None if initial is None
                             else self.problem.bounds.project(np.atleast_2d(initial)))
        return self.inject(state, self.problem.hints) if len(self.problem.hints) else state

    def inject(self, state: EvoPoseState, hints: np.ndarray) -> EvoPoseState:
        """Queue external full poses (hints, H x 6) to enter the population at the next ``ask``."""
        hints = np.atleast_2d(np.asarray(hints, float))
        if not hints.size:
            return state
        return replace(state, pending_hints=np.concatenate([state.pending_hints, hints.reshape(-1, 6)]))

    # -- ask / tell --------------------------------------------------------------------
    def ask(self, state: EvoPoseState, rng: np.random.Generator) -> tuple[EvoPoseState, Ask]:
        """New candidates and their origins (:class:`Ask`), and the state that has handed them out.

        Fresh random starts are over-sampled ``options.screening`` times; the caller keeps the best
        ``asked.fresh_keep`` of them by a coarse fitness (:func:`evopose.loop.screen`) before refining.
        """
        o = self.options
        parts, origins = [], []
        next_origin = state.next_origin
        fresh_from, fresh_keep = next_origin, 0

        def new_origins(n: int) -> np.ndarray:
            nonlocal next_origin
            next_origin += n
            return next_origin - n + np.arange(n)

        if state.generation == 0 and len(state.population) == 0:
            given = state.pending_initial
            n_random = o.population + o.offspring
            if given is not None:
                parts.append(given)
                origins.append(new_origins(len(given)))
                n_random = max(o.offspring - len(given), 0)
            if n_random:
                fresh_from, fresh_keep = next_origin, n_random
                parts.append(initial_poses(self.problem, n_random * o.screening, rng))
                origins.append(new_origins(n_random * o.screening))
        else:
            n_imm = int(round(o.immigrants * o.offspring))
            n_children = o.offspring - n_imm
            if n_children:
                children, child_origin = self._children(state, n_children, rng)
                parts.append(children)
                origins.append(child_origin)
            if n_imm:
                fresh_from, fresh_keep = next_origin, n_imm
                parts.append(initial_poses(self.problem, n_imm * o.screening, rng))
                origins.append(new_origins(n_imm * o.screening))
        hints_seen = state.hints_seen
        if len(state.pending_hints):
            h = self.problem.bounds.project(state.pending_hints)
            parts.append(h)
            origins.append(-1 - hints_seen - np.arange(len(h)))
            hints_seen += len(h)
        asked = Ask(np.concatenate(parts), np.concatenate(origins), fresh_from, fresh_keep)
        state = replace(state, next_origin=next_origin, hints_seen=hints_seen, pending_hints=np.zeros((0, 6)),
                        pending_initial=None)
        return state, asked

    def tell(self, state: EvoPoseState, asked: Ask, poses: np.ndarray, fitness: np.ndarray, *,
             judge: Judge | None = None, evaluations: int = 0, elapsed: float = 0.0) -> tuple[EvoPoseState, Told]:
        """Elitist (mu + lambda) selection of distinct individuals; updates the consensus count.

        Parameters
        ----------
        state : EvoPoseState
            The state ``ask`` returned.
        asked : Ask
            The proposal (after screening), whose rows ``poses`` are.
        poses : array, shape (K, 6)
            The candidates as evaluated (refined, Lamarckian); ``asked.candidates`` if not refined.
        fitness : array, shape (K,)
            Eq. (4) of ``poses``.
        judge : callable (pose, fitness) -> Match, optional
            Called for the new best when it changed (the stop rule's match thresholds); unknown without.
        evaluations, elapsed : int, float
            Evaluations made and seconds spent so far (budgets of the stop rule).
        """
        o = self.options
        prev_best = state.best_pose if len(state.population) else None
        pop = np.concatenate([state.population, poses])
        fit = np.concatenate([state.fitness, fitness])
        org = np.concatenate([state.origin, asked.origins])
        order = np.argsort(fit, kind="stable")
        pop, fit, org = pop[order], fit[order], org[order]
        near = self._basin_matrix(pop, rotation_from_euler(pop[:, 3:]))
        # consensus: independent starts whose refined descendants landed in the best basin
        in_best = near[0]
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
            keep[i + 1:] &= ~near[i, i + 1:]
        idx = np.nonzero(keep)[0][: o.population]
        improved = prev_best is None or fit[0] < state.best_fitness - 1e-9 * max(1.0, abs(state.best_fitness))
        starts = state.starts + int(np.count_nonzero(asked.fresh))
        best_match = state.best_match
        if judge is not None and fit[0] != state.best_fitness:
            best_match = judge(pop[0].copy(), float(fit[0]))
        state = replace(state, population=pop[idx], fitness=fit[idx], origin=org[idx],
                        best_supporters=frozenset(supporters), generation=state.generation + 1,
                        history=state.history + (float(fit[0]),),
                        starts=starts, improved_at=state.generation + 1 if improved else state.improved_at,
                        improved_starts=starts if improved else state.improved_starts,
                        best_match=best_match)
        return state, Told(state.generation, state.best_fitness, bool(improved),
                           self.stop_reason(state, evaluations, elapsed))

    def rescore(self, state: EvoPoseState, fitness: np.ndarray, *, judge: Judge | None = None,
                evaluations: int = 0, elapsed: float = 0.0) -> tuple[EvoPoseState, Told]:
        """The objective changed (eq. 4's step rule): the population's new ``fitness`` (mu,).

        The consensus count starts over (the old supporters were judged by another fitness).
        """
        state = replace(state, fitness=np.array(fitness, float), best_supporters=frozenset())
        if judge is not None:
            state = replace(state, best_match=judge(state.best_pose, state.best_fitness))
        return state, Told(state.generation, state.best_fitness, False, self.stop_reason(state, evaluations, elapsed))

    def stop_reason(self, state: EvoPoseState, evaluations: int, elapsed: float) -> str | None:
        """Why the search should stop now, or None."""
        o = self.options
        if o.good_fitness is not None and state.best_fitness <= o.good_fitness:
            return "good_fitness"
        supporters = state.best_supporters
        hinted = any(x < 0 for x in supporters)
        if (state.generation >= o.min_generations and hinted and o.consensus
                and len(supporters) >= o.consensus and o.is_acceptable(state.best_match)):
            return "consensus"  # a team-mate's hint confirmed by the own search: no need for more starts
        if state.generation >= o.min_generations and self.settled(state):
            return "consensus"
        needed = (o.min_starts if o.is_close(state.best_match) else o.min_starts_loose) * self.start_factor
        if state.generation >= o.min_generations and state.starts >= needed:
            if o.consensus and len(supporters) >= o.consensus and o.is_acceptable(state.best_match):
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

    def settled(self, state: EvoPoseState) -> bool:
        """Whether the search may stop before ``min_starts``: the best basin's match is close, it was reached from
        ``settled_supporters`` independent starts, and the best has stood unimproved for as many starts again
        (``settled_ratio``) as it took to reach it, after at least ``settled_starts`` (times the start factor).

        What later starts find is a rarer, better basin (a best reached from 3 of 249 starts, beaten at 351 by one
        reached once) or a deeper floor of the best basin (1.2 % lower, found at 453 starts after a best that had
        13 supporters at 249; tests/test_uncertainty.py's one- and two-camera paper-scale problems, which a stop
        at 128 starts lost): the first is why few supporters do not settle, the second why a best still moving
        does not. Chosen on 390 problems of seed 101 (bench_confidence's groups and the regression set's
        generators), on which no answer's accuracy, basin, confidence or precision changed against the 256-start
        rule; judged on ``bench_confidence --seed 7`` and the regression set (BENCHMARKS.md, "Where a solve's time
        goes")."""
        o = self.options
        return bool(o.consensus and o.settled_supporters  # a consensus stop: never when ``consensus`` is 0
                    and len(state.best_supporters) >= max(o.settled_supporters, o.consensus)
                    and o.is_close(state.best_match) and o.is_acceptable(state.best_match)
                    and state.starts >= o.settled_starts * self.start_factor
                    and state.starts >= o.settled_ratio * state.improved_starts)

    def ready(self, state: EvoPoseState) -> bool:
        """Whether the best is ready for a verdict (:func:`evopose.solver.solve` pauses the search for one): its
        basin reached from ``judged_supporters`` independent starts among at most ``judged_starts`` (a common basin)
        and matching acceptably, not judged before."""
        o = self.options
        return bool(o.consensus and o.judged_supporters  # a consensus stop: never when ``consensus`` is 0
                    and not state.judged and state.generation >= o.min_generations
                    and state.starts <= o.judged_starts and len(state.best_supporters) >= o.judged_supporters
                    and o.is_acceptable(state.best_match))

    def judged(self, state: EvoPoseState) -> EvoPoseState:
        """The state of a search whose best was judged and that goes on (:meth:`ready` is not asked again)."""
        return replace(state, judged=True)

    def _basin_matrix(self, pop: np.ndarray, R_all: np.ndarray) -> np.ndarray:
        """Which poses of ``pop`` (K, 6) share a basin, pairwise, shape (K, K) (rotations ``R_all`` (K, 3, 3)):
        computed at once, not row by row in the selection loop (a tenth of a solve's time)."""
        pos_tol = self.options.same_position * max(self.reference_distance, 1e-6)
        cos_tol = np.cos(self.options.same_rotation)
        dpos = np.linalg.norm(pop[None, :, :3] - pop[:, None, :3], axis=2)
        # trace(R_i^T R_j) = 1 + 2 cos(angle)
        cos = (np.einsum("ikl,jkl->ij", R_all, R_all) - 1.0) / 2.0
        return (dpos <= pos_tol) & (cos >= cos_tol)

    # -- operators -----------------------------------------------------------------------
    def _tournament(self, state: EvoPoseState, n: int, rng: np.random.Generator) -> np.ndarray:
        a = rng.integers(0, len(state.population), n)
        b = rng.integers(0, len(state.population), n)
        return np.where(state.fitness[a] <= state.fitness[b], a, b)

    def _children(self, state: EvoPoseState, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        p1 = self._tournament(state, n, rng)
        p2 = self._tournament(state, n, rng)
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
