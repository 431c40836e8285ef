"""evopose.neighbours answers as the k-d tree it replaces did, to the bit, ties included (docs/design.md §2,
"Lazy imports"): the search's results do not depend on which of the two is used."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from evopose.neighbours import k_nearest, nearest_distance, nearest_other


def _point_sets():
    rng = np.random.default_rng(11)
    for trial in range(90):
        n, dim = int(rng.integers(2, 300)), int(rng.integers(2, 4))
        points = rng.uniform(0.0, 50.0, (n, dim))
        if trial % 3 == 0:
            points = np.round(points)  # an integer grid: exact ties and duplicates
        elif trial % 3 == 1:
            points = np.round(points * 4) / 4
        yield points, rng


def test_nearest_other_point_is_the_trees_second_neighbour_ties_and_duplicates_included():
    for points, _ in _point_sets():
        distance, index = cKDTree(points).query(points, k=2)
        np.testing.assert_array_equal(nearest_distance(points, points, exclude_self=True), distance[:, 1])
        np.testing.assert_array_equal(nearest_other(points), index[:, 1])


def test_nearest_point_of_another_set_is_the_trees():
    for points, rng in _point_sets():
        others = rng.uniform(0.0, 50.0, (max(1, len(points) // 2), points.shape[1]))
        np.testing.assert_array_equal(nearest_distance(points, others), cKDTree(others).query(points)[0])


def test_k_nearest_are_the_trees_in_the_trees_order():
    for points, rng in _point_sets():
        queries = points[rng.integers(0, len(points), 10)]
        k = int(rng.integers(1, len(points) + 1))
        np.testing.assert_array_equal(k_nearest(queries, points, k),
                                      cKDTree(points).query(queries, k=k)[1].reshape(len(queries), k))


def test_a_grid_of_exact_ties_gets_the_trees_neighbours():
    grid = np.zeros((54, 3))
    grid[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2) * 0.5  # a chessboard's inner corners, exact in binary
    np.testing.assert_array_equal(nearest_other(grid), cKDTree(grid).query(grid, k=2)[1][:, 1])


def test_no_candidate_and_bad_shapes():
    assert np.all(np.isinf(nearest_distance(np.zeros((3, 2)), np.zeros((0, 2)))))
    with pytest.raises(ValueError):
        nearest_distance(np.zeros((3, 2)), np.zeros((4, 3)))
    with pytest.raises(ValueError):
        k_nearest(np.zeros((1, 2)), np.zeros((2, 2)), 3)
    with pytest.raises(ValueError):
        nearest_other(np.zeros((1, 2)))
