"""The search end to end: robustness cases, eq. (3) constraints, hints, seeds, eq. (4) views, tracking."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.problems import is_success, make_problem, pose_errors
from evopose import Bounds, EvoPose, PoseObjective, PoseProblem, SearchOptions, View, solve, track
from evopose.pose import PARAM_NAMES


def _errors(sp, pose):
    rot, pos = pose_errors(pose, sp.true_pose, sp.symmetries, sp.problem.model.points.mean(axis=0))
    return np.rad2deg(rot), pos


def _assert_solved(sp, solution):
    rot, pos = _errors(sp, solution.pose)
    assert is_success(np.deg2rad(rot), pos, sp.distance), (
        f"{sp.kind}: rotation error {rot:.1f} deg, position error {pos:.2f} m at {sp.distance:.1f} m "
        f"(fitness {solution.fitness:.2f}, {solution.stop_reason})")


@pytest.mark.parametrize("kind, seed, difficulty", [
    ("box", 101, dict(noise=2.0, clutter=0.0, missing=0.0)),          # noise
    ("box", 102, dict(noise=1.0, clutter=0.0, missing=0.2)),          # occlusion
    ("box", 103, dict(noise=1.0, clutter=0.3, missing=0.1)),          # clutter, 30 %
    ("random", 104, dict(noise=1.5, clutter=0.3, missing=0.2)),       # all at once
    ("ellipsoid", 105, dict(noise=1.0, clutter=0.2, missing=0.1)),    # near-symmetric airship
    ("grid", 106, dict(noise=1.0, clutter=0.25, missing=0.1, distance=6.0)),  # planar regular grid
])
def test_robustness_cases_are_solved(kind, seed, difficulty):
    sp = make_problem(kind, np.random.default_rng(seed), **difficulty)
    solution = solve(sp.problem, seed=seed)
    _assert_solved(sp, solution)
    assert solution.converged


def test_robust_fitness_prefers_truth_where_plain_eq1_does_not():
    """With clutter on one side the paper's eq. (1) minimum moves; the robust fitness keeps the truth."""
    sp = make_problem("random", np.random.default_rng(7), noise=0.5, clutter=0.0, missing=0.0)
    view = sp.problem.views[0]
    rng = np.random.default_rng(0)
    far_side = view.points.max(axis=0) + rng.uniform(40, 120, (8, 2))  # false points beyond one corner
    cluttered = sp.problem.with_views([View(view.camera, np.concatenate([view.points, far_side]))])
    shifted = sp.true_pose.copy()
    shifted[:2] += 0.02 * sp.distance  # a wrong pose leaning towards the false points
    paper = PoseObjective(cluttered, "paper")
    robust = PoseObjective(cluttered, "robust")
    candidates = np.stack([sp.true_pose, shifted])
    # whichever wins eq. (1), the robust one must rank the truth first
    assert robust(candidates)[0] < robust(candidates)[1]
    assert paper(candidates).shape == (2,)


def test_same_seed_same_result_and_different_seed_runs_differently():
    sp = make_problem("box", np.random.default_rng(11), noise=1.0, clutter=0.1, missing=0.1)
    a = solve(sp.problem, seed=5)
    b = solve(sp.problem, seed=5)
    c = solve(sp.problem, seed=6)
    np.testing.assert_array_equal(a.pose, b.pose)
    assert a.history == b.history and a.evaluations == b.evaluations
    assert c.history != a.history


def test_constraints_eq3_hold_and_help():
    """IMU attitude within +-0.01 rad: every returned angle stays in [C - eps, C + eps]."""
    sp = make_problem("ellipsoid", np.random.default_rng(21), noise=1.0, clutter=0.1, missing=0.05)
    bounds = sp.problem.bounds
    eps = 0.01
    for name, i in (("roll", 3), ("pitch", 4)):
        bounds = bounds.constrained(name, sp.true_pose[i] + 0.005, eps)
    problem = PoseProblem(sp.problem.model, sp.problem.views, bounds)
    solution = solve(problem, seed=1)
    for i in (3, 4):
        centre = sp.true_pose[i] + 0.005
        assert abs(solution.pose[i] - centre) <= eps + 1e-9, PARAM_NAMES[i]
    _assert_solved(sp, solution)


def test_fixed_parameter_never_moves():
    sp = make_problem("box", np.random.default_rng(22), noise=1.0, clutter=0.0, missing=0.0)
    bounds = sp.problem.bounds.constrained("yaw", sp.true_pose[5], 0.0)
    solution = solve(PoseProblem(sp.problem.model, sp.problem.views, bounds), seed=0)
    assert solution.pose[5] == pytest.approx(sp.true_pose[5], abs=1e-12)


