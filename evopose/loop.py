"""The generation loop, the only one: ask -> screen -> evaluate (refine, eq. 4) -> tell, until tell says stop.

:func:`evolve` drives any optimiser with the ask / tell of :class:`evopose.search.EvoPose` (the global
search of :func:`evopose.solve`) or :class:`evopose.local.LocalSearch` (the warm starts of
:func:`evopose.track` and :meth:`evopose.cooperative.CooperativeEstimator.generation`). How candidates
are evaluated is an :class:`Evaluator`: the coarse screening of fresh starts, the Lamarckian
refinement (:func:`evopose.refine.refine`) and the fitness, eq. (4), with its weights' rule (the paper's
step rule, or :mod:`evopose.weights`). The optimiser never sees the objective, only fitness values and a match judgement.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, Protocol

import numpy as np

from .fitness import PoseObjective
from .options import SearchOptions
from .problem import PoseProblem
from .refine import Schedule, annealing, refine
from .search import Ask, Judge, Told
from .weights import ViewWeighting, rule_weights, settled

#: Truncation distance of the coarse fitness used to screen random starts, in units of tau.
SCREEN_TAU_SCALE = 4.0
#: Annealing time at which the refinement of children and hints starts (they are near good poses).
LOCAL_ANNEALING_START = 0.5
#: Generation after which the step-function weight rule of eq. (4) is first applied.
STEP_RULE_FROM_GENERATION = 2
#: Candidates evaluated (or refined) between two looks at the clock when a generation has a deadline.
CHUNK = 16


class AskTell(Protocol):
    """What :func:`evolve` needs of an optimiser; every method returns a new state."""

    def inject(self, state: Any, hints: np.ndarray) -> Any: ...

    def ask(self, state: Any, rng: np.random.Generator | None) -> tuple[Any, Ask]: ...

    def tell(self, state: Any, asked: Ask, poses: np.ndarray, fitness: np.ndarray, *, judge: Judge | None = None,
             evaluations: int = 0, elapsed: float = 0.0) -> tuple[Any, Told]: ...

    def rescore(self, state: Any, fitness: np.ndarray, *, judge: Judge | None = None, evaluations: int = 0,
                elapsed: float = 0.0) -> tuple[Any, Told]: ...


def _in_chunks(n: int, deadline: float | None, work: Callable[[slice], None]) -> int:
    """``work`` on rows ``[0, n)``: all at once without a deadline, else in chunks until the ``time.perf_counter()``
    deadline passes (the first row always runs); how many rows were worked on. Chunks start at one row and grow
    to what the time left allows at the measured cost per row (at most :data:`CHUNK`), so the deadline is
    overrun by about one row's work."""
    if deadline is None:
        work(slice(0, n))
        return n
    done, size = 0, 1
    while done < n and (done == 0 or time.perf_counter() < deadline):
        started = time.perf_counter()
        stop = min(done + size, n)
        work(slice(done, stop))
        now = time.perf_counter()
        per_row = (now - started) / (stop - done)
        done = stop
        size = int(min(max((deadline - now) / max(per_row, 1e-9), 1), CHUNK))
    return done


def screen(coarse: PoseObjective, asked: Ask, deadline: float | None = None) -> Ask:
    """Keep the ``asked.fresh_keep`` best fresh starts by the coarse fitness; other candidates pass. At the
    ``deadline`` the fresh starts not yet screened are left out."""
    fresh = asked.fresh
    if np.count_nonzero(fresh) <= asked.fresh_keep:
        return asked
    idx = np.nonzero(fresh)[0]
    f = np.full(len(idx), np.inf)

    def coarse_rows(rows: slice) -> None:
        f[rows] = coarse(asked.candidates[idx[rows]])

    screened = _in_chunks(len(idx), deadline, coarse_rows)
    chosen = idx[np.argsort(f[:screened], kind="stable")[:asked.fresh_keep]]
    mask = ~fresh
    mask[chosen] = True
    return asked.subset(mask)


