"""Unit tests of evopose.refine: never worse, inside the box, fixed parameters held, and convergence
from a nearby start on clean synthetic problems."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from benchmarks.problems import make_problem, pose_errors
from evopose.camera import Camera
from evopose.fitness import PoseObjective
from geometry import euler_from_rotation, rotation_from_euler
from evopose.problem import Bounds, PoseProblem, View
from evopose.refine import match_residuals, refine


def perturbed(true_pose: np.ndarray, distance: float, rng: np.random.Generator, n: int,
              deg: float = 5.0, frac: float = 0.03) -> np.ndarray:
    """``n`` poses rotated by exactly ``deg`` (random axis) and moved by exactly ``frac * distance`` (random direction)."""
    out = []
    R_true = rotation_from_euler(true_pose[3:])
    for _ in range(n):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        R = Rotation.from_rotvec(np.deg2rad(deg) * axis).as_matrix() @ R_true
        out.append(np.r_[true_pose[:3] + frac * distance * direction, euler_from_rotation(R)])
    return np.array(out)


def distorted_two_view_problem(seed: int = 0):
    """Two views (one with an extrinsic), plumb_bob distortion, 10 % clutter, unequal weights."""
    sp = make_problem("random", np.random.default_rng(seed), noise=0.5, clutter=0.1, missing=0.0,
                      distance=6.0, n_views=2)
    views = []
    for view, dist, w in zip(sp.problem.views, ([0.08, -0.02, 0.001, -0.001, 0.005],
                                                 [-0.1, 0.03, -0.0005, 0.001, -0.004]), (1.0, 0.6)):
        c = view.camera
        cam = Camera(c.fx, c.fy, c.cx, c.cy, c.width, c.height, np.array(dist), c.world_from_camera)
        views.append(View(cam, view.points, w))
    return sp, sp.problem.with_views(views)


def population(sp, problem: PoseProblem, rng: np.random.Generator) -> np.ndarray:
    """Near and far candidates, and some uniform in the box (mostly hopeless)."""
    near = perturbed(sp.true_pose, sp.distance, rng, 6, deg=3.0, frac=0.01)
    mid = perturbed(sp.true_pose, sp.distance, rng, 6, deg=15.0, frac=0.05)
    far = problem.bounds.uniform(8, rng)
    return np.vstack([sp.true_pose, near, mid, far])


# --- never worse, consistent fitness ---------------------------------------------------------------------------

@pytest.mark.parametrize("kind", ["robust", "paper"])
def test_refine_never_worsens_fitness(kind):
    sp, problem = distorted_two_view_problem()
    objective = PoseObjective(problem, kind)
    poses = population(sp, problem, np.random.default_rng(1))
    poses_in = poses.copy()
    before = objective(poses)
    out, fit = refine(objective, poses)
    np.testing.assert_array_equal(poses, poses_in)   # the input is not modified
    assert out.shape == poses.shape and fit.shape == (len(poses),)
    after = objective(out)
    # the returned fitness is the objective's fitness of the returned poses
    np.testing.assert_allclose(fit, after, rtol=1e-9, atol=1e-12)
    assert np.all(after <= before * (1 + 1e-12) + 1e-12), after - before
    # and it does improve the near candidates (it is not a no-op)
    assert np.all(after[1:7] < before[1:7])


def test_refine_uses_the_given_fitness_and_leaves_it_alone():
    sp, problem = distorted_two_view_problem()
    objective = PoseObjective(problem, "robust")
    poses = population(sp, problem, np.random.default_rng(2))
    before = objective(poses)
    given = before.copy()
    out_a, fit_a = refine(objective, poses, fitness=given)
    np.testing.assert_array_equal(given, before)
    out_b, fit_b = refine(objective, poses)
    np.testing.assert_allclose(out_a, out_b, atol=1e-12)
    np.testing.assert_allclose(fit_a, fit_b, rtol=1e-12)


def test_refine_honours_view_weights():
    """A view switched off by the step rule (weight 0) is ignored: the result equals refining without it."""
    sp, problem = distorted_two_view_problem()
    objective = PoseObjective(problem, "robust", weights=np.array([1.0, 0.0]))
    alone = PoseObjective(problem.with_views([problem.views[0]]), "robust")
    poses = population(sp, problem, np.random.default_rng(3))[:10]
    out, fit = refine(objective, poses)
    out_alone, fit_alone = refine(alone, poses)
    np.testing.assert_allclose(out, out_alone, atol=1e-9)
    np.testing.assert_allclose(fit, fit_alone, rtol=1e-9)
    np.testing.assert_allclose(fit, objective(out), rtol=1e-9)


# --- bounds and eq. (3) constraints ----------------------------------------------------------------------------

def test_refine_keeps_poses_inside_the_box():
    sp = make_problem("random", np.random.default_rng(4), noise=0.5, clutter=0.0, missing=0.0, distance=5.0)
    t = sp.true_pose
    # a tight box that excludes the truth on x (the optimum pushes against x's upper edge)
    lo = np.r_[t[:3] - [0.2, 0.05, 0.1], t[3:] - 0.1]
    hi = np.r_[t[0] - 0.03, t[1:3] + [0.05, 0.1], t[3:] + 0.1]
    problem = PoseProblem(sp.problem.model, sp.problem.views, Bounds(lo, hi))
    objective = PoseObjective(problem, "robust")
    rng = np.random.default_rng(5)
    starts = np.vstack([perturbed(t, sp.distance, rng, 10, deg=4.0, frac=0.02),   # partly outside the box
                        problem.bounds.uniform(10, rng)])
    out, fit = refine(objective, starts)
    assert np.all(out >= lo) and np.all(out <= hi), (out - lo, hi - out)
    assert np.all(problem.bounds.contains(out, atol=0.0))
    np.testing.assert_allclose(fit, objective(out), rtol=1e-9)
    # the start outside the box was brought in first: never worse than its projection
    assert np.all(fit <= objective(problem.bounds.project(starts)) * (1 + 1e-12))
    # with the truth beyond the x edge, the best individuals end on that edge
    assert np.isclose(out[np.argmin(fit), 0], hi[0], atol=1e-3)


def test_refine_wraps_periodic_angles():
    sp = make_problem("random", np.random.default_rng(6), noise=0.5, clutter=0.0, missing=0.0, distance=5.0)
    objective = PoseObjective(sp.problem, "robust")
    bounds = sp.problem.bounds
    assert bounds.periodic[3:].all()
    starts = perturbed(sp.true_pose, sp.distance, np.random.default_rng(7), 12, deg=3.0, frac=0.005)
    starts[:, 3:] += 2 * np.pi * np.random.default_rng(8).integers(-2, 3, (12, 3))   # same rotations
    out, fit = refine(objective, starts)
    assert np.all(out[:, 3:] >= -np.pi) and np.all(out[:, 3:] < np.pi)
    np.testing.assert_allclose(fit, objective(out), rtol=1e-9)


def test_refine_does_not_move_fixed_parameters():
    sp = make_problem("random", np.random.default_rng(9), noise=0.5, clutter=0.0, missing=0.0, distance=5.0)
    t = sp.true_pose
    z_fixed = t[2] + 0.04                 # deliberately a little off the truth
    bounds = sp.problem.bounds.constrained("roll", t[3], 0.0).constrained("z", z_fixed, 0.0)
    bounds = bounds.constrained("yaw", t[5], 0.02)
    np.testing.assert_array_equal(bounds.free, [True, True, False, False, True, True])
    problem = PoseProblem(sp.problem.model, sp.problem.views, bounds)
    objective = PoseObjective(problem, "robust")
    starts = perturbed(t, sp.distance, np.random.default_rng(10), 10, deg=3.0, frac=0.01)
    out, fit = refine(objective, starts)
    np.testing.assert_array_equal(out[:, 2], z_fixed)
    np.testing.assert_array_equal(out[:, 3], t[3])
    assert np.all(np.abs(out[:, 5] - t[5]) <= 0.02 + 1e-12)
    assert np.all(bounds.contains(out, atol=0.0))
    # the free parameters did move
    assert np.all(np.abs(out[:, [0, 1, 4]] - bounds.project(starts)[:, [0, 1, 4]]).max(axis=1) > 1e-4)
    np.testing.assert_allclose(fit, objective(out), rtol=1e-9)


# --- convergence -------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("seed", range(5))
def test_refine_converges_from_a_nearby_start(seed):
    """5 deg and 3 % of the distance off, on a clean problem (random 3-D marks at 5 m, 0.5 px noise):
    every start reaches the pose within 0.5 deg / 1 % of the truth, at the fitness of the truth or better."""
    sp = make_problem("random", np.random.default_rng(seed), noise=0.5, clutter=0.0, missing=0.0, distance=5.0)
    objective = PoseObjective(sp.problem, "robust")
    starts = perturbed(sp.true_pose, sp.distance, np.random.default_rng(100 + seed), 8)
    start_err = np.array([pose_errors(s, sp.true_pose, sp.symmetries) for s in starts])
    np.testing.assert_allclose(start_err[:, 0], np.deg2rad(5.0), rtol=1e-6)
    out, fit = refine(objective, starts)
    err = np.array([pose_errors(s, sp.true_pose, sp.symmetries) for s in out])
    assert np.all(np.rad2deg(err[:, 0]) < 0.5), np.rad2deg(err[:, 0])
    assert np.all(err[:, 1] < 0.01 * sp.distance), err[:, 1] / sp.distance
    assert np.all(fit <= objective(sp.true_pose[None])[0] * (1 + 1e-9))
    # all starts agree on one local minimum
    assert np.ptp(fit) < 1e-6 * fit.max()


def test_refine_fitness_consistent_with_normals():
    """The compiled refinement computes its own projection and visibility: with a model with normals
    (the box) its fitness must still be :class:`PoseObjective`'s."""
    sp = make_problem("box", np.random.default_rng(11), noise=0.5, clutter=0.2, missing=0.1, distance=6.0)
    assert sp.problem.model.normals is not None
    objective = PoseObjective(sp.problem, "robust")
    poses = population(sp, sp.problem, np.random.default_rng(12))
    before = objective(poses)
    out, fit = refine(objective, poses)
    np.testing.assert_allclose(fit, objective(out), rtol=1e-9, atol=1e-12)
    assert np.all(fit <= before * (1 + 1e-12))
    assert np.any(fit < before)


