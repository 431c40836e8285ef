"""Driving the search: :func:`solve` a pose problem from scratch, :func:`track` a sequence (eq. 2)."""

from __future__ import annotations

import time

import numpy as np

from .fitness import PoseObjective
from .problem import PoseProblem, View
from .refine import TRACK_HARD_SCHEDULE, TRACK_SCHEDULE, annealing, refine
from .search import GOOD_REASONS, EvoPose, EvoPoseState, SearchOptions, Solution

#: Truncation distance of the coarse fitness used to screen random starts, in units of tau.
SCREEN_TAU_SCALE = 4.0
#: Annealing time at which the refinement of children and hints starts (they are near good poses).
LOCAL_ANNEALING_START = 0.5
#: Final polish of the best pose: hard nearest-neighbour steps (accepted only when the fitness drops).
POLISH_SCHEDULE = annealing(1, hard=6, start=1.0)
#: Generation after which the step-function weight rule of eq. (4) is first applied.
STEP_RULE_FROM_GENERATION = 2


def screen(coarse: PoseObjective, candidates: np.ndarray, origins: np.ndarray, fresh_from: int,
           keep: int) -> tuple[np.ndarray, np.ndarray]:
    """Keep the ``keep`` best fresh starts (origin >= ``fresh_from``) by the coarse fitness; others pass.

    Shapes: candidates (K, 6), origins (K,) -> (K', 6), (K',).
    """
    fresh = origins >= fresh_from
    if keep <= 0 or np.count_nonzero(fresh) <= keep:
        return candidates, origins
    idx = np.nonzero(fresh)[0]
    f = coarse(candidates[idx])
    chosen = idx[np.argsort(f, kind="stable")[:keep]]
    mask = ~fresh
    mask[chosen] = True
    return candidates[mask], origins[mask]


def _rng(seed: int | np.random.Generator | None) -> np.random.Generator:
    return seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)


