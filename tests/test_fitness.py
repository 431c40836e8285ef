"""Unit tests of the fitness: the compiled chamfer kernels, eq. (1) ("paper"), the robust variant, eq. (4)
over several views, the step-function weights, and visibility by normals."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.problems import grid_model, make_problem
from evopose.camera import Camera
from evopose.fitness import (
    TAU_MAX_PX,
    TAU_MIN_PX,
    PoseObjective,
    auto_tau,
    project_into_view,
    step_weights,
)
from evopose.kernels import MUTUAL, NO_MATCH_D2, chamfer_matches, chamfer_sums, view_terms
from geometry import rotation_from_euler
from evopose.problem import Bounds, Model, PoseProblem, View

BOUNDS = Bounds([-10, -10, 0.5, -np.pi, -np.pi, -np.pi], [10, 10, 50, np.pi, np.pi, np.pi])


# --- compiled kernels vs a brute-force reference ----------------------------------------------------------

def kernel_data(seed: int, N: int = 9, M: int = 40, P: int = 33):
    rng = np.random.default_rng(seed)
    u = rng.uniform(0, 640, (N, M))
    v = rng.uniform(0, 480, (N, M))
    usable = rng.random((N, M)) > 0.25
    usable[0] = False            # an individual with no usable model point at all
    usable[1] = True
    usable[2] = False
    usable[2, 0] = True          # exactly one usable point
    px = rng.uniform(0, 640, P)
    py = rng.uniform(0, 480, P)
    return u, v, usable, px, py


def reference_d2(u, v, usable, px, py):
    """(N, M, P) squared distances, NO_MATCH_D2 where the model point is unusable."""
    d2 = (u[:, :, None] - px[None, None]) ** 2 + (v[:, :, None] - py[None, None]) ** 2
    return np.where(usable[:, :, None], d2, NO_MATCH_D2)


def _untyped(n: int) -> np.ndarray:
    """Label coordinates of untyped points (the paper's eq. 1): zeros."""
    return np.zeros(n)


@pytest.mark.parametrize("robust", [True, False])
@pytest.mark.parametrize("seed", [0, 1])
def test_chamfer_sums_matches_brute_force(seed, robust):
    u, v, usable, px, py = kernel_data(seed)
    tau = 25.0
    img_sum, mod_sum, n_usable = chamfer_sums(u, v, _untyped(u.shape[1]), usable, px, py, _untyped(len(px)), tau, robust)
    d2 = reference_d2(u, v, usable, px, py)
    img_min = d2.min(axis=1)                                   # (N, P): nearest usable model point per image point
    mod_min = d2.min(axis=2)                                   # (N, M)
    if robust:
        img_expected = np.sqrt(np.minimum(img_min, tau * tau)).sum(axis=1)
    else:
        img_expected = np.sqrt(img_min).sum(axis=1)
    mod_expected = np.where(usable, np.sqrt(np.minimum(mod_min, tau * tau)), 0.0).sum(axis=1)
    np.testing.assert_allclose(img_sum, img_expected, rtol=1e-12)
    np.testing.assert_allclose(mod_sum, mod_expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(n_usable, usable.sum(axis=1))
    # the individual without usable model points: every image point costs tau (robust) or the sentinel
    assert img_sum[0] == pytest.approx(len(px) * (tau if robust else np.sqrt(NO_MATCH_D2)), rel=1e-12)
    assert mod_sum[0] == 0.0 and n_usable[0] == 0
    # truncation matters in this data (else the robust/paper distinction would be untested)
    assert np.any(np.sqrt(img_min[1:]) > tau) and np.any(np.sqrt(img_min[1:]) < tau)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_mutual_term_matches_brute_force(seed):
    """The "mutual" view term: RMS over image points and usable marks of the distance to the mutual nearest
    partner within tau, tau for a point without one."""
    u, v, usable, px, py = kernel_data(seed)
    tau = 40.0
    got = view_terms(u, v, _untyped(u.shape[1]), usable, px, py, _untyped(len(px)), tau, MUTUAL)
    d2 = reference_d2(u, v, usable, px, py)                    # (N, M, P)
    for n in range(len(u)):
        used = np.nonzero(usable[n])[0]
        total, pairs = 0.0, 0
        for m in used:
            p = int(np.argmin(d2[n, m]))
            if d2[n, m, p] < tau * tau and int(np.argmin(d2[n, :, p])) == m:
                total += 2 * d2[n, m, p]
                pairs += 1
        total += tau * tau * (len(px) + len(used) - 2 * pairs)
        assert got[n] == pytest.approx(np.sqrt(total / (len(px) + len(used))), rel=1e-12), n
    assert got[0] == pytest.approx(tau)                        # nothing usable: every image point pays tau
    # the data has mutual pairs, pairs beyond tau and non-mutual nearest neighbours
    assert np.any(got[1:] < tau)


def test_chamfer_sums_exact_matches_give_zero():
    rng = np.random.default_rng(3)
    px, py = rng.uniform(0, 100, 7), rng.uniform(0, 100, 7)
    u, v = px[None].copy(), py[None].copy()
    for robust in (True, False):
        img_sum, mod_sum, n_usable = chamfer_sums(u, v, _untyped(7), np.ones((1, 7), bool), px, py, _untyped(7), 5.0, robust)
        assert img_sum[0] == 0.0 and mod_sum[0] == 0.0 and n_usable[0] == 7


@pytest.mark.parametrize("seed", [0, 1])
def test_chamfer_matches_matches_brute_force(seed):
    u, v, usable, px, py = kernel_data(seed)
    img_nn, img_d2, mod_nn, mod_d2 = chamfer_matches(u, v, _untyped(u.shape[1]), usable, px, py, _untyped(len(px)))
    N, M = u.shape
    P = len(px)
    assert img_nn.shape == img_d2.shape == (N, P) and mod_nn.shape == mod_d2.shape == (N, M)
    d2 = reference_d2(u, v, usable, px, py)
    any_usable = usable.any(axis=1)
    img_expected_nn = np.where(any_usable[:, None], d2.argmin(axis=1), -1)
    np.testing.assert_array_equal(img_nn, img_expected_nn)
    np.testing.assert_allclose(img_d2, d2.min(axis=1), rtol=1e-12)
    np.testing.assert_array_equal(mod_nn, np.where(usable, d2.argmin(axis=2), -1))
    np.testing.assert_allclose(mod_d2, np.where(usable, d2.min(axis=2), NO_MATCH_D2), rtol=1e-12)
    # the indices point at the reported distances
    n, p = np.nonzero(img_nn >= 0)
    np.testing.assert_allclose((u[n, img_nn[n, p]] - px[p]) ** 2 + (v[n, img_nn[n, p]] - py[p]) ** 2,
                               img_d2[n, p], rtol=1e-12)
    assert np.all(img_nn[0] == -1) and np.all(img_d2[0] == NO_MATCH_D2)
    assert np.all(img_nn[2] == 0)


# --- eq. (1): the paper's plain fitness, by hand ------------------------------------------------------------

def test_paper_fitness_is_literal_eq1():
    fx, fy, cx, cy = 500.0, 520.0, 320.0, 240.0
    camera = Camera(fx, fy, cx, cy)
    model_points = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [0.0, 0.3, 0.2], [0.1, -0.2, -9.0]])
    image_points = np.array([[330.0, 230.0], [400.0, 250.0], [300.0, 300.0], [10.0, 470.0], [350.0, 200.0]])
    problem = PoseProblem(Model(model_points), (View(camera, image_points),), BOUNDS)
    poses = np.array([
        [0.1, -0.2, 4.0, 0.1, 0.2, 0.3],
        [0.0, 0.0, 3.0, 0.0, 0.0, 0.0],      # the last model point lands behind the camera (z = -6)
        [-0.3, 0.4, 6.0, -0.5, 0.1, 2.0],
    ])
    expected = []
    for s in poses:
        R = rotation_from_euler(s[3:])
        p_cam = model_points @ R.T + s[:3]
        front = p_cam[:, 2] > 0
        uv = np.stack([fx * p_cam[front, 0] / p_cam[front, 2] + cx, fy * p_cam[front, 1] / p_cam[front, 2] + cy], 1)
        # d = sum_i min_j |p_i - m_j(s)|
        d = sum(min(np.hypot(*(p - m)) for m in uv) for p in image_points)
        expected.append(d)
    z_last = (rotation_from_euler(poses[1, 3:]) @ model_points[3] + poses[1, :3])[2]
    assert z_last < 0  # so the hand computation above did exclude a point
    objective = PoseObjective(problem, "paper")
    np.testing.assert_allclose(objective(poses), expected, rtol=1e-12)
    np.testing.assert_allclose(objective.view_terms(poses)[:, 0], expected, rtol=1e-12)
    # the tau argument does not bound the paper's kind
    np.testing.assert_allclose(PoseObjective(problem, "paper", tau=1.0)(poses), expected, rtol=1e-12)
    assert objective.evaluations == 6


