"""The covariance in the ROS ``PoseWithCovariance`` convention (docs/protocol.md, "Covariance"; issue 20): the
rotation block over small rotations about the fixed X, Y, Z axes, not over Euler-angle increments.

Checked three ways: the Jacobian against finite differences of ``R = Rz Ry Rx``; the transformed covariance
against Monte Carlo samples of perturbed poses (Euler perturbations drawn with the Euler covariance, each
expressed as the fixed-axis rotation vector ``log(R_sample R_mean^T)``); and the solver's covariance against a
Gauss-Newton covariance computed directly in fixed-axis coordinates (the projection perturbed by ``exp(omega) R``),
independent of the Jacobian formula.
"""

from __future__ import annotations

import numpy as np

from benchmarks.problems import make_problem
from evopose import PoseObjective, solve
from evopose.covariance import (covariance, deviation, fixed_axis_covariance, fixed_axis_jacobian,
                                mutual_matches)
from evopose.mixture import mixture_covariance
from geometry import euler_from_rotation, rotation_from_euler
from scipy.spatial.transform import Rotation

#: Yaw 0.6 rad (the issue's example), some pitch and roll: roll / pitch / yaw sigmas of 10 / 30 / 20 mrad are X / Y / Z
#: sigmas of 16 / 27 / 19 mrad.
POSE = np.array([1.0, -2.0, 12.0, 0.2, 0.35, 0.6])


def _euler_covariance() -> np.ndarray:
    """A covariance of ``(x, y, z, roll, pitch, yaw)`` increments with correlated blocks: rotations 10-30 mrad."""
    sigmas = np.array([0.05, 0.08, 0.3, 0.01, 0.03, 0.02])
    rng = np.random.default_rng(7)
    A = rng.standard_normal((6, 6))
    correlation = np.corrcoef(A @ A.T + 6 * np.eye(6))
    return correlation * np.outer(sigmas, sigmas)


def _relative_error(sample: np.ndarray, model: np.ndarray) -> float:
    """Largest entry difference, each over the product of the two sigmas it couples (a correlation error)."""
    scale = np.sqrt(np.outer(np.diag(model), np.diag(model)))
    return float(np.max(np.abs(sample - model) / scale))


def test_the_jacobian_is_the_derivative_of_the_fixed_axis_rotation():
    rng = np.random.default_rng(1)
    for rpy in rng.uniform([-3, -1.4, -3], [3, 1.4, 3], (20, 3)):
        J = fixed_axis_jacobian(rpy)
        for i in range(3):
            h = np.zeros(3)
            h[i] = 1e-6
            omega = Rotation.from_matrix(rotation_from_euler(rpy + h) @ rotation_from_euler(rpy).T).as_rotvec()
            np.testing.assert_allclose(omega / 1e-6, J[:, i], atol=1e-5)


def test_the_fixed_axis_covariance_matches_monte_carlo_samples_of_perturbed_poses():
    """200 000 poses perturbed by Euler increments drawn from the Euler covariance: the sample covariance of
    their (position, ``log(R_sample R_mean^T)``) is the transformed covariance to 1 % of the sigmas; the Euler
    covariance read as fixed-axis (what the issue found) is off by far more."""
    euler = _euler_covariance()
    rng = np.random.default_rng(2)
    samples = POSE + rng.multivariate_normal(np.zeros(6), euler, 200_000)
    d = deviation(samples, POSE)
    observed = d.T @ d / len(d)
    ros = fixed_axis_covariance(euler, POSE)
    assert _relative_error(observed, ros) < 0.01
    assert _relative_error(observed, euler) > 0.2
    sigmas_ratio = np.sqrt(np.diag(ros)[3:5] / np.diag(euler)[3:5])
    assert np.max(np.abs(sigmas_ratio - 1)) > 0.1  # the X / Y rotation sigmas the issue saw off by 10-20 % and more


def test_deviation_is_position_difference_and_fixed_axis_rotation_vector():
    a = POSE + np.array([0.1, -0.2, 0.3, 0.0, 0.0, 0.0])
    omega = np.array([0.02, -0.01, 0.03])
    b_R = Rotation.from_rotvec(omega).as_matrix() @ rotation_from_euler(POSE[3:])
    b = np.concatenate([POSE[:3], euler_from_rotation(b_R)])
    np.testing.assert_allclose(deviation(b, POSE), np.concatenate([np.zeros(3), omega]), atol=1e-12)
    np.testing.assert_allclose(deviation(a, POSE)[:3], [0.1, -0.2, 0.3], atol=1e-12)
    # the same rotation by another Euler triple (pitch past pi/2) is no rotation at all
    r, p, y = POSE[3:]
    twin = np.array([*POSE[:3], r + np.pi, np.pi - p, y + np.pi])
    np.testing.assert_allclose(deviation(twin, POSE), 0, atol=1e-12)


def test_the_solvers_covariance_is_gauss_newton_in_fixed_axis_coordinates():
    """On a seeded problem: the covariance over the pairs equals ``s^2 (J^T W J + P)^-1`` with ``J`` the
    projection's derivative w.r.t. the position and a small rotation ``exp([omega]x) R`` about the fixed axes
    (central differences), and ``P`` the box prior of the position; the Euler one does not."""
    sp = make_problem("random", np.random.default_rng(41), noise=1.0, clutter=0.0, missing=0.0, size_px=200)
    solution = solve(sp.problem, seed=0)
    objective = PoseObjective(sp.problem)
    pose = np.asarray(solution.pose, float)
    estimate = covariance(objective, pose)
    assert estimate.ok
    published = mixture_covariance(objective, pose, mutual_matches(objective, pose))  # what the solver publishes
    np.testing.assert_allclose(solution.covariance, published.matrix, rtol=1e-9, atol=0)
    np.testing.assert_allclose(published.matrix, fixed_axis_covariance(published.euler, pose), rtol=1e-12, atol=0)
    np.testing.assert_allclose(estimate.matrix, fixed_axis_covariance(estimate.euler, pose), rtol=1e-12, atol=0)

    matches = mutual_matches(objective, pose)
    steps = np.array([1e-4, 1e-4, 1e-4, 1e-5, 1e-5, 1e-5])
    probes = []
    for sign in (1, -1):
        for i in range(6):
            step = np.zeros(6)
            step[i] = sign * steps[i]
            R = Rotation.from_rotvec(step[3:]).as_matrix() @ rotation_from_euler(pose[3:])
            probes.append(np.concatenate([pose[:3] + step[:3], euler_from_rotation(R)]))
    probes = np.array(probes)
    J = np.zeros((len(matches.view), 2, 6))
    for k in np.unique(matches.view):
        rows = np.nonzero(matches.view == k)[0]
        proj = objective.project(int(k), probes)
        m = matches.model_index[rows]
        J[rows, 0] = ((proj.u[:6, m] - proj.u[6:, m]) / (2 * steps[:, None])).T
        J[rows, 1] = ((proj.v[:6, m] - proj.v[6:, m]) / (2 * steps[:, None])).T
    w = matches.weights[matches.view]
    normal = np.einsum("m,mai,maj->ij", w, J, J)
    bounds = sp.problem.bounds
    prior = np.where(bounds.periodic, 0.0, 12.0 / np.maximum(bounds.width, 1e-300) ** 2)
    assert np.all(bounds.periodic[3:]), "the prior on the angles would need the Jacobian too"
    direct = np.linalg.inv(normal / estimate.residual_variance + np.diag(prior))
    assert _relative_error(estimate.matrix, direct) < 0.01, (estimate.matrix, direct)
    assert _relative_error(estimate.euler, direct) > 0.05
