"""Compiled inner loops: nearest-neighbour distances between projected model points and image points.

One pass over the ``N x M x P`` point pairs yields both matching directions of the
chamfer distance: for every image point its nearest projected model point (the
``min_j |p_i - m_j(s)|`` of eq. 1) and for every model point its nearest image point.
Squared distances are used inside the loop; a large finite sentinel stands for
"no candidate" so that ``fastmath`` stays valid.
"""

from __future__ import annotations

import numba as nb
import numpy as np

#: Squared distance reported when no candidate exists (no usable model point, or unusable model point).
NO_MATCH_D2 = 1e30
_FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def chamfer_sums(u, v, usable, px, py, tau, robust):  # pragma: no cover - compiled
    """Per-individual sums of both matching directions.

    Parameters
    ----------
    u, v : float64 arrays, shape (N, M)
        Projected model points (pixels).
    usable : bool array, shape (N, M)
        Model points in front of the camera and facing it.
    px, py : float64 arrays, shape (P,)
        Image points.
    tau : float
        Truncation of the per-point distance (pixels) when ``robust``.
    robust : bool
        True: bounded ``min(d, tau)``; False: the paper's plain eq. (1) sum.

    Returns
    -------
    img_sum : (N,) sum over image points of (truncated) nearest-model distance.
    mod_sum : (N,) sum over usable model points of truncated nearest-image distance.
    n_usable : (N,) number of usable model points.
    """
    N, M = u.shape
    P = px.shape[0]
    img_sum = np.zeros(N)
    mod_sum = np.zeros(N)
    n_usable = np.zeros(N)
    row = np.empty(P)
    tau2 = tau * tau
    for n in range(N):
        for p in range(P):
            row[p] = NO_MATCH_D2
        s_mod = 0.0
        cnt = 0
        for m in range(M):
            if not usable[n, m]:
                continue
            um = u[n, m]
            vm = v[n, m]
            best = NO_MATCH_D2
            for p in range(P):
                dx = px[p] - um
                dy = py[p] - vm
                d2 = dx * dx + dy * dy
                best = min(best, d2)
                row[p] = min(row[p], d2)
            cnt += 1
            s_mod += np.sqrt(min(best, tau2))
        s_img = 0.0
        if robust:
            for p in range(P):
                s_img += np.sqrt(min(row[p], tau2))
        else:
            for p in range(P):
                s_img += np.sqrt(row[p])
        img_sum[n] = s_img
        mod_sum[n] = s_mod
        n_usable[n] = cnt
    return img_sum, mod_sum, n_usable


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def chamfer_matches(u, v, usable, px, py):  # pragma: no cover - compiled
    """Nearest neighbours in both directions, with indices (for local refinement).

    Returns
    -------
    img_nn : int64 (N, P), index of the nearest usable model point to each image point (-1 if none).
    img_d2 : float64 (N, P), its squared distance.
    mod_nn : int64 (N, M), index of the nearest image point to each usable model point (-1 if unusable).
    mod_d2 : float64 (N, M), its squared distance (NO_MATCH_D2 if unusable).
    """
    N, M = u.shape
    P = px.shape[0]
    img_nn = np.full((N, P), -1, np.int64)
    img_d2 = np.full((N, P), NO_MATCH_D2)
    mod_nn = np.full((N, M), -1, np.int64)
    mod_d2 = np.full((N, M), NO_MATCH_D2)
    for n in range(N):
        for m in range(M):
            if not usable[n, m]:
                continue
            um = u[n, m]
            vm = v[n, m]
            best = NO_MATCH_D2
            best_p = -1
            for p in range(P):
                dx = px[p] - um
                dy = py[p] - vm
                d2 = dx * dx + dy * dy
                if d2 < best:
                    best = d2
                    best_p = p
                if d2 < img_d2[n, p]:
                    img_d2[n, p] = d2
                    img_nn[n, p] = m
            mod_nn[n, m] = best_p
            mod_d2[n, m] = best
    return img_nn, img_d2, mod_nn, mod_d2