# --- one chamfer distance, one objective ---------------------------------------------------------------------------

@pytest.mark.parametrize("case", ["distorted two views", "box with normals", "one view weighted 0", "paper's eq. 1"])
def test_fitness_equals_the_refinement_s_residual_cost(case):
    """The refinement's nearest-neighbour residuals (what its hard steps pull on, from its own packed views and
    projection), truncated at tau and summed as eq. (1) and (4) say, give the fitness of the same pose."""
    kind, weights = "robust", None
    if case == "box with normals":
        sp = make_problem("box", np.random.default_rng(11), noise=0.5, clutter=0.2, missing=0.1, distance=6.0)
        problem = sp.problem
    else:
        sp, problem = distorted_two_view_problem()
        kind = "paper" if case == "paper's eq. 1" else "robust"
        weights = [0.7, 0.0] if case == "one view weighted 0" else None
    objective = PoseObjective(problem, kind, weights=weights)
    poses = population(sp, problem, np.random.default_rng(13))
    fitness = objective(poses)
    for pose, f in zip(poses, fitness):
        cost = 0.0
        for (image, model), w, tau in zip(match_residuals(objective, pose), objective.weights, objective.taus):
            if kind == "robust":  # both directions, truncated, one mean
                term = (np.minimum(image, tau).sum() + np.minimum(model, tau).sum()) / (len(image) + len(model))
            else:                 # eq. (1): every image point to its nearest projected model point
                term = image.sum()
            cost += w * term
        assert cost == pytest.approx(f, rel=1e-9, abs=1e-12)
    # and the cost the refinement reports for its result is the objective's
    out, fit = refine(objective, poses[:6])
    np.testing.assert_allclose(fit, objective(out), rtol=1e-9, atol=1e-12)


