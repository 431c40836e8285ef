"""The covariance under eq. (1)'s marginal likelihood (issue 35, :mod:`evopose.mixture`): the noise fitted over every
point against every mark, and Louis' observed information, which keeps what the unknown correspondences cost."""

from __future__ import annotations

import dataclasses

import numpy as np

from benchmarks.problems import make_paper_scale_problem, make_problem
from evopose import PoseObjective, solve
from evopose.covariance import covariance, mutual_matches
from evopose.mixture import (false_shares, mixture_covariance, mixture_fit, mixture_information, view_statistics,
                             view_terms)


def test_the_noise_is_not_understated_where_the_nearest_mark_is_often_not_the_points_own():
    """At the paper's scale (marks 3-5 px apart) with 1.8 px noise, at the true pose: the mutual pairs' residuals
    understate the noise (a point pairs with whichever mark it fell nearest), the mixture's sigma does not."""
    noise, pairs, mixture = 1.8, [], []
    for i in range(12):
        sp = make_paper_scale_problem(np.random.default_rng([3, i]), cameras=("H1", "H2"), noise=noise, clutter=0.15)
        objective = PoseObjective(sp.problem)
        matches = mutual_matches(objective, sp.true_pose)
        pairs.append(np.mean(matches.residuals ** 2))
        mixture.append(mixture_fit(objective, sp.true_pose, 1.0, false_shares(matches)).sigma2)
    assert np.sqrt(np.mean(pairs)) < 0.85 * noise
    assert abs(np.sqrt(np.mean(mixture)) / noise - 1) < 0.1, np.sqrt(np.mean(mixture))


def test_marks_far_apart_give_the_gauss_newton_covariance():
    """Marks 20+ px apart at 1 px noise, no false points: each point is its nearest mark's, the responsibilities
    are 0 or 1, and the mixture's covariance is the least-squares one on the pairs (the same noise). Both taken with
    the noise as known: the published one's Student's t factor is the next test's."""
    sp = make_problem("random", np.random.default_rng(41), noise=1.0, clutter=0.0, missing=0.0, size_px=200)
    pose = solve(sp.problem, seed=0).pose
    objective = PoseObjective(sp.problem)
    matches = mutual_matches(objective, pose)
    mixed = mixture_covariance(objective, pose, matches, noise_estimated=False)
    least_squares = covariance(objective, pose, matches)
    assert mixed.ok and least_squares.ok
    ratio = least_squares.residual_variance / mixed.residual_variance
    assert 0.8 < ratio < 1.25  # both estimate the same 1 px noise
    np.testing.assert_allclose(mixed.matrix * ratio, least_squares.matrix, rtol=0.02,
                               atol=0.02 * np.sqrt(np.outer(np.diag(least_squares.matrix),
                                                            np.diag(least_squares.matrix))).max())


def test_the_published_covariance_widens_by_students_t_for_the_noise_it_fitted():
    """With the noise fitted from ``dof`` residual coordinates the pose's error is Student's t: the published
    covariance is the known-noise one times ``dof / (dof - 2)``; with few pairs that is a visible widening."""
    for size_px, missing in ((200, 0.0), (60, 0.5)):   # many pairs, then few
        sp = make_problem("random", np.random.default_rng(41), noise=1.0, clutter=0.0, missing=missing,
                          size_px=size_px)
        pose = solve(sp.problem, seed=0).pose
        objective = PoseObjective(sp.problem)
        matches = mutual_matches(objective, pose)
        published, known = mixture_covariance(objective, pose, matches), mixture_covariance(
            objective, pose, matches, noise_estimated=False)
        assert published.ok and known.ok and published.dof == known.dof > 2
        factor = published.dof / (published.dof - 2)
        np.testing.assert_allclose(published.matrix, known.matrix * factor, rtol=1e-4)   # factors 1.07 and 1.11 here
        assert np.all(np.diag(published.matrix)[3:] > np.diag(known.matrix)[3:])


def test_unknown_correspondences_lose_information():
    """Louis' identity: the observed information is the complete-data one less a covariance of scores, so never
    more than the complete-data information, and less where points lie between marks (the paper's scale)."""
    sp = make_paper_scale_problem(np.random.default_rng([3, 1]), cameras=("H1", "H2"), noise=1.5, clutter=0.1)
    objective = PoseObjective(sp.problem)
    free = objective.problem.bounds.free
    terms = [(k, 1.0, view_terms(objective, sp.true_pose, k, free)) for k in range(objective.n_views)]
    stats = view_statistics(terms, 1.5 ** 2, np.full(objective.n_views, 0.1))
    observed = mixture_information(stats, 1.5 ** 2, int(free.sum()))
    complete = sum(np.einsum("pm,mai,maj->ij", r, t.jacobian, t.jacobian) for _, _, t, r, _, _ in stats) / 1.5 ** 2
    lost = np.linalg.eigvalsh(complete - observed)
    assert lost.min() > -1e-9 * lost.max() and lost.max() > 0.05 * np.linalg.eigvalsh(complete).max()


def test_the_solver_publishes_the_mixture_covariance():
    """:func:`evopose.solver.published`: the covariance out of a solve is the mixture's at the published pose."""
    sp = make_paper_scale_problem(np.random.default_rng([11, 1]), cameras=("H1", "H2"), noise=0.7, clutter=0.2)
    solution = solve(sp.problem, seed=0)
    objective = PoseObjective(sp.problem)
    expected = mixture_covariance(objective, solution.pose, mutual_matches(objective, solution.pose))
    np.testing.assert_allclose(solution.covariance, expected.matrix, rtol=1e-9, atol=0)


def test_information_that_is_not_finite_gives_no_covariance_instead_of_an_error(monkeypatch):
    """An agent on an unlabelled paper-scale frame once died in ``eigh`` (``LinAlgError: Eigenvalues did not
    converge``): a fit whose information is not finite now gives no covariance (infinite: not precise, not good)."""
    import evopose.mixture as mixture

    sp = make_problem("random", np.random.default_rng(41), noise=1.0, clutter=0.0, missing=0.0, size_px=200)
    objective = PoseObjective(sp.problem)
    fitted = mixture.mixture_fit
    monkeypatch.setattr(mixture, "mixture_fit", lambda *args: dataclasses.replace(
        fitted(*args), information=np.full((6, 6), np.nan)))
    estimate = mixture_covariance(objective, sp.true_pose, mutual_matches(objective, sp.true_pose))
    assert not estimate.ok and np.isinf(estimate.matrix).all()
