"""`time_budget` holds inside a generation: candidates are evaluated and refined a chunk at a time while time is
left (docs/security.md, "Untrusted input": time budget). Tested through deadlines already past or far away, never through the clock's speed: the
amount of work done must follow the deadline, and the result must not depend on the chunking."""

from __future__ import annotations

import numpy as np

from benchmarks.problems import make_paper_scale_problem
from evopose import Evaluator, EvoPose, SearchOptions, solve
from evopose.loop import _in_chunks, evolve
from evopose.solver import solution_of


def test_chunks_cover_everything_without_a_deadline_or_with_time_left():
    seen: list[slice] = []
    assert _in_chunks(100, None, seen.append) == 100 and seen == [slice(0, 100)]
    seen.clear()
    assert _in_chunks(100, float("inf"), seen.append) == 100
    covered = np.concatenate([np.arange(s.start, s.stop) for s in seen])
    assert np.array_equal(covered, np.arange(100)) and seen[0] == slice(0, 1)  # starts with one row, grows


def test_a_deadline_already_passed_still_does_the_first_row_and_no_more():
    seen: list[slice] = []
    assert _in_chunks(100, 0.0, seen.append) == 1 and seen == [slice(0, 1)]


def generation(seed: int = 3):
    problem = make_paper_scale_problem(np.random.default_rng(seed), cameras=("H1", "H2")).problem
    options = SearchOptions()
    evo = EvoPose(problem, options)
    evaluator = Evaluator.for_search(problem, options)
    _, asked = evo.ask(evo.start(None), np.random.default_rng(seed))
    return evaluator, asked


def test_with_time_left_a_generation_is_exactly_the_unbounded_one():
    evaluator, asked = generation()
    screened = evaluator.screen(asked)
    assert np.array_equal(evaluator.screen(asked, float("inf")).candidates, screened.candidates)
    poses, fitness = evaluator(screened)
    kept, poses_chunked, fitness_chunked = evaluator.until(screened, float("inf"))
    assert len(kept.candidates) == len(screened.candidates)
    assert np.array_equal(poses, poses_chunked) and np.array_equal(fitness, fitness_chunked)


def test_past_the_deadline_a_generation_evaluates_one_candidate():
    evaluator, asked = generation()
    screened = evaluator.screen(asked, 0.0)
    assert screened.fresh.sum() <= 1 < asked.fresh.sum()  # one fresh start screened, the rest left out
    kept, poses, fitness = evaluator.until(asked, 0.0)
    assert len(kept.candidates) == len(poses) == len(fitness) == 1 and np.isfinite(fitness[0])
    full_poses, full_fitness = evaluator(asked.subset(np.arange(1)))
    assert np.array_equal(poses, full_poses) and np.array_equal(fitness, full_fitness)  # that one is refined


def test_a_search_cut_by_its_budget_is_not_confident():
    problem = make_paper_scale_problem(np.random.default_rng(3), cameras=("H1", "H2")).problem
    cut = solve(problem, SearchOptions(time_budget=1e-9), seed=3)
    assert cut.generations == 1 and cut.stop_reason == "time_budget" and not cut.converged and not cut.confident
    # solve holds the budget inside its generation: a few candidates' work, not a whole generation's
    whole_generation = solve(problem, SearchOptions(max_generations=1), seed=3)
    assert cut.evaluations * 100 < whole_generation.evaluations, (cut.evaluations, whole_generation.evaluations)
    free = solve(problem, SearchOptions(time_budget=1e3), seed=3)
    assert np.array_equal(free.pose, solve(problem, SearchOptions(), seed=3).pose)


def test_a_verdict_without_time_to_polish_the_rivals_is_not_confident():
    """The same finished search judged with its budget's time left, and with it spent (the search took longer
    than budget and grace): the rivals go unpolished, so no distinct pose can be ruled out."""
    problem = make_paper_scale_problem(np.random.default_rng(3), cameras=("H1", "H2")).problem
    options = SearchOptions(time_budget=5.0)
    evo = EvoPose(problem, options)
    run = evolve(evo, evo.start(None), Evaluator.for_search(problem, options), rng=np.random.default_rng(3))
    in_time = solution_of(problem, options, run, seconds=0.0)
    late = solution_of(problem, options, run, seconds=10.0)
    assert in_time.confident, in_time.confidence.reason
    assert not late.confident and late.confidence.reason == "out of time"
