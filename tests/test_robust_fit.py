"""evopose.robust_fit, by its effect: false points within tau of their marks tilt the least-squares pose and the
biweighted fit lets them go; on clean points it changes nothing that matters; eq. (3) holds; too few pairs
leave the pose as it was."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.problems import make_problem, pose_errors
from evopose.fitness import PoseObjective
from evopose.problem import PoseProblem
from evopose.refine import refine
from evopose.robust_fit import residual_scale, robust_pose
from evopose.robust_kernel import loss_and_weight
from evopose.solver import POLISH_SCHEDULE


def biased_problem(seed: int, share: float = 0.25, shift_px: tuple[float, float] = (1.5, 2.5)):
    """A clean problem seen by two cameras (random 3-D marks at 8 m, 0.3 px noise), then in each view the image
    points of a ``share`` of the marks moved ``shift_px`` pixels in random directions: the body's structure
    found 1.5-2.5 px beside marks the front-end missed (Cycles frames at the paper's scale), inside tau (4 px)."""
    rng = np.random.default_rng(seed)
    sp = make_problem("random", rng, noise=0.3, clutter=0.0, missing=0.0, distance=8.0, n_views=2)
    views = []
    for view in sp.problem.views:
        points = view.points.copy()
        moved = rng.choice(len(points), max(1, int(round(share * len(points)))), replace=False)
        angle = rng.uniform(0, 2 * np.pi, len(moved))
        points[moved] += rng.uniform(*shift_px, len(moved))[:, None] * np.stack([np.cos(angle), np.sin(angle)], 1)
        views.append(type(view)(view.camera, points, view.weight))
    return sp, sp.problem.with_views(views)


def errors_deg_m(pose: np.ndarray, sp) -> tuple[float, float]:
    rotation, position = pose_errors(pose, sp.true_pose, sp.symmetries)
    return float(np.rad2deg(rotation)), float(position)


SEEDS = range(12)


def least_squares_and_robust(problem: PoseProblem, start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    objective = PoseObjective(problem, "mutual", 4.0)
    least_squares = refine(objective, start[None], None, POLISH_SCHEDULE)[0][0]
    return least_squares, robust_pose(objective, least_squares)


def test_false_points_within_tau_pull_least_squares_and_the_robust_fit_lets_them_go():
    """A quarter of each view's points 1.5-2.5 px off their marks: over 12 problems least squares is 0.23 deg and
    1.4 mm off on average, the robust fit under half of that in both (0.10 deg, 0.7 mm)."""
    ls_err, rb_err = [], []
    for seed in SEEDS:
        sp, problem = biased_problem(seed)
        least_squares, robust = least_squares_and_robust(problem, sp.true_pose)
        ls_err.append(errors_deg_m(least_squares, sp))
        rb_err.append(errors_deg_m(robust, sp))
    ls_mean, rb_mean = np.mean(ls_err, axis=0), np.mean(rb_err, axis=0)
    assert np.all(rb_mean < 0.6 * ls_mean), (ls_mean, rb_mean)
    assert sum(r[0] < l[0] for l, r in zip(ls_err, rb_err)) >= 9  # most problems, not one lucky one


def test_on_clean_points_the_robust_fit_is_as_precise_as_least_squares():
    """No false points (0.5 px noise): the pairs beyond 3 sigma it drops are true ones, so it may lose a little,
    not more than a quarter of least squares' error on average."""
    ls_err, rb_err = [], []
    for seed in SEEDS:
        sp = make_problem("random", np.random.default_rng(seed), noise=0.5, clutter=0.0, missing=0.0, distance=8.0,
                          n_views=2)
        least_squares, robust = least_squares_and_robust(sp.problem, sp.true_pose)
        ls_err.append(errors_deg_m(least_squares, sp))
        rb_err.append(errors_deg_m(robust, sp))
    ls_mean, rb_mean = np.mean(ls_err, axis=0), np.mean(rb_err, axis=0)
    assert np.all(rb_mean <= 1.25 * ls_mean), (ls_mean, rb_mean)


def test_fixed_parameters_never_move_and_the_pose_stays_in_the_box():
    sp, problem = biased_problem(7)
    t = sp.true_pose
    z_fixed = t[2] + 0.005
    bounds = problem.bounds.constrained("roll", t[3], 0.0).constrained("z", z_fixed, 0.0).constrained("yaw", t[5],
                                                                                                         0.01)
    constrained = PoseProblem(problem.model, problem.views, bounds)
    objective = PoseObjective(constrained, "mutual", 4.0)
    start = bounds.project(t + np.array([0.004, -0.004, 0.0, 0.0, 0.003, 0.002]))
    out = robust_pose(objective, start)
    assert out[2] == z_fixed and out[3] == t[3]
    assert abs(out[5] - t[5]) <= 0.01 + 1e-12
    assert bounds.contains(out, atol=0.0)
    assert np.abs(out[[0, 1, 4]] - start[[0, 1, 4]]).max() > 1e-4  # the free ones did move


def test_a_pose_with_too_few_pairs_is_returned_as_it_was():
    sp, problem = biased_problem(3)
    view = problem.views[0]
    sparse = problem.with_views([type(view)(view.camera, view.points[:2], view.weight)])
    objective = PoseObjective(sparse, "mutual", 4.0)
    start = sp.true_pose + 0.01
    np.testing.assert_array_equal(robust_pose(objective, start), start)


def test_the_biweight_and_the_scale():
    d = np.array([0.0, 0.5, 1.0, 1.5, 3.0])
    biweight = getattr(loss_and_weight, "py_func", loss_and_weight)  # the code the kernel compiles, run as Python
    rho, w = np.array([biweight(x, 1.5, True) for x in d]).T
    np.testing.assert_allclose(w[[0, 3, 4]], [1.0, 0.0, 0.0])
    assert np.all(np.diff(w) <= 0) and 0 < w[2] < w[1] < 1
    np.testing.assert_allclose(rho[[0, 3, 4]], [0.0, 1.5 ** 2 / 6, 1.5 ** 2 / 6])  # the loss stops at its ceiling
    trimmed = np.array([getattr(loss_and_weight, "py_func", loss_and_weight)(x, 1.5, False) for x in d])
    np.testing.assert_allclose(trimmed[:, 1], [1.0, 1.0, 1.0, 0.0, 0.0])
    np.testing.assert_allclose(trimmed[:, 0], [0.0, 0.125, 0.5, 1.125, 1.125])
    # a 2-D Gaussian of sigma 1 has median radius sqrt(2 ln 2)
    radii = np.linalg.norm(np.random.default_rng(0).normal(size=(20000, 2)), axis=1)
    assert residual_scale(radii) == pytest.approx(1.0, abs=0.02)
    assert residual_scale(np.array([0.01, 0.02])) == 0.35 and residual_scale(np.zeros(0)) == 0.35


def test_a_handful_of_clean_pairs_keeps_the_least_squares_precision():
    """Issue 35: a marked box 50 px wide (20-30 m, f = 2400 px) shows 6-14 marks at 1 px noise. The residual scale
    from so few pairs is uncertain (half its value at times), and a fixed 3-sigma cut dropped true pairs: rotation
    errors 1.20x and position 1.33x least squares' on these 16 problems. With the cut widened for the pairs'
    residual degrees of freedom: 1.10x and 1.12x (the biweight stage itself is less efficient than least squares
    on clean points)."""
    from benchmarks.problems import box_model

    extent = 2 * box_model()[0].radius
    ls_err, rb_err = [], []
    for seed in range(16):
        rng = np.random.default_rng([35, seed])
        distance = rng.uniform(20, 30)
        sp = make_problem("box", rng, distance=distance, noise=1.0, clutter=0.0, missing=0.1,
                          size_px=2400 * extent / distance)
        least_squares, robust = least_squares_and_robust(sp.problem, sp.true_pose)
        ls_err.append(errors_deg_m(least_squares, sp))
        rb_err.append(errors_deg_m(robust, sp))
    ls_mean, rb_mean = np.mean(ls_err, axis=0), np.mean(rb_err, axis=0)
    assert np.all(rb_mean <= 1.15 * ls_mean), (ls_mean, rb_mean)


def test_a_whole_step_under_the_settled_bar_ends_a_stage_and_leaves_the_pose_where_more_steps_would(monkeypatch):
    """SETTLED_WHOLE_STEP: Gauss-Newton's whole steps shrink quadratically, so a stage ends after a whole step under
    1e-4; the steps it saves (each a re-match of every mark) would move the pose by less than 1e-6 on every problem."""
    import evopose.robust_fit as rf

    calls = {"n": 0}
    irls = rf.robust_irls

    def counted(*args):   # the steps the compiled stages take (each a re-match of every mark)
        taken = irls(*args)
        calls["n"] += int(taken)
        return taken

    monkeypatch.setattr(rf, "robust_irls", counted)
    quick, full, quick_calls, full_calls = [], [], 0, 0
    for seed in SEEDS:
        sp, problem = biased_problem(seed)
        objective = PoseObjective(problem, "mutual", 4.0)
        start = refine(objective, sp.true_pose[None], None, POLISH_SCHEDULE)[0][0]
        calls["n"] = 0
        quick.append(robust_pose(objective, start))
        quick_calls += calls["n"]
        with monkeypatch.context() as m:
            m.setattr(rf, "SETTLED_WHOLE_STEP", 0.0)   # only the 1e-6 bar
            calls["n"] = 0
            full.append(robust_pose(objective, start))
            full_calls += calls["n"]
    assert np.max(np.abs(np.array(quick) - np.array(full))) < 1e-6
    assert quick_calls < full_calls   # and it saved work
