"""Eq. (4)'s adaptive view weights (evopose/weights.py): the rule's properties on constructed views, the paper's step
rule as its degenerate case, the evidence measured on real views, and seeded problems with one degraded view."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.problems import make_problem, pose_errors
from evopose import SearchOptions, View, solve
from evopose.fitness import PoseObjective, step_weights
from evopose.loop import Evaluator
from evopose.weights import (
    MAX_RATIO,
    ViewEvidence,
    adaptive_weights,
    information_share,
    rule_weights,
    settled,
    view_evidence,
)

BASE = np.array([0.5, 0.5])


def evidence(residual=(0.4, 0.4), matched=(12, 12), visible=(13, 13), image=(15, 15), information=(1.0, 1.0)):
    return ViewEvidence(np.array(residual, float), np.array(matched), np.array(visible), np.array(image),
                        np.array(information, float))


# --- the rule on constructed views -------------------------------------------------------------------------------

def test_healthy_equal_views_keep_equal_weights():
    np.testing.assert_array_equal(adaptive_weights(evidence(), BASE, 0.8), BASE)
    three = ViewEvidence(*(np.repeat(a[:1], 3) for a in (np.array([0.4]), np.array([12]), np.array([13]),
                                                        np.array([15]), np.array([0.9]))))
    np.testing.assert_array_equal(adaptive_weights(three, np.full(3, 1 / 3), 0.8), np.full(3, 1 / 3))


def test_a_view_of_clutter_gets_less_weight():
    """The same marks matched, but the second view's image has three times as many points: clutter."""
    w = adaptive_weights(evidence(image=(15, 45)), BASE, 0.8)
    assert w[0] == BASE[0] and 0 < w[1] < w[0]


def test_a_view_with_little_information_gets_less_weight():
    """Fewer marks matched, at a larger residual variance: less information about the pose than the camera could give."""
    w = adaptive_weights(evidence(residual=(0.4, 0.7), matched=(12, 6), information=(1.0, 0.2)), BASE, 0.8)
    assert w[0] == BASE[0] and 0 < w[1] < w[0]


def test_a_large_residual_without_marks_is_dropped_with_marks_it_is_bounded():
    """The step stage: a view over the threshold matching almost nothing shows no target (weight 0); one over the
    threshold that still matches several marks shows it, and keeps at least 1/R of its weight."""
    absent = adaptive_weights(evidence(residual=(0.4, 0.95), matched=(12, 1), information=(1.0, 0.01)), BASE, 0.8)
    np.testing.assert_array_equal(absent, [0.5, 0.0])
    present = adaptive_weights(evidence(residual=(0.4, 0.85), matched=(12, 6), information=(1.0, 0.01)), BASE, 0.8)
    assert present[1] == pytest.approx(BASE[1] / MAX_RATIO) and present[0] == BASE[0]


def test_the_step_rule_is_the_degenerate_case():
    rng = np.random.default_rng(0)
    for _ in range(200):
        V = int(rng.integers(2, 5))
        ev = ViewEvidence(rng.uniform(0, 1, V), rng.integers(0, 20, V), rng.integers(5, 20, V),
                          rng.integers(1, 40, V), rng.uniform(0, 1, V))
        base = rng.uniform(0, 1, V) * (rng.random(V) > 0.2)
        if not np.any(base > 0):
            base[0] = 1.0
        threshold = float(rng.uniform(0.3, 1.0))
        np.testing.assert_array_equal(adaptive_weights(ev, base, threshold, max_ratio=1, present_marks=np.inf),
                                      step_weights(ev.residual, base, threshold))


def test_weights_are_finite_non_negative_bounded_and_sum_at_most_the_base():
    rng = np.random.default_rng(1)
    for _ in range(300):
        V = int(rng.integers(2, 6))
        ev = ViewEvidence(rng.uniform(0, 1, V), rng.integers(0, 25, V), rng.integers(0, 25, V),
                          rng.integers(0, 60, V), rng.uniform(0, 1, V) * (rng.random(V) > 0.1))
        base = rng.uniform(0.1, 1, V)
        w = adaptive_weights(ev, base, 0.8)
        assert np.all(np.isfinite(w)) and np.all(w >= 0) and np.any(w > 0)
        assert w.sum() <= base.sum() + 1e-12
        kept = w > 0
        # never silenced without the step stage's evidence; never above the base weight
        assert np.all(w[kept] >= base[kept] / MAX_RATIO - 1e-12) and np.all(w <= base + 1e-12)
        dropped = ~kept
        assert np.all((ev.residual[dropped] > 0.8) & (ev.matched[dropped] < 5)) or np.all(w == base)