def _best_of(objective: PoseObjective, poses: np.ndarray, fitness: np.ndarray,
             schedules: tuple[Schedule, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Refine every pose along each schedule from the same start; keep the best result per pose."""
    best_p, best_f = refine(objective, poses, fitness, schedules[0])
    for schedule in schedules[1:]:
        p, f = refine(objective, poses, fitness, schedule)
        better = f < best_f
        best_p[better], best_f[better] = p[better], f[better]
    return best_p, best_f


@dataclass(frozen=True, eq=False)
class Evaluator:
    """How candidates are evaluated (immutable; the step rule derives a new one).

    Attributes
    ----------
    objective : PoseObjective
        Eq. (4) with the weights in force.
    coarse : PoseObjective or None
        Screening fitness of fresh starts (a wider tau); None: no screening.
    explore : tuple of schedules
        Refinement of fresh starts; with several, each runs from the same start and the best result is kept.
    exploit : tuple of schedules
        Refinement of the other candidates (children, hints, given poses).
    view_reject : float or None
        Threshold of eq. (4)'s step rule (:meth:`PoseObjective.step_rule_weights`); None: no step rule.
    view_weighting : "equal" | "step" | "adaptive"
        How eq. (4)'s weights follow the best pose (:func:`evopose.weights.rule_weights`); "equal" keeps them.
    """

    objective: PoseObjective
    coarse: PoseObjective | None = None
    explore: tuple[Schedule, ...] = ()
    exploit: tuple[Schedule, ...] = ()
    view_reject: float | None = None
    view_weighting: ViewWeighting = "step"

    @classmethod
    def for_search(cls, problem: PoseProblem, options: SearchOptions) -> "Evaluator":
        """The global search's evaluation: screening, annealed refinement (full for fresh starts, its narrow
        end for the others), eq. (4) of ``options.fitness`` and its step rule."""
        objective = PoseObjective(problem, options.fitness, options.tau)
        coarse = PoseObjective(problem, options.fitness, options.tau, tau_scale=SCREEN_TAU_SCALE,
                               counter=objective.counter)
        explore = exploit = ()
        if options.refine_steps:
            explore = (annealing(options.refine_steps),)
            exploit = (annealing(max(options.refine_steps // 2, 1), start=LOCAL_ANNEALING_START),)
        return cls(objective, coarse, explore, exploit, options.view_reject, options.view_weights)

    @property
    def evaluations(self) -> int:
        """Projections of the model so far, screening included (the objectives share one counter)."""
        return self.objective.evaluations

    def screen(self, asked: Ask, deadline: float | None = None) -> Ask:
        return asked if self.coarse is None else screen(self.coarse, asked, deadline)

    def __call__(self, asked: Ask) -> tuple[np.ndarray, np.ndarray]:
        """Eq. (4) of the candidates, then their refinement: poses (K, 6) and fitness (K,)."""
        _, poses, fitness = self.until(asked, None)
        return poses, fitness

    def until(self, asked: Ask, deadline: float | None) -> tuple[Ask, np.ndarray, np.ndarray]:
        """:meth:`__call__` within a ``time.perf_counter()`` deadline (a time budget holds inside a generation):
        candidates are evaluated, then refined, a chunk at a time while time is left; those not evaluated by the
        deadline are left out of the returned ``asked``, those not refined keep their evaluated pose and fitness.
        Without a deadline, or when time suffices, the result is exactly :meth:`__call__`'s (each candidate is
        evaluated and refined on its own)."""
        poses = np.array(asked.candidates, float)
        fitness = np.full(len(poses), np.inf)

        def evaluate(rows: slice) -> None:
            fitness[rows] = self.objective(poses[rows])

        evaluated = _in_chunks(len(poses), deadline, evaluate)
        if evaluated < len(poses):
            asked, poses, fitness = asked.subset(np.arange(evaluated)), poses[:evaluated], fitness[:evaluated]
        fresh = asked.fresh
        # fresh starts explore (the whole annealing); children and hints exploit (its narrow end)
        for rows, schedules in ((fresh, self.explore), (~fresh, self.exploit)):
            if not (schedules and np.any(rows)):
                continue
            idx = np.nonzero(rows)[0]

            def refine_rows(chunk: slice, idx=idx, schedules=schedules) -> None:
                at = idx[chunk]
                poses[at], fitness[at] = _best_of(self.objective, poses[at], fitness[at], schedules)

            if deadline is None or time.perf_counter() < deadline:
                _in_chunks(len(idx), deadline, refine_rows)
        return asked, poses, fitness

    def reweighted(self, best_pose: np.ndarray) -> "Evaluator | None":
        """The evaluator with eq. (4)'s weights by its rule at ``best_pose``, or None if they do not change."""
        if self.objective.n_views < 2 or self.view_weighting == "equal":
            return None
        if self.view_weighting == "step":
            if self.view_reject is None:
                return None
            weights = self.objective.step_rule_weights(best_pose, self.view_reject)
            if np.array_equal(weights, self.objective.weights):
                return None
        else:
            # during the search only the step stage (R = 1): the graded weights polish the end (evopose.weights)
            weights = rule_weights(self.objective, best_pose, self.view_weighting, self.view_reject, max_ratio=1.0)
            if settled(self.objective.weights, weights):
                return None
        return replace(self, objective=self.objective.with_weights(weights))


