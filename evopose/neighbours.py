"""Nearest neighbours of small point sets: each query's nearest point, and a few queries' k nearest.

What ``scipy.spatial.cKDTree`` gave the search (the truncation distance's spacing, the starts' local clusters, a
grid's repeated steps, whether two poses show the same image), written here so that an agent does not import
``scipy.spatial``: that package, with the ``scipy.sparse`` and ``scipy.special`` it imports, held about 10 MB of a
camera agent's resident memory (``scipy.linalg``, which it imports too, numba loads anyway; docs/design.md §2,
"Lazy imports").

Distances are the k-d tree's, to the bit: ``sqrt`` of the sum of squared coordinate differences, taken in
coordinate order. Where the answer is an index, equally near points leave a choice that the tree made by its
traversal order; to keep those answers as they were, a query with such a tie is answered by the tree itself
(imported then, and only then: a chessboard's exact grid has ties, the shipped target models and noisy image
points have none). :func:`nearest_distance` sorts the points along their first coordinate and scans outwards from
each query until that coordinate alone is farther than the best so far (:func:`evopose.kernels.nearest_sorted`,
compiled): exact, and about ``O(P log P)`` for points spread over an image (``O(P^2)`` only when they all share one
first coordinate).
"""

from __future__ import annotations

import numpy as np

from .kernel_backend import nearest_sorted

#: Most query-by-point squared distances :func:`k_nearest` holds at once (floats: 32 MB).
CHUNK_ENTRIES = 1 << 22


def _as_sets(queries: np.ndarray, points: np.ndarray, exclude_self: bool) -> tuple[np.ndarray, np.ndarray]:
    queries = np.ascontiguousarray(queries, dtype=float)
    points = np.ascontiguousarray(points, dtype=float)
    if queries.ndim != 2 or points.ndim != 2 or queries.shape[1] != points.shape[1]:
        raise ValueError(f"expected (Q, D) queries and (P, D) points, got {queries.shape} and {points.shape}")
    if exclude_self and queries.shape != points.shape:
        raise ValueError("exclude_self needs the points as their own queries")
    return queries, points


def _nearest(queries: np.ndarray, points: np.ndarray, exclude_self: bool):
    if len(points) == 0:
        return np.full(len(queries), np.inf), np.full(len(queries), -1, np.int64), np.zeros(len(queries), bool)
    order = np.argsort(points[:, 0], kind="stable")
    return nearest_sorted(queries, points, order, exclude_self)


def _tree_neighbours(queries: np.ndarray, points: np.ndarray, k: int) -> np.ndarray:
    """The k-d tree's ``k`` nearest indices per query, (Q, k): only for queries with exact ties (module doc)."""
    from scipy.spatial import cKDTree  # lazy: a tie is rare, and the package is heavy (docs/design.md)

    return np.asarray(cKDTree(points).query(queries, k=k)[1]).reshape(len(queries), k)


def nearest_distance(queries: np.ndarray, points: np.ndarray, exclude_self: bool = False) -> np.ndarray:
    """Distance from each query to its nearest point: ``queries`` (Q, D), ``points`` (P, D) -> (Q,), ``inf``
    with no candidate. ``exclude_self``: ``queries`` is ``points`` and each point's nearest *other* point is
    wanted (the k-d tree's second neighbour of a point queried against its own set)."""
    queries, points = _as_sets(queries, points, exclude_self)
    return np.sqrt(_nearest(queries, points, exclude_self)[0])


def nearest_other(points: np.ndarray) -> np.ndarray:
    """Index of each point's nearest other point, (P, D) -> (P,), as the k-d tree's ``query(points, k=2)``
    gave it (its second column); ``P >= 2``."""
    points, _ = _as_sets(points, points, True)
    if len(points) < 2:
        raise ValueError(f"a nearest other point needs at least 2 points, got {len(points)}")
    d2, index, tied = _nearest(points, points, True)
    tied = tied | (d2 == 0.0)  # a duplicate is as near as the point itself, which the tree may have named
    if tied.any():
        index = index.copy()
        index[tied] = _tree_neighbours(points[tied], points, 2)[:, 1]
    return index


def k_nearest(queries: np.ndarray, points: np.ndarray, k: int) -> np.ndarray:
    """Indices of each query's ``k`` nearest points, nearest first, as the k-d tree's ``query(queries, k=k)``
    gave them: ``queries`` (Q, D), ``points`` (P, D) with ``k <= P`` -> (Q, k). Brute force in chunks of
    queries: meant for a few queries (the starts' seeds), not for all points against all."""
    queries, points = _as_sets(queries, points, False)
    if not 0 < k <= len(points):
        raise ValueError(f"k must be within 1..{len(points)}, got {k}")
    out = np.empty((len(queries), k), np.int64)
    tied = np.zeros(len(queries), bool)
    keep = min(k + 1, len(points))  # a tie between the k-th and the next one changes which k
    rows = max(1, CHUNK_ENTRIES // len(points))
    for s in range(0, len(queries), rows):
        diff = queries[s:s + rows, None, :] - points[None, :, :]
        d2 = np.sum(diff * diff, axis=-1)
        part = np.argpartition(d2, keep - 1, axis=1)[:, :keep] if keep < len(points) else \
            np.broadcast_to(np.arange(len(points)), d2.shape)
        near = np.take_along_axis(d2, part, axis=1)
        order = np.argsort(near, axis=1, kind="stable")
        near = np.take_along_axis(near, order, axis=1)
        out[s:s + rows] = np.take_along_axis(part, order, axis=1)[:, :k]
        tied[s:s + rows] = np.any(near[:, 1:] == near[:, :-1], axis=1)
    if tied.any():
        out[tied] = _tree_neighbours(queries[tied], points, k)
    return out


__all__ = ["k_nearest", "nearest_distance", "nearest_other"]