def test_robust_fitness_by_hand():
    camera = Camera(500.0, 500.0, 320.0, 240.0)
    model_points = np.array([[0.0, 0.0, 0.0], [0.4, 0.0, 0.0], [0.0, 0.4, 0.0]])
    # at z = 5: the model projects to (320, 240), (360, 240), (320, 280)
    image_points = np.array([[323.0, 244.0], [360.0, 240.0], [100.0, 100.0]])  # 5 px off, exact, clutter
    problem = PoseProblem(Model(model_points), (View(camera, image_points),), BOUNDS)
    tau = 10.0
    d = PoseObjective(problem, "robust", tau=tau)(np.array([[0, 0, 5.0, 0, 0, 0]]))
    img_terms = 5.0 + 0.0 + tau
    mod_terms = 5.0 + 0.0 + min(np.hypot(3, 36), tau)
    assert d[0] == pytest.approx((img_terms + mod_terms) / 6, rel=1e-12)  # one mean over both directions


def test_objective_rejects_bad_arguments():
    camera = Camera(500.0, 500.0, 320.0, 240.0)
    problem = PoseProblem(Model(np.zeros((1, 3))), (View(camera, np.zeros((1, 2)), weight=0.0),), BOUNDS)
    with pytest.raises(ValueError, match="weight"):
        PoseObjective(problem, "robust")
    problem = problem.with_views([View(camera, np.zeros((1, 2)))])
    with pytest.raises(ValueError, match="kind"):
        PoseObjective(problem, "chamfer")


