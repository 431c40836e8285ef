"""Compiled inner loops: nearest-neighbour distances between projected model points and image points.

The one place where eq. (1)'s distance is written: :func:`chamfer_row` makes one pass over the
``M x P`` pairs of one pose in one view and yields both matching directions of the chamfer
distance, for every image point its nearest projected model point (``min_j |p_i - m_j(s)|``, eq. 1)
and for every model point its nearest image point. :func:`view_term_row` turns those sums into the
view's term ``d^(k)`` (the paper's eq. 1, or its bounded two-sided variant). The fitness of whole
populations (:func:`view_terms`) and the refinement's own fitness (:mod:`evopose.refine_kernel`)
both call them, so the two cannot drift apart. :func:`nearest_row` is the one nearest-neighbour
matching with indices (the refinement's hard steps, the unmatched-marks count); :func:`nearest_sorted` the
nearest neighbours of small point sets (:mod:`evopose.neighbours`). Python calls these kernels through
:mod:`evopose.kernel_backend`, which runs them compiled ahead of time or through numba's JIT (docs/design.md §2,
"Compiled kernels").

Squared distances are used inside the loops; a large finite sentinel stands for "no candidate" so
that ``fastmath`` stays valid. Every distance is taken in (u, v, label) space: ``pz`` (P,) and ``mz`` (M,) are
the image points' and the marks' label coordinates (:func:`evopose.problem.label_coordinates`; zeros for untyped
points, the paper's case), so points of different classes are never within a truncation distance.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .kernel_abi import FASTMATH as _FASTMATH
from .kernel_abi import MUTUAL, NO_MATCH_D2, PAPER, ROBUST

__all__ = ["MUTUAL", "NO_MATCH_D2", "PAPER", "ROBUST", "chamfer_matches", "chamfer_row", "chamfer_sums", "is_typed",
           "mutual_row", "nearest_row", "nearest_sorted", "view_term_row", "view_terms"]


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True, inline="always")
def _nearest(um, vm, px, py, row):  # pragma: no cover - compiled
    """The squared distance from the model point ``(um, vm)`` to its nearest image point ``(px, py)``; ``row``
    (>= P,) keeps, per image point, its nearest squared distance to the model points seen so far (one pass
    serves both matching directions of eq. 1). Untyped points: the paper's eq. (1)."""
    best = NO_MATCH_D2
    for p in range(px.shape[0]):
        dx = px[p] - um
        dy = py[p] - vm
        d2 = dx * dx + dy * dy
        best = min(best, d2)
        row[p] = min(row[p], d2)
    return best


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True, inline="always")
def _nearest_typed(um, vm, zm, px, py, pz, row):  # pragma: no cover - compiled
    """:func:`_nearest` in (u, v, label) space, for typed points (a separate loop: the label axis would slow
    the untyped one by a half)."""
    best = NO_MATCH_D2
    for p in range(px.shape[0]):
        dx = px[p] - um
        dy = py[p] - vm
        dz = pz[p] - zm
        d2 = dx * dx + dy * dy + dz * dz
        best = min(best, d2)
        row[p] = min(row[p], d2)
    return best


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def is_typed(mz, pz):  # pragma: no cover - compiled
    """Whether any label coordinate is non-zero; else the points are untyped (the paper's eq. 1). Computed once
    per view and population, not per pose."""
    for m in range(mz.shape[0]):
        if mz[m] != 0.0:
            return True
    for p in range(pz.shape[0]):
        if pz[p] != 0.0:
            return True
    return False


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def chamfer_row(u, v, mz, usable, px, py, pz, typed, tau, robust, row):  # pragma: no cover - compiled
    """Both matching directions of one pose in one view.

    Parameters
    ----------
    u, v : float64 arrays, shape (M,)
        Projected model points (pixels).
    mz : float64 array, shape (M,)
        The model points' label coordinates.
    usable : bool array, shape (M,)
    px, py, pz : float64 arrays, shape (P,)
        Image points and their label coordinates.
    typed : bool
        :func:`is_typed` of ``mz``, ``pz`` (False: the label coordinates are ignored).
    tau : float
        Truncation of the per-point distance (pixels) when ``robust``.
    robust : bool
    row : float64 array, shape (>= P,)
        Scratch.

    Returns
    -------
    img_sum : sum over image points of the (truncated, if robust) distance to the nearest usable model point.
    mod_sum : sum over usable model points of the truncated distance to the nearest image point.
    n_usable : number of usable model points.
    """
    P = px.shape[0]
    tau2 = tau * tau
    for p in range(P):
        row[p] = NO_MATCH_D2
    s_mod = 0.0
    cnt = 0
    for m in range(u.shape[0]):
        if not usable[m]:
            continue
        best = _nearest_typed(u[m], v[m], mz[m], px, py, pz, row) if typed else _nearest(u[m], v[m], px, py, row)
        cnt += 1
        s_mod += np.sqrt(min(best, tau2))
    s_img = 0.0
    if robust:
        for p in range(P):
            s_img += np.sqrt(min(row[p], tau2))
    else:
        for p in range(P):
            s_img += np.sqrt(row[p])
    return s_img, s_mod, cnt


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def mutual_row(u, v, mz, usable, px, py, pz, typed, tau, row, col):  # pragma: no cover - compiled
    """One-to-one matching of one pose in one view: mutual nearest neighbours closer than ``tau``.

    ``row`` (>= P,) and ``col`` (M,) are scratch: one branch-free pass gives every image point's and every
    usable model point's nearest squared distance; then each model point closer than ``tau`` to an image point
    finds that point and is its mutual partner when it is also the point's nearest.

    Returns
    -------
    sq_sum : float
        ``sum_i e_i^2 + sum_j e_j^2`` over the image points and the usable model points, ``e`` the distance
        to the mutual partner when there is one within ``tau``, else ``tau`` (pixels squared).
    n_usable : int
    n_pairs : int
        Mutual pairs within ``tau``.
    """
    P = px.shape[0]
    for p in range(P):
        row[p] = NO_MATCH_D2
    for m in range(u.shape[0]):
        col[m] = NO_MATCH_D2
        if not usable[m]:
            continue
        col[m] = _nearest_typed(u[m], v[m], mz[m], px, py, pz, row) if typed else _nearest(u[m], v[m], px, py, row)
    tau2 = tau * tau
    s = 0.0
    n_usable = 0
    n_pairs = 0
    for m in range(u.shape[0]):
        if not usable[m]:
            continue
        n_usable += 1
        best = col[m]
        if best >= tau2:
            continue
        um = u[m]
        vm = v[m]
        zm = mz[m]
        for p in range(P):  # the nearest image point (recomputed: equal up to rounding, first one wins)
            dx = px[p] - um
            dy = py[p] - vm
            dz = pz[p] - zm if typed else 0.0
            if dx * dx + dy * dy + dz * dz <= best * (1.0 + 1e-9):
                if best <= row[p]:  # and this model point is the image point's nearest: a mutual pair
                    s += 2.0 * best
                    n_pairs += 1
                break
    s += tau2 * (P + n_usable - 2 * n_pairs)
    return s, n_usable, n_pairs


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def view_term_row(u, v, mz, usable, px, py, pz, typed, tau, mode, row, col):  # pragma: no cover - compiled
    """The view's term ``d^(k)`` for one pose (pixels); ``row`` (>= P,) and ``col`` (M,) are scratch.

    ``mode`` :data:`PAPER`: the paper's eq. (1) ``sum_i min_j |p_i - m_j(s)|``;
    :data:`ROBUST`: ``(sum_i min(d_i, tau) + sum_j min(d_j, tau)) / (P + n_usable)``, one mean over both
    directions; :data:`MUTUAL`: the root mean square over both directions of the distance to the mutual
    nearest partner, ``tau`` for a point without one within ``tau`` (:func:`mutual_row`).
    """
    if mode == MUTUAL:
        s, n_usable, _ = mutual_row(u, v, mz, usable, px, py, pz, typed, tau, row, col)
        return np.sqrt(s / (px.shape[0] + n_usable))
    s_img, s_mod, cnt = chamfer_row(u, v, mz, usable, px, py, pz, typed, tau, mode == ROBUST, row)
    if mode == ROBUST:
        return (s_img + s_mod) / (px.shape[0] + cnt)
    return s_img


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def view_terms(u, v, mz, usable, px, py, pz, tau, mode):  # pragma: no cover - compiled
    """:func:`view_term_row` for every pose: ``u``, ``v``, ``usable`` (N, M), ``mz`` (M,) -> (N,)."""
    N, M = u.shape
    out = np.empty(N)
    row = np.empty(px.shape[0])
    col = np.empty(M)
    typed = is_typed(mz, pz)
    for n in range(N):
        out[n] = view_term_row(u[n], v[n], mz, usable[n], px, py, pz, typed, tau, mode, row, col)
    return out


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def chamfer_sums(u, v, mz, usable, px, py, pz, tau, robust):  # pragma: no cover - compiled
    """:func:`chamfer_row` for every pose: ``u``, ``v``, ``usable`` (N, M) -> img_sum, mod_sum, n_usable (N,)."""
    N = u.shape[0]
    img_sum = np.zeros(N)
    mod_sum = np.zeros(N)
    n_usable = np.zeros(N)
    row = np.empty(px.shape[0])
    typed = is_typed(mz, pz)
    for n in range(N):
        s_img, s_mod, cnt = chamfer_row(u[n], v[n], mz, usable[n], px, py, pz, typed, tau, robust, row)
        img_sum[n] = s_img
        mod_sum[n] = s_mod
        n_usable[n] = cnt
    return img_sum, mod_sum, n_usable


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def nearest_row(u, v, mz, usable, px, py, pz, typed, img_nn, img_d2, mod_nn, mod_d2):  # pragma: no cover - compiled
    """Nearest neighbours in both directions for one pose in one view, with indices.

    Fills ``img_nn`` / ``img_d2`` (P,): the nearest usable model point to each image point (-1 and
    ``NO_MATCH_D2`` if none) and ``mod_nn`` / ``mod_d2`` (M,): the nearest image point to each usable
    model point (-1 and ``NO_MATCH_D2`` if unusable). Ties go to the lowest index.
    """
    for p in range(px.shape[0]):
        img_nn[p] = -1
        img_d2[p] = NO_MATCH_D2
    for m in range(u.shape[0]):
        mod_nn[m] = -1
        mod_d2[m] = NO_MATCH_D2
        if not usable[m]:
            continue
        um = u[m]
        vm = v[m]
        zm = mz[m]
        best = NO_MATCH_D2
        best_p = -1
        for p in range(px.shape[0]):
            dx = px[p] - um
            dy = py[p] - vm
            dz = pz[p] - zm if typed else 0.0
            d2 = dx * dx + dy * dy + dz * dz
            if d2 < best:
                best = d2
                best_p = p
            if d2 < img_d2[p]:
                img_d2[p] = d2
                img_nn[p] = m
        mod_nn[m] = best_p
        mod_d2[m] = best


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def chamfer_matches(u, v, mz, usable, px, py, pz):  # pragma: no cover - compiled
    """:func:`nearest_row` for every pose (N, M).

    Returns
    -------
    img_nn : int64 (N, P), index of the nearest usable model point to each image point (-1 if none).
    img_d2 : float64 (N, P), its squared distance.
    mod_nn : int64 (N, M), index of the nearest image point to each usable model point (-1 if unusable).
    mod_d2 : float64 (N, M), its squared distance (NO_MATCH_D2 if unusable).
    """
    N, M = u.shape
    P = px.shape[0]
    img_nn = np.empty((N, P), np.int64)
    img_d2 = np.empty((N, P))
    mod_nn = np.empty((N, M), np.int64)
    mod_d2 = np.empty((N, M))
    typed = is_typed(mz, pz)
    for n in range(N):
        nearest_row(u[n], v[n], mz, usable[n], px, py, pz, typed, img_nn[n], img_d2[n], mod_nn[n], mod_d2[n])
    return img_nn, img_d2, mod_nn, mod_d2


