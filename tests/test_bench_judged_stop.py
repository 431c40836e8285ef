"""The replay that chose the judged stop (benchmarks/bench_judged_stop.py): a rule ends a search where solve would,
and pays for a verdict that did not end it; and the replay of one real search agrees with solve."""

import numpy as np

from benchmarks.bench_judged_stop import outcome, replay
from benchmarks.problems import make_problem
from evopose import solve


def _row(starts, supporters, searched, *, ends=False, confident=False, finished=False, judged=True):
    row = {"starts": starts, "supporters": supporters, "searched": searched, "acceptable": True, "finished": finished}
    if judged:
        row.update(judging=0.01, confident=confident, ends=ends, good=confident)
    return row


def test_a_rule_ends_at_its_first_pause_only_when_the_verdict_ends_it_and_pays_for_one_that_does_not():
    record = {"group": "telephoto", "generations": [
        _row(96, 1, 0.1, judged=False), _row(147, 3, 0.2, ends=False), _row(198, 5, 0.3, ends=True, confident=True),
        _row(249, 6, 0.4, finished=True, confident=True)]}
    # 3 supporters, at most 150 starts: paused at 147, unsure, so the search runs to its end and pays both verdicts
    row, seconds = outcome(record, (3, 150, "confident"))
    assert row is record["generations"][-1] and np.isclose(seconds, 0.4 + 0.01 + 0.01)
    # 5 supporters: paused first at 198, where the verdict ends the search
    row, seconds = outcome(record, (5, None, "confident"))
    assert row is record["generations"][2] and np.isclose(seconds, 0.3 + 0.01)
    # ending on any verdict stops at the first pause, unsure or not
    assert outcome(record, (3, 150, "any verdict"))[0] is record["generations"][1]
    # a cap no pause meets: the search's own end
    assert outcome(record, (5, 150, "confident"))[0] is record["generations"][-1]


def test_the_replay_of_a_search_ends_where_solve_ends_it(monkeypatch):
    """Box seed 53 (tests/test_solver.py): solve ends judged at generation 1; the replay's shipped rule does too."""
    import benchmarks.bench_confidence as bench_confidence

    sp = make_problem("box", np.random.default_rng(53), noise=1.0, clutter=0.2, missing=0.1)
    monkeypatch.setattr(bench_confidence, "make", lambda group, seed, index: sp)   # the replay's problem is this one
    record = replay(("telephoto", 0, 0))   # index 0: the seed solve is given below
    row, _ = outcome(record, (3, 150, "confident"))
    solved = solve(sp.problem, seed=0)
    assert solved.stop_reason == "judged" and record["generations"].index(row) + 1 == solved.generations == 1
    assert row["confident"] == solved.confident