def test_refine_does_not_mutate_the_objective():
    """Refinement reads the objective's own packed arrays (computed once by the objective); it attaches nothing
    to it and changes none of its numbers, so a fresh objective refines the same."""
    sp, problem = distorted_two_view_problem()
    objective = PoseObjective(problem, "robust", weights=[1.0, 0.6])
    attributes = set(vars(objective))
    weights, taus = objective.weights.copy(), objective.taus.copy()
    poses = population(sp, problem, np.random.default_rng(14))
    out, fit = refine(objective, poses)
    assert set(vars(objective)) - attributes <= {"packed"} and not hasattr(objective, "_packed")
    assert objective.packed is objective.packed
    np.testing.assert_array_equal(objective.weights, weights)
    np.testing.assert_array_equal(objective.taus, taus)
    with pytest.raises(dataclasses.FrozenInstanceError):
        objective.weights = np.array([1.0, 0.0])
    with pytest.raises(ValueError, match="read-only"):
        objective.weights[1] = 0.0
    out_fresh, fit_fresh = refine(PoseObjective(problem, "robust", weights=[1.0, 0.6]), poses)
    np.testing.assert_array_equal(out, out_fresh)
    np.testing.assert_array_equal(fit, fit_fresh)


def test_the_refinements_own_solve_matches_lapack_and_gives_a_zero_for_a_zero_pivot():
    """The damped Gauss-Newton step's 6 x 6 solve (written out in the kernel: numba's np.linalg.solve loads LAPACK
    through scipy.linalg) gives LAPACK's answer on the systems a step meets: a damped normal matrix, rows of held
    parameters set to the identity, a badly scaled one (metres against radians); a zero pivot gives 0, not NaN."""
    from evopose.refine_kernel import solve_in_place

    solve = getattr(solve_in_place, "py_func", solve_in_place)   # the code the kernel compiles, run as Python
    rng = np.random.default_rng(3)
    for case in range(200):
        J = rng.normal(size=(40, 6)) * np.array([1.0, 1.0, 1e-2, 50.0, 50.0, 50.0])   # position and angle scales
        A = J.T @ J
        A[np.diag_indices(6)] *= 1.0 + 10.0 ** rng.uniform(-6, 1)
        held = rng.random(6) < 0.3
        A[held], A[:, held] = 0.0, 0.0
        A[held, held] = 1.0
        rhs = rng.normal(size=6)
        expected = np.linalg.solve(A, rhs)
        got = solve(A.copy(), rhs.copy())
        np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12 * np.abs(expected).max(), err_msg=str(case))
    singular = np.diag([2.0, 0.0, 1.0, 1.0, 1.0, 1.0])
    got = solve(singular.copy(), np.ones(6))
    assert np.isfinite(got).all() and got[1] == 0.0 and got[0] == 0.5