def test_auto_tau():
    grid = np.stack(np.meshgrid(np.arange(10) * 20.0, np.arange(8) * 20.0), -1).reshape(-1, 2)
    assert auto_tau(grid) == pytest.approx(10.0)
    assert auto_tau(grid * 0.1) == TAU_MIN_PX
    assert auto_tau(grid * 100) == TAU_MAX_PX
    assert TAU_MIN_PX <= auto_tau(np.zeros((1, 2))) <= TAU_MAX_PX


# --- eq. (4): several views ----------------------------------------------------------------------------------

@pytest.mark.parametrize("kind", ["robust", "paper"])
def test_two_views_objective_is_weighted_sum(kind):
    sp = make_problem("box", np.random.default_rng(21), noise=1.0, clutter=0.1, missing=0.05, n_views=2)
    v1, v2 = sp.problem.views
    W1, W2 = 0.7, 0.2
    problem = sp.problem.with_views([View(v1.camera, v1.points, W1), View(v2.camera, v2.points, W2)])
    assert not np.allclose(v2.camera.world_from_camera, np.eye(4))
    rng = np.random.default_rng(22)
    poses = np.vstack([sp.true_pose, sp.true_pose + rng.normal(scale=[0.2, 0.2, 0.5, 0.1, 0.1, 0.1], size=(7, 6))])
    objective = PoseObjective(problem, kind)
    d1 = PoseObjective(problem.with_views([v1]), kind)(poses)
    d2 = PoseObjective(problem.with_views([v2]), kind)(poses)
    np.testing.assert_allclose(objective(poses), W1 * d1 + W2 * d2, rtol=1e-12)
    terms = objective.view_terms(poses)
    np.testing.assert_allclose(terms, np.stack([d1, d2], axis=1), rtol=1e-12)
    # both views carry information here (neither term is trivially zero)
    assert np.all(terms > 0)
    # a view whose weight was set to 0 (step rule) is skipped, in a new objective: the old one is unchanged
    reweighted = objective.with_weights([W1, 0.0])
    np.testing.assert_allclose(reweighted(poses), W1 * d1, rtol=1e-12)
    np.testing.assert_array_equal(reweighted.view_terms(poses, only_weighted=True)[:, 1], 0.0)
    np.testing.assert_allclose(objective(poses), W1 * d1 + W2 * d2, rtol=1e-12)
    np.testing.assert_array_equal(objective.weights, [W1, W2])


