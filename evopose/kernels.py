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


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def accumulate_normal_equations(uv, J, usable, px, py, gate2, w_view, H, g):  # pragma: no cover - compiled
    """Add one view's Gauss–Newton normal equations for nearest-neighbour pairs, in place.

    Pairs are (image point -> nearest usable model point) and (usable model point ->
    nearest image point), each kept when closer than ``sqrt(gate2)`` pixels. The two
    directions are weighted ``w_view / 2`` divided by their point counts, as in the
    robust fitness.

    Parameters
    ----------
    uv : float64 (N, M, 2)
        Projected model points.
    J : float64 (N, M, 2, 6)
        d uv / d s.
    usable : bool (N, M)
    px, py : float64 (P,)
    gate2 : float
        Squared gate (pixels^2).
    w_view : float
    H : float64 (N, 6, 6), g : float64 (N, 6)
        Accumulators: ``H += sum w J^T J``, ``g += sum w J^T r`` with ``r = uv - p``.
    """
    N, M = usable.shape
    P = px.shape[0]
    row_d2 = np.empty(P)
    row_m = np.empty(P, np.int64)
    col_p = np.empty(M, np.int64)
    col_d2 = np.empty(M)
    for n in range(N):
        for p in range(P):
            row_d2[p] = NO_MATCH_D2
            row_m[p] = -1
        n_usable = 0
        for m in range(M):
            col_p[m] = -1
            col_d2[m] = NO_MATCH_D2
            if not usable[n, m]:
                continue
            n_usable += 1
            um = uv[n, m, 0]
            vm = uv[n, m, 1]
            best = NO_MATCH_D2
            best_p = -1
            for p in range(P):
                dx = px[p] - um
                dy = py[p] - vm
                d2 = dx * dx + dy * dy
                if d2 < best:
                    best = d2
                    best_p = p
                if d2 < row_d2[p]:
                    row_d2[p] = d2
                    row_m[p] = m
            col_p[m] = best_p
            col_d2[m] = best
        w_img = 0.5 * w_view / P
        w_mod = 0.5 * w_view / max(n_usable, 1)
        for k in range(P + M):
            if k < P:
                if row_d2[k] >= gate2:
                    continue
                m = row_m[k]
                q = k
                w = w_img
            else:
                m = k - P
                if col_d2[m] >= gate2:
                    continue
                q = col_p[m]
                w = w_mod
            r0 = uv[n, m, 0] - px[q]
            r1 = uv[n, m, 1] - py[q]
            for i in range(6):
                a0 = J[n, m, 0, i] * w
                a1 = J[n, m, 1, i] * w
                g[n, i] += a0 * r0 + a1 * r1
                for j in range(i + 1):
                    H[n, i, j] += a0 * J[n, m, 0, j] + a1 * J[n, m, 1, j]
    for n in range(N):
        for i in range(6):
            for j in range(i):
                H[n, j, i] = H[n, i, j]


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def accumulate_soft_normal_equations(uv, J, usable, px, py, sigma, outlier, w_img, w_mod, H, g):  # pragma: no cover
    """Add one view's normal equations for soft (EM-ICP) matching, in place.

    Every pair gets the Gaussian weight ``exp(-d^2 / 2 sigma^2)``, normalised per image
    point (over model points, plus an ``outlier`` slack) and per model point (over image
    points, plus the slack). Weights are aggregated per model point so the cost per pair
    is a few flops: ``H = sum_j c_j J_j^T J_j``, ``g = sum_j J_j^T (c_j m_j - q_j)`` with
    ``c_j`` the total weight of model point j and ``q_j`` its weighted image target.

    Parameters
    ----------
    uv : (N, M, 2), J : (N, M, 2, 6), usable : (N, M), px, py : (P,)
    sigma : float
        Kernel width in pixels (annealed by the caller).
    outlier : float
        Slack added to each normaliser, in units of the kernel's peak (e.g. exp(-2.5^2/2)).
    w_img, w_mod : float
        Weights of the image->model and model->image directions.
    H : (N, 6, 6), g : (N, 6)
        Accumulators.
    """
    N, M = usable.shape
    P = px.shape[0]
    inv2s2 = 0.5 / (sigma * sigma)
    cut2 = 9.0 * sigma * sigma  # pairs beyond 3 sigma weigh < 1.2 %: skipped
    w_pair = np.empty((M, P))
    row_sum = np.empty(P)
    c = np.empty(M)
    qx = np.empty(M)
    qy = np.empty(M)
    for n in range(N):
        n_usable = 0
        for p in range(P):
            row_sum[p] = outlier
        for m in range(M):
            if not usable[n, m]:
                for p in range(P):
                    w_pair[m, p] = 0.0
                continue
            n_usable += 1
            um = uv[n, m, 0]
            vm = uv[n, m, 1]
            for p in range(P):
                dx = px[p] - um
                dy = py[p] - vm
                d2 = dx * dx + dy * dy
                w = np.exp(-d2 * inv2s2) if d2 < cut2 else 0.0
                w_pair[m, p] = w
                row_sum[p] += w
        a = w_img / P
        b = w_mod / max(n_usable, 1)
        for m in range(M):
            c[m] = 0.0
            qx[m] = 0.0
            qy[m] = 0.0
            if not usable[n, m]:
                continue
            col_sum = outlier
            for p in range(P):
                col_sum += w_pair[m, p]
            inv_col = b / col_sum
            for p in range(P):
                w = w_pair[m, p]
                if w == 0.0:
                    continue
                wt = w * (a / row_sum[p] + inv_col)
                c[m] += wt
                qx[m] += wt * px[p]
                qy[m] += wt * py[p]
        for m in range(M):
            cm = c[m]
            if cm == 0.0:
                continue
            r0 = cm * uv[n, m, 0] - qx[m]
            r1 = cm * uv[n, m, 1] - qy[m]
            for i in range(6):
                j0 = J[n, m, 0, i]
                j1 = J[n, m, 1, i]
                g[n, i] += j0 * r0 + j1 * r1
                a0 = j0 * cm
                a1 = j1 * cm
                for j in range(i + 1):
                    H[n, i, j] += a0 * J[n, m, 0, j] + a1 * J[n, m, 1, j]
    for n in range(N):
        for i in range(6):
            for j in range(i):
                H[n, j, i] = H[n, i, j]