@pytest.mark.parametrize("distortion", [(0.0,) * 5, (-0.2, 0.05, 1e-3, -2e-3, 0.01)], ids=["pinhole", "plumb_bob"])
def test_the_refinements_jacobian_is_the_projections_derivative(distortion):
    """The refinement's analytic Jacobian (evopose.projection.pose_jacobian) against central differences of the
    projection itself, every usable point and parameter; a parameter held fixed and an unusable point get zero."""
    from evopose import projection as kernels   # the numba functions themselves (the refinement's callees)

    rng = np.random.default_rng(11)
    intr = np.array([800.0, 790.0, 320.0, 240.0, *distortion])
    cfw = np.eye(4)
    cfw[:3, :3] = rotation_from_euler(np.array([2.5, 0.1, -0.3]))
    cfw[:3, 3] = [0.3, -0.2, 12.0]
    model = rng.normal(scale=0.4, size=(30, 3))
    normals = model / np.linalg.norm(model, axis=1, keepdims=True)
    u, v, usable = np.empty(30), np.empty(30), np.empty(30, bool)
    r, rc = np.empty((3, 3)), np.empty((3, 3))
    for _ in range(5):
        s = np.concatenate([rng.normal(scale=0.5, size=3), rng.uniform(-np.pi, np.pi, 3)])
        kernels.project_pose(s, model, normals, True, intr, cfw, u, v, usable, r, rc)
        assert 5 < usable.sum() < 30   # some points face away: their rows must be zero
        free = np.array([True, True, False, True, True, True])
        J = np.full((30, 2, 6), np.nan)
        kernels.pose_jacobian(s, model, intr, cfw, usable, free, J)
        numeric = np.zeros((30, 2, 6))
        for d in np.flatnonzero(free):
            h = 1e-6
            up, vp, um, vm = (np.empty(30) for _ in range(4))
            sp, sm = s.copy(), s.copy()
            sp[d] += h
            sm[d] -= h
            kernels.project_pose(sp, model, normals, True, intr, cfw, up, vp, np.empty(30, bool), r, rc)
            kernels.project_pose(sm, model, normals, True, intr, cfw, um, vm, np.empty(30, bool), r, rc)
            numeric[:, 0, d], numeric[:, 1, d] = (up - um) / (2 * h), (vp - vm) / (2 * h)
        np.testing.assert_allclose(J[usable], numeric[usable], rtol=1e-5, atol=1e-4)
        assert not J[~usable].any() and not J[:, :, 2].any()