@nb.njit(cache=True, nogil=True)
def nearest_sorted(queries, points, order, exclude_self):  # pragma: no cover - compiled
    """Nearest neighbours of small point sets (:mod:`evopose.neighbours`), per query: the squared distance to its nearest point, that point's index, and whether another point is
    exactly as near. ``order`` sorts ``points`` by their first coordinate. ``exclude_self``: the queries are the
    points themselves, and a query is not its own neighbour."""
    n_q, dim = queries.shape
    n_p = points.shape[0]
    xs = np.empty(n_p)
    for j in range(n_p):
        xs[j] = points[order[j], 0]
    best_d2 = np.full(n_q, np.inf)
    best_i = np.full(n_q, -1, np.int64)
    tied = np.zeros(n_q, np.bool_)
    for q in range(n_q):
        x = queries[q, 0]
        start = np.searchsorted(xs, x)
        for direction in (-1, 1):
            j = start - 1 if direction < 0 else start
            while 0 <= j < n_p:
                dx = xs[j] - x
                if dx * dx > best_d2[q]:
                    break
                i = order[j]
                if not (exclude_self and i == q):
                    d2 = 0.0
                    for k in range(dim):
                        diff = points[i, k] - queries[q, k]
                        d2 += diff * diff
                    if d2 < best_d2[q]:
                        best_d2[q] = d2
                        best_i[q] = i
                        tied[q] = False
                    elif d2 == best_d2[q]:
                        tied[q] = True
                        best_i[q] = min(best_i[q], i)
                j += direction
    return best_d2, best_i, tied