# --- step-function weights (eq. 4 rule) -------------------------------------------------------------------------

def test_step_weights_drops_views_above_threshold():
    w = np.array([0.5, 0.3, 0.2])
    np.testing.assert_array_equal(step_weights(np.array([1.0, 5.0, 2.0]), w, 2.0), [0.5, 0.0, 0.2])
    np.testing.assert_array_equal(step_weights(np.array([1.0, 5.0, 2.0]), w, np.array([0.5, 6.0, 3.0])),
                                  [0.0, 0.3, 0.2])
    np.testing.assert_array_equal(step_weights(np.array([1.0, 1.0, 1.0]), w, 2.0), w)


def test_step_weights_keeps_base_weights_when_all_would_be_dropped():
    w = np.array([0.5, 0.3, 0.2])
    out = step_weights(np.array([3.0, 5.0, 9.0]), w, 2.0)
    np.testing.assert_array_equal(out, w)
    assert out is not w
    # the only view under the threshold has weight 0: nothing to trust, keep the base weights
    w0 = np.array([0.0, 0.6, 0.4])
    np.testing.assert_array_equal(step_weights(np.array([1.0, 5.0, 9.0]), w0, 2.0), w0)


def test_step_rule_weights_zero_a_bad_view():
    sp = make_problem("box", np.random.default_rng(23), noise=0.5, clutter=0.0, missing=0.0, n_views=2)
    v1, v2 = sp.problem.views
    # the second camera sees something else entirely
    garbage = np.random.default_rng(24).uniform(0, 640, (len(v2.points), 2))
    problem = sp.problem.with_views([v1, View(v2.camera, garbage, 1.0)])
    for kind, threshold in (("robust", 0.5), ("paper", 50.0)):
        objective = PoseObjective(problem, kind)
        weights = objective.step_rule_weights(sp.true_pose, threshold)
        np.testing.assert_array_equal(weights, [1.0, 0.0])
        np.testing.assert_array_equal(objective.weights, [1.0, 1.0])   # the rule derives, never assigns
        reweighted = objective.with_weights(weights)
        np.testing.assert_allclose(reweighted(sp.true_pose[None]),
                                   objective.view_terms(sp.true_pose[None])[:, 0], rtol=1e-12)


# --- visibility by normals -------------------------------------------------------------------------------------

def two_sided_model(with_normals: bool = True) -> Model:
    pts = np.array([[0.0, 0.0, 0.0], [0.2, 0.0, 0.0]])
    normals = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0]]) if with_normals else None
    return Model(pts, normals)


def test_back_facing_points_are_not_usable():
    camera = Camera(500.0, 500.0, 320.0, 240.0)
    view = View(camera, np.array([[320.0, 240.0]]))
    facing = np.array([[0, 0, 5.0, 0, 0, 0], [0, 0, 5.0, 0, np.pi, 0]])   # the second turned round
    proj = project_into_view(two_sided_model(), view, facing)
    np.testing.assert_array_equal(proj.usable, [[True, False], [False, True]])
    np.testing.assert_array_equal(project_into_view(two_sided_model(), view, facing, use_normals=False).usable,
                                  [[True, True], [True, True]])
    np.testing.assert_array_equal(project_into_view(two_sided_model(False), view, facing).usable,
                                  [[True, True], [True, True]])


def test_robust_fitness_ignores_back_facing_points():
    camera = Camera(500.0, 500.0, 320.0, 240.0)
    pose = np.array([[0, 0, 5.0, 0, 0, 0]])
    # only the front-facing point is seen, exactly
    view = View(camera, np.array([[320.0, 240.0]]))
    tau = 10.0
    with_normals = PoseObjective(PoseProblem(two_sided_model(), (view,), BOUNDS), "robust", tau=tau)
    without = PoseObjective(PoseProblem(two_sided_model(False), (view,), BOUNDS), "robust", tau=tau)
    assert with_normals(pose)[0] == 0.0
    # without normals the unseen point (20 px away) counts as a missing mark
    assert without(pose)[0] == pytest.approx((0.0 + 0.0 + tau) / 3)
    # a model wholly facing away: every image point and the (empty) model side cost tau
    turned = np.array([[0, 0, 5.0, 0, np.pi, 0]])
    only_front = Model(np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, 0.0, -1.0]]))
    objective = PoseObjective(PoseProblem(only_front, (view,), BOUNDS), "robust", tau=tau)
    assert objective(turned)[0] == pytest.approx(tau)