def run(problem: PoseProblem, options: SearchOptions, rng: np.random.Generator,
        initial: np.ndarray | None = None, hint_source=None, on_generation=None) -> tuple[Solution, EvoPoseState]:
    """The generation loop: ask -> refine -> evaluate (eq. 4) -> tell, until a stop reason.

    Parameters
    ----------
    hint_source : callable () -> array (H, 6) or None, optional
        Polled once per generation for hints that arrived meanwhile (agents pass their inbox).
    on_generation : callable (EvoPoseState) -> None, optional
        Called after every generation (progress, Fig. 6 curves).
    """
    t0 = time.perf_counter()
    objective = PoseObjective(problem, options.fitness, options.tau)
    coarse = PoseObjective(problem, options.fitness, options.tau, tau_scale=SCREEN_TAU_SCALE)
    schedule = annealing(options.refine_steps)
    local_schedule = annealing(max(options.refine_steps // 2, 1), start=LOCAL_ANNEALING_START)
    evo = EvoPose(problem, options, rng, objective.fitness_scale())
    state = evo.start(initial)
    reason = None
    while reason is None:
        if hint_source is not None:
            new = hint_source()
            if new is not None and np.size(new):
                evo.inject(state, new)
        candidates, origins = evo.ask(state)
        candidates, origins = screen(coarse, candidates, origins, state.fresh_from, state.fresh_keep)
        fitness = objective(candidates)
        if options.refine_steps:
            # fresh starts explore (the whole annealing); children and hints exploit (its narrow end)
            fresh = origins >= state.fresh_from if state.fresh_keep else np.zeros(len(origins), bool)
            for rows, sched in ((fresh, schedule), (~fresh, local_schedule)):
                if np.any(rows):
                    candidates[rows], fitness[rows] = refine(objective, candidates[rows], fitness[rows], sched)
        best_before = state.best_fitness
        evo.tell(state, candidates, fitness, origins)
        if state.best_fitness != best_before:
            state.best_unmatched = objective.unmatched_fraction(state.best_pose)
        if (options.view_reject is not None and objective.n_views > 1
                and state.generation >= STEP_RULE_FROM_GENERATION):
            old = objective.weights.copy()
            new_w = objective.apply_step_rule(state.best_pose, options.view_reject)
            if not np.array_equal(old, new_w):  # eq. (4) changed: fitness values must be recomputed
                state.fitness = objective(state.population)
                state.best_supporters = set()
                state.best_unmatched = objective.unmatched_fraction(state.best_pose)
                evo.fitness_scale = objective.fitness_scale()
        if on_generation is not None:
            on_generation(state)
        reason = evo.stop_reason(state, objective.evaluations + coarse.evaluations, time.perf_counter() - t0)
    if options.refine_steps:
        polished, fit = refine(objective, state.best_pose[None], np.array([state.best_fitness]), POLISH_SCHEDULE)
        i = int(np.argmin(state.fitness))
        state.population[i], state.fitness[i] = polished[0], fit[0]
    best = state.best_pose
    terms = objective.view_terms(best[None])[0]
    solution = Solution(
        pose=best, fitness=state.best_fitness, view_terms=terms, view_weights=objective.weights.copy(),
        generations=state.generation, evaluations=objective.evaluations + coarse.evaluations,
        seconds=time.perf_counter() - t0,
        converged=reason in GOOD_REASONS and evo.is_good(state.best_fitness, state.best_unmatched),
        stop_reason=reason,
        history=list(state.history), from_hint=state.best_from_hint, problem=problem, options=options)
    return solution, state


def solve(problem: PoseProblem, options: SearchOptions | None = None,
          seed: int | np.random.Generator | None = None, **kwargs) -> Solution:
    """Find the pose of the model in the views (EvoPose, eq. 1-4).

    Parameters
    ----------
    problem : PoseProblem
    options : SearchOptions, optional
    seed : int or numpy Generator, optional
        The same seed reproduces the same result exactly.
    **kwargs
        Passed to :func:`run` (``hint_source``, ``on_generation``, ``initial``).
    """
    return run(problem, options or SearchOptions(), _rng(seed), **kwargs)[0]


def match_quality(problem: PoseProblem, pose: np.ndarray, options: SearchOptions | None = None) -> float:
    """Mean normalised view term at ``pose``: 0 is a perfect match, 1 is no match (robust fitness)."""
    options = options or SearchOptions()
    objective = PoseObjective(problem, "robust", options.tau)
    terms = objective.view_terms(np.atleast_2d(pose))[0]
    w = objective.base_weights
    return float(np.sum(w * terms / objective.taus) / np.sum(w))


def track(previous: Solution, new_views: list[View] | tuple[View, ...], *, problem: PoseProblem | None = None,
          options: SearchOptions | None = None, seed: int | np.random.Generator | None = None,
          lost_quality: float = 0.5, hints: np.ndarray | None = None) -> Solution:
    """Warm-started pose for the next frame (eq. 2): refine the previous pose on the new views.

    The previous pose is refined locally; if the match is then lost (normalised
    robust term, or the share of visible marks without a one-to-one match, above
    ``lost_quality``), the search re-initialises from scratch with the previous pose as a hint.

    Parameters
    ----------
    previous : Solution
        The last frame's solution (carries its problem and options).
    new_views : sequence of View
        This frame's image points.
    problem : PoseProblem, optional
        Replaces the previous problem (e.g. new bounds); its views are replaced by ``new_views``.
    hints : array (H, 6), optional
        Team-mates' poses; the better of previous pose and hints seeds the refinement.
    """
    t0 = time.perf_counter()
    base = problem or previous.problem
    if base is None:
        raise ValueError("track needs the previous solution's problem or an explicit problem")
    options = options or previous.options or SearchOptions()
    prob = base.with_views(new_views)
    objective = PoseObjective(prob, options.fitness, options.tau)
    starts = np.atleast_2d(previous.pose)
    if hints is not None and np.size(hints):
        starts = np.concatenate([starts, np.atleast_2d(hints)])
    fit0 = objective(starts)
    pose, fit = refine(objective, starts, fit0, schedule=TRACK_SCHEDULE)
    pose_hard, fit_hard = refine(objective, starts, fit0, schedule=TRACK_HARD_SCHEDULE)
    better = fit_hard < fit
    pose[better], fit[better] = pose_hard[better], fit_hard[better]
    i = int(np.argmin(fit))
    terms = objective.view_terms(pose[i][None])[0]
    quality = float(np.sum(objective.base_weights * terms / objective.taus) / np.sum(objective.base_weights))
    if (options.fitness == "robust" and quality <= lost_quality
            and objective.unmatched_fraction(pose[i]) <= lost_quality):
        return Solution(pose=pose[i], fitness=float(fit[i]), view_terms=terms,
                        view_weights=objective.weights.copy(), generations=0,
                        evaluations=objective.evaluations, seconds=time.perf_counter() - t0, converged=True,
                        stop_reason="tracked", history=[float(fit[i])], from_hint=i > 0,
                        problem=prob, options=options)
    lost = prob.with_hints(np.concatenate([prob.hints, starts]))
    sol = solve(lost, options, seed)
    return sol.with_(reinitialised=True, seconds=time.perf_counter() - t0)