@dataclass(frozen=True, eq=False)
class Run:
    """How :func:`evolve` ended: the optimiser's last state, the last :class:`Told`, the evaluator in force."""

    state: Any
    told: Told
    evaluator: Evaluator
    seconds: float

    @property
    def finished(self) -> bool:
        """The optimiser gave a stop reason (False: the run met its deadline and can be resumed)."""
        return self.told.stop_reason is not None


def evolve(optimiser: AskTell, state: Any, evaluator: Evaluator, *,
           hint_source: Callable[[], np.ndarray | None] | None = None,
           on_generation: Callable[[Any], None] | None = None, deadline: float | None = None,
           elapsed_before: float = 0.0, until_generation: int | None = None, time_budget: float | None = None,
           rng: np.random.Generator | None = None, clock: Callable[[], float] = time.perf_counter,
           pause: Callable[[Any], bool] | None = None) -> Run:
    """Run generations until the optimiser's ``tell`` gives a stop reason, or until ``deadline``.

    Parameters
    ----------
    optimiser : EvoPose or LocalSearch
    state
        The optimiser's state to start from (its ``start``).
    evaluator : Evaluator
    hint_source : callable () -> array (H, 6) or None, optional
        Polled once per generation for hints that arrived meanwhile (agents pass their inbox).
    on_generation : callable (state) -> None, optional
        Called after every generation (progress, Fig. 6 curves).
    deadline : float, optional
        An instant of ``clock``: after the generation that passes it, return an unfinished run
        (``Run.finished`` False) whose state and evaluator resume the search in a later call (real time:
        a vehicle publishes the best so far at its camera rate while a search goes on).
    elapsed_before : float
        Seconds the search already ran in earlier calls (its time budget counts them).
    until_generation : int, optional
        Also return (unfinished) once this many generations are told: slices of a fixed number of
        generations, which two vehicles with the same inputs run alike whatever their clocks.
    time_budget : float, optional
        The search's whole budget, s (``SearchOptions.time_budget``; earlier calls' ``elapsed_before`` count):
        held inside a generation too (:meth:`Evaluator.until`). The optimiser's ``tell`` stops on it.
    rng : numpy Generator, optional
        The random stream the optimiser's ``ask`` draws from (an input, as evosax's ``ask(key, state)``: the
        optimiser holds none), advanced by this run.
    clock : callable () -> float
        The clock ``deadline`` is an instant of, and the run's seconds are measured on (``time.perf_counter``).
    pause : callable (state) -> bool, optional
        Also return (unfinished) after a generation whose state this says to pause at (a verdict on the best:
        :meth:`evopose.search.EvoPose.ready`); resumed, the search goes on as if never paused.
    """
    t0 = clock() - elapsed_before
    # inside a generation, evaluation stops at the search's time budget (a slice's ``deadline`` is a pause between
    # whole generations: the resumed search is the same as an unpaused one); the evaluator holds it on perf_counter
    inside = None if time_budget is None else time.perf_counter() - elapsed_before + time_budget
    while True:
        if hint_source is not None:
            new = hint_source()
            if new is not None and np.size(new):
                state = optimiser.inject(state, new)
        state, asked = optimiser.ask(state, rng)
        asked = evaluator.screen(asked, inside)
        asked, poses, fitness = evaluator.until(asked, inside)
        state, told = optimiser.tell(state, asked, poses, fitness, judge=evaluator.objective.match,
                                     evaluations=evaluator.evaluations, elapsed=clock() - t0)
        if told.generation >= STEP_RULE_FROM_GENERATION:
            reweighted = evaluator.reweighted(state.best_pose)
            if reweighted is not None:  # eq. (4) changed: the population's fitness must be recomputed
                evaluator = reweighted
                objective = evaluator.objective
                state, told = optimiser.rescore(state, objective(state.population), judge=objective.match,
                                                evaluations=evaluator.evaluations, elapsed=clock() - t0)
        if on_generation is not None:
            on_generation(state)
        if (told.stop_reason is not None or (deadline is not None and clock() >= deadline)
                or (until_generation is not None and told.generation >= until_generation)
                or (pause is not None and pause(state))):
            return Run(state, told, evaluator, clock() - t0)