def test_settled_weights_change_only_by_a_whole_halving():
    assert settled(BASE, BASE)
    assert settled(BASE, np.array([0.5, 0.5 / 2 ** 0.5]))       # one level: kept as it is
    assert not settled(BASE, np.array([0.5, 0.25]))             # a halving: adopted
    assert not settled(BASE, np.array([0.5, 0.0]))              # a view dropped: adopted


def test_information_share_of_views():
    rng = np.random.default_rng(2)
    J = rng.normal(0, 50, (12, 2, 6))
    prior = np.full(6, 1e-3)
    full = information_share(J, rng.normal(0, 0.5, (12, 2)), J, 4.0, prior)
    half = information_share(J[:6], rng.normal(0, 0.5, (6, 2)), J, 4.0, prior)
    noisy = information_share(J, rng.normal(0, 2.0, (12, 2)), J, 4.0, prior)
    assert full == pytest.approx(1.0, abs=0.05)
    assert 0 < half < full and 0 < noisy < full
    assert information_share(J[:0], np.zeros((0, 2)), J, 4.0, prior) < 0.01


# --- measured on real views -------------------------------------------------------------------------------------

def _degraded(seed: int):
    """Two views of the box; the second degraded: 40 % of its marks gone, 4 px noise on the rest (blur), and as
    many distractor points again near the target."""
    rng = np.random.default_rng(seed)
    sp = make_problem("box", rng, noise=0.7, clutter=0.1, missing=0.0, n_views=2, size_px=200)
    good, other = sp.problem.views
    model_idx, pts = sp.correspondences[1]
    keep = rng.random(len(pts)) > 0.4
    kept = pts[keep] + rng.normal(0, 4.0, (int(keep.sum()), 2))
    lo, hi = pts.min(axis=0) - 20, pts.max(axis=0) + 20
    junk = rng.uniform(lo, hi, (len(pts), 2))
    bad = View(other.camera, np.concatenate([kept, junk]), 0.5)
    problem = sp.problem.with_views([View(good.camera, good.points, 0.5), bad])
    return sp, problem


def test_view_evidence_tells_the_degraded_view():
    sp, problem = _degraded(5)
    objective = PoseObjective(problem)
    ev = view_evidence(objective, sp.true_pose)
    assert ev.explained[1] < ev.explained[0] and ev.information[1] < ev.information[0]
    w = rule_weights(objective, sp.true_pose, "adaptive", 0.8)
    assert 0 < w[1] < w[0] == 0.5
    np.testing.assert_array_equal(objective.weights, [0.5, 0.5])   # the rule derives, never assigns
    np.testing.assert_array_equal(rule_weights(objective, sp.true_pose, "equal", 0.8), [0.5, 0.5])
    np.testing.assert_array_equal(rule_weights(objective, sp.true_pose, "step", 0.8),
                                  objective.step_rule_weights(sp.true_pose, 0.8))


def test_options_select_the_rule():
    sp, problem = _degraded(5)
    assert Evaluator.for_search(problem, SearchOptions(view_weights="adaptive")).view_weighting == "adaptive"
    assert Evaluator.for_search(problem, SearchOptions(view_weights="equal")).reweighted(sp.true_pose) is None
    with pytest.raises(ValueError, match="view_weights"):
        SearchOptions(view_weights="median")


def test_adaptive_beats_equal_with_one_degraded_view():
    """Seeded problems, the same search seed for both rules: with one view degraded, the adaptive weights give a
    smaller position and rotation error in total than equal weights, and never a wrong basin where equal is right."""
    errors = {"equal": [], "adaptive": []}
    for seed in range(4):
        sp, problem = _degraded(100 + seed)
        for rule in errors:
            sol = solve(problem, SearchOptions(view_weights=rule), seed=seed)
            if rule == "adaptive":  # the degraded view ends weighed down (or dropped), never above the healthy one
                assert sol.view_weights[1] < sol.view_weights[0] == 0.5
            rot, pos = pose_errors(sol.pose, sp.true_pose, sp.symmetries, problem.model.points.mean(axis=0))
            errors[rule].append((np.rad2deg(rot), pos / sp.distance))
    equal, adaptive = np.array(errors["equal"]), np.array(errors["adaptive"])
    assert adaptive[:, 0].sum() < equal[:, 0].sum() and adaptive[:, 1].sum() < equal[:, 1].sum()