def test_good_hint_enters_and_wins_bad_hint_dies():
    sp = make_problem("box", np.random.default_rng(31), noise=1.0, clutter=0.2, missing=0.1)
    options = SearchOptions()
    rng = np.random.default_rng(0)
    evo = EvoPose(sp.problem, options, rng, PoseObjective(sp.problem).fitness_scale())
    objective = PoseObjective(sp.problem)
    state = evo.start()
    candidates, origins = evo.ask(state)
    evo.tell(state, candidates, objective(candidates), origins)
    bad = sp.true_pose.copy()
    bad[3:] += np.deg2rad([150.0, -60.0, 90.0])
    bad[:3] *= 1.5
    evo.inject(state, bad[None])
    candidates, origins = evo.ask(state)
    hint_rows = origins < 0
    assert hint_rows.sum() == 1
    np.testing.assert_allclose(candidates[hint_rows][0], sp.problem.bounds.project(bad))
    evo.tell(state, candidates, objective(candidates), origins)
    assert not np.any(state.origin < 0), "a hint that fits nothing must be discarded by selection"
    # the true pose as a hint becomes the best individual at once
    evo.inject(state, sp.true_pose[None])
    candidates, origins = evo.ask(state)
    evo.tell(state, candidates, objective(candidates), origins)
    assert state.best_from_hint


def test_solve_with_hint_uses_it():
    sp = make_problem("ellipsoid", np.random.default_rng(32), noise=1.0, clutter=0.2, missing=0.1)
    hinted = sp.problem.with_hints(sp.true_pose[None] + np.r_[0.02, -0.02, 0.1, 0.02, -0.02, 0.02])
    solution = solve(hinted, seed=0)
    _assert_solved(sp, solution)
    assert solution.from_hint
    alone = solve(sp.problem, seed=0)
    assert solution.generations < alone.generations, "a good hint must shorten the search"


def test_step_rule_drops_a_view_without_the_target():
    """Eq. (4) with two views; the second shows only clutter and must get weight 0."""
    sp = make_problem("box", np.random.default_rng(41), noise=1.0, clutter=0.1, missing=0.0, n_views=2)
    good, other = sp.problem.views
    rng = np.random.default_rng(1)
    junk = View(other.camera, rng.uniform([100, 100], [540, 380], (15, 2)))
    problem = sp.problem.with_views([good, junk])
    solution = solve(problem, seed=0)
    assert solution.view_weights[0] > 0 and solution.view_weights[1] == 0
    _assert_solved(sp, solution)


def test_two_views_beat_one_on_depth():
    """Eq. (4): over a few problems the stereo position error is lower than the single view's."""
    both_err, alone_err = [], []
    for seed in (42, 43, 44, 45):
        sp = make_problem("box", np.random.default_rng(seed), noise=2.0, clutter=0.1, missing=0.0, n_views=2)
        both = solve(sp.problem, seed=0)
        alone = solve(sp.problem.with_views(sp.problem.views[:1]), seed=0)
        _assert_solved(sp, both)
        both_err.append(_errors(sp, both.pose)[1])
        alone_err.append(_errors(sp, alone.pose)[1])
    assert np.mean(both_err) < np.mean(alone_err), (both_err, alone_err)


def test_paper_fitness_is_selectable_and_evaluated():
    sp = make_problem("random", np.random.default_rng(51), noise=0.5, clutter=0.0, missing=0.0)
    solution = solve(sp.problem, SearchOptions(fitness="paper", max_generations=5), seed=0)
    assert solution.fitness == pytest.approx(PoseObjective(sp.problem, "paper")(solution.pose[None])[0])


def test_tracking_follows_small_motion_and_reinitialises_when_lost():
    rng = np.random.default_rng(61)
    sp = make_problem("box", rng, noise=0.5, clutter=0.0, missing=0.0)
    first = solve(sp.problem, seed=0)
    _assert_solved(sp, first)
    from evopose.fitness import project_into_view
    pose = sp.true_pose.copy()
    previous = first
    for _ in range(5):
        pose = pose + np.r_[0.01, -0.01, 0.02, 0.01, 0.005, -0.01]
        view = sp.problem.views[0]
        proj = project_into_view(sp.problem.model, view, pose[None])
        pts = proj.uv[0][proj.usable[0]] + 0.5 * rng.standard_normal((int(proj.usable[0].sum()), 2))
        previous = track(previous, [View(view.camera, pts)])
        assert previous.stop_reason == "tracked"
    rot, pos = pose_errors(previous.pose, pose, sp.symmetries, sp.problem.model.points.mean(axis=0))
    assert np.rad2deg(rot) < 2 and pos < 0.02 * sp.distance
    # a frame from a far-away pose: the fit is lost and the search starts over
    jump = pose + np.r_[0.0, 0.0, 0.0, 1.5, -1.0, 2.0]
    proj = project_into_view(sp.problem.model, sp.problem.views[0], jump[None])
    lost = track(previous, [View(sp.problem.views[0].camera, proj.uv[0][proj.usable[0]])], seed=0)
    assert lost.reinitialised


def test_bounds_are_respected_by_the_result():
    sp = make_problem("box", np.random.default_rng(71), noise=1.0, clutter=0.0, missing=0.0)
    lo, hi = sp.problem.bounds.lo.copy(), sp.problem.bounds.hi.copy()
    lo[:3], hi[:3] = sp.true_pose[:3] - 1.0, sp.true_pose[:3] + 1.0
    solution = solve(PoseProblem(sp.problem.model, sp.problem.views, Bounds(lo, hi)), seed=0)
    assert Bounds(lo, hi).contains(solution.pose)