def test_paper_fitness_uses_every_point_in_front():
    """Eq. (1) has no visibility model: the paper's kind counts back-facing points too."""
    camera = Camera(500.0, 500.0, 320.0, 240.0)
    view = View(camera, np.array([[340.0, 240.0]]))     # where the back-facing point projects
    objective = PoseObjective(PoseProblem(two_sided_model(), (view,), BOUNDS), "paper")
    assert objective(np.array([[0, 0, 5.0, 0, 0, 0]]))[0] == pytest.approx(0.0, abs=1e-9)


# --- clutter: robust vs the plain eq. (1) --------------------------------------------------------------------------

def grid_row_shifts(true_pose: np.ndarray, square: float = 0.1) -> np.ndarray:
    """The true pose moved by one grid row / column (either way) in the board's plane."""
    R = rotation_from_euler(true_pose[3:])
    out = []
    for d in ([0, square, 0], [0, -square, 0], [square, 0, 0], [-square, 0, 0]):
        s = true_pose.copy()
        s[:3] += R @ np.array(d)
        out.append(s)
    return np.array(out)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_robust_fitness_prefers_truth_over_one_row_shift_with_clutter(seed):
    sp = make_problem("grid", np.random.default_rng(seed), noise=0.5, clutter=0.25, missing=0.0)
    n_true = len(sp.correspondences[0][0])
    n_points = len(sp.problem.views[0].points)
    assert n_points - n_true >= 0.2 * n_points     # there is clutter
    objective = PoseObjective(sp.problem, "robust")
    d = objective(np.vstack([sp.true_pose, grid_row_shifts(sp.true_pose)]))
    assert np.all(d[0] < d[1:]), d
    # by a clear margin: the shifted grid misses a whole row (or column) in both directions
    assert np.all(d[1:] - d[0] > 0.05 * objective.taus[0])


def clustered_clutter_problem() -> tuple[PoseProblem, np.ndarray]:
    """A frontal 9 x 6 grid (40 px spacing) seen exactly, and 18 false points (25 %) clustered 120 px
    to its right."""
    model, _ = grid_model()
    camera = Camera(2000.0, 2000.0, 320.0, 240.0)
    true_pose = np.array([0.0, 0.0, 5.0, 0.0, 0.0, 0.0])
    uv, usable = camera.project_population(true_pose, model.points)
    assert usable.all()
    rng = np.random.default_rng(30)
    clutter = np.array([600.0, 240.0]) + rng.normal(scale=5.0, size=(18, 2))
    view = View(camera, np.concatenate([uv[0], clutter]))
    return PoseProblem(model, (view,), BOUNDS), true_pose


def test_paper_fitness_prefers_a_wrong_pose_under_clustered_clutter():
    problem, true_pose = clustered_clutter_problem()
    # slide the board sideways: -0.1 .. +0.3 m (= -1 .. +3 columns)
    shifts = np.round(np.arange(-0.1, 0.3001, 0.005), 6)
    poses = np.tile(true_pose, (len(shifts), 1))
    poses[:, 0] += shifts
    paper = PoseObjective(problem, "paper")(poses)
    robust = PoseObjective(problem, "robust")(poses)
    i_true = int(np.nonzero(shifts == 0.0)[0][0])
    i_one = int(np.nonzero(shifts == 0.1)[0][0])
    # eq. (1): the clutter pulls the board towards it by whole columns
    assert paper[i_one] < paper[i_true]
    assert shifts[np.argmin(paper)] >= 0.1
    # the robust fitness still has its minimum at the truth
    assert np.argmin(robust) == i_true
    assert robust[i_true] < robust[i_one]
    assert robust[i_true] < np.delete(robust, i_true).min()
