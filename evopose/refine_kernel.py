"""Compiled local refinement: the whole annealing schedule of every individual in one call.

Per individual and step: project the model into every weighted view (pinhole +
plumb_bob, its analytic Jacobian), accumulate Gauss–Newton normal equations from
soft (EM-ICP) or hard (nearest-neighbour) matches, take a damped step, hold fixed
parameters, and bring the pose back into the search box. Hard steps are accepted only
when the fitness drops. The projection (:mod:`evopose.projection`), the view terms and the
nearest-neighbour matching (:mod:`evopose.kernels`) are the very functions the fitness uses.

Array conventions (V views, M model points, P_total image points):
``intr`` (V, 9) = fx, fy, cx, cy, k1, k2, p1, p2, k3; ``cam_from_world`` (V, 4, 4);
``pts`` (P_total, 2) with view k's points at ``offsets[k]:offsets[k+1]``; ``pz`` (P_total,) their label
coordinates and ``mz`` (V, M) the marks' in each view (:func:`evopose.problem.label_coordinates`).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .kernel_abi import FASTMATH as _FASTMATH
from .kernel_abi import MUTUAL
from .kernels import is_typed, nearest_row, view_term_row
from .projection import pose_jacobian, project_pose

_TWO_PI = 2.0 * np.pi


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def _soft_accumulate(u, v, mz, J, usable, px, py, pz, sigma, outlier, w_img, w_mod, H, g, w_pair,
                     row_sum):  # pragma: no cover
    """EM-ICP normal equations of one pose in one view (weights aggregated per model point)."""
    M = u.shape[0]
    P = px.shape[0]
    inv2s2 = 0.5 / (sigma * sigma)
    cut2 = 9.0 * sigma * sigma
    n_usable = 0
    for p in range(P):
        row_sum[p] = outlier
    for m in range(M):
        if not usable[m]:
            continue
        n_usable += 1
        um = u[m]
        vm = v[m]
        zm = mz[m]
        for p in range(P):
            dx = px[p] - um
            dy = py[p] - vm
            dz = pz[p] - zm
            d2 = dx * dx + dy * dy + dz * dz
            w = np.exp(-d2 * inv2s2) if d2 < cut2 else 0.0
            w_pair[m, p] = w
            row_sum[p] += w
    a = w_img / (P + n_usable)
    b = w_mod / (P + n_usable)
    for m in range(M):
        if not usable[m]:
            continue
        col_sum = outlier
        for p in range(P):
            col_sum += w_pair[m, p]
        inv_col = b / col_sum
        c = 0.0
        qx = 0.0
        qy = 0.0
        for p in range(P):
            w = w_pair[m, p]
            if w == 0.0:
                continue
            wt = w * (a / row_sum[p] + inv_col)
            c += wt
            qx += wt * px[p]
            qy += wt * py[p]
        if c == 0.0:
            continue
        r0 = c * u[m] - qx
        r1 = c * v[m] - qy
        for i in range(6):
            j0 = J[m, 0, i]
            j1 = J[m, 1, i]
            g[i] += j0 * r0 + j1 * r1
            for j in range(i + 1):
                H[i, j] += c * (j0 * J[m, 0, j] + j1 * J[m, 1, j])


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def _hard_accumulate(u, v, mz, J, usable, px, py, pz, typed, gate2, w_img, w_mod, H, g, img_nn, img_d2, mod_nn,
                     mod_d2, mutual):  # pragma: no cover - compiled
    """Nearest-neighbour normal equations of one pose in one view, both directions within a gate.

    With ``mutual`` only mutual nearest pairs count (the pairs of the mutual fitness, :func:`mutual_row`).
    """
    P = px.shape[0]
    nearest_row(u, v, mz, usable, px, py, pz, typed, img_nn, img_d2, mod_nn, mod_d2)
    n_usable = 0
    for m in range(u.shape[0]):
        if usable[m]:
            n_usable += 1
    a = w_img / (P + n_usable)
    b = w_mod / (P + n_usable)
    for m in range(u.shape[0]):
        if usable[m] and mod_d2[m] < gate2 and (not mutual or img_nn[mod_nn[m]] == m):
            _add_pair(u, v, J, m, px[mod_nn[m]], py[mod_nn[m]], b, H, g)
    for p in range(P):
        if img_d2[p] < gate2 and (not mutual or mod_nn[img_nn[p]] == p):
            _add_pair(u, v, J, img_nn[p], px[p], py[p], a, H, g)


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True, inline="always")
def _add_pair(u, v, J, m, qx, qy, w, H, g):  # pragma: no cover - compiled
    r0 = u[m] - qx
    r1 = v[m] - qy
    for i in range(6):
        j0 = J[m, 0, i] * w
        j1 = J[m, 1, i] * w
        g[i] += j0 * r0 + j1 * r1
        for j in range(i + 1):
            H[i, j] += j0 * J[m, 0, j] + j1 * J[m, 1, j]


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def to_bounds(s, lo, hi, periodic):  # pragma: no cover - compiled
    """As :meth:`evopose.problem.Bounds.project` for one pose."""
    for d in range(6):
        if d >= 3:  # angles: the turn nearest the middle of the box
            s[d] += _TWO_PI * np.round((0.5 * (lo[d] + hi[d]) - s[d]) / _TWO_PI)
        if periodic[d]:
            s[d] = lo[d] + (s[d] - lo[d]) % _TWO_PI
        else:
            s[d] = min(max(s[d], lo[d]), hi[d])


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def fitness_one(s, model, normals, use_normals, intr, cfw, weights, taus, pts, pz, mz, typed, offsets, mode,
                u, v, usable, row, col, R, Rc):  # pragma: no cover - compiled
    """Eq. (4) for one pose: ``sum_k W_k d^(k)``, with the fitness's own view term (``mode``: :mod:`evopose.kernels`)."""
    total = 0.0
    for k in range(intr.shape[0]):
        if weights[k] == 0.0:
            continue
        project_pose(s, model, normals, use_normals, intr[k], cfw[k], u, v, usable, R, Rc)
        a, b = offsets[k], offsets[k + 1]
        total += weights[k] * view_term_row(u, v, mz[k], usable, pts[a:b, 0], pts[a:b, 1], pz[a:b],
                                            typed[k], taus[k], mode, row, col)
    return total


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def solve_in_place(A, rhs):  # pragma: no cover - compiled
    """x with A x = rhs for a small square A (n, n), by Gaussian elimination with partial pivoting, as LAPACK's
    gesv; A and rhs are overwritten, rhs becomes x. A zero pivot gives 0 for its unknown. Written out, not
    np.linalg.solve: numba's solve loads LAPACK through scipy.linalg at its first call (~130 ms and ~85 modules per
    agent process, for a 6 x 6 system)."""
    n = rhs.shape[0]
    for c in range(n):
        p = c
        for r in range(c + 1, n):
            if abs(A[r, c]) > abs(A[p, c]):
                p = r
        if p != c:
            for j in range(n):
                A[c, j], A[p, j] = A[p, j], A[c, j]
            rhs[c], rhs[p] = rhs[p], rhs[c]
        if A[c, c] == 0.0:
            continue
        for r in range(c + 1, n):
            f = A[r, c] / A[c, c]
            if f != 0.0:
                for j in range(c, n):
                    A[r, j] -= f * A[c, j]
                rhs[r] -= f * rhs[c]
    for c in range(n - 1, -1, -1):
        if A[c, c] == 0.0:
            rhs[c] = 0.0
            continue
        acc = rhs[c]
        for j in range(c + 1, n):
            acc -= A[c, j] * rhs[j]
        rhs[c] = acc / A[c, c]
    return rhs


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def _bounded_step(H, g, s, lo, hi, periodic, step_free, lam, A, clamp):  # pragma: no cover - compiled
    """The damped Gauss–Newton step (6,) that respects the box: a parameter the step would push past its bound
    (eq. 3 makes boxes narrow) is held at that bound and the others are solved given it (an active set),
    so that the position still moves while an angle sits at the edge of its IMU interval."""
    held = np.zeros(6, np.bool_)
    delta = np.zeros(6)
    for _ in range(7):
        for i in range(6):
            clamp[i] = delta[i] if held[i] else 0.0
        for i in range(6):
            active = step_free[i] and not held[i]
            for j in range(6):
                A[i, j] = H[i, j] if (active and step_free[j] and not held[j]) else 0.0
            if active:
                A[i, i] += lam * H[i, i] + 1e-12
        rhs = np.zeros(6)
        for i in range(6):
            if step_free[i] and not held[i]:
                rhs[i] = -g[i]
                for j in range(6):
                    if held[j]:
                        rhs[i] -= H[i, j] * clamp[j]
            else:
                A[i, i] = 1.0
        solved = solve_in_place(A, rhs)
        again = False
        for d in range(6):
            if held[d]:
                solved[d] = clamp[d]
            elif not step_free[d]:
                solved[d] = 0.0
            elif not periodic[d]:
                v = s[d] + solved[d]
                if v < lo[d] or v > hi[d]:
                    held[d] = True
                    solved[d] = (lo[d] if v < lo[d] else hi[d]) - s[d]
                    again = True
        delta = solved
        if not again:
            break
    return delta


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def typed_views(mz, pz, offsets):  # pragma: no cover - compiled
    """Per view, once: whether its points are typed (:func:`evopose.kernels.is_typed`), bool (V,); and the most image
    points of one view (at least 1), the size of the per-view scratch arrays."""
    V = offsets.shape[0] - 1
    P_max = 1
    typed = np.empty(V, np.bool_)
    for k in range(V):
        P_max = max(P_max, offsets[k + 1] - offsets[k])
        typed[k] = is_typed(mz[k], pz[offsets[k]:offsets[k + 1]])
    return typed, P_max


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def refine_population(poses, fitness, lo, hi, periodic, free, model, normals, use_normals, intr, cfw,
                      weights, taus, sigmas, pts, pz, mz, offsets, mode, kinds, scales, outlier,
                      damping):  # pragma: no cover - compiled
    """Refine every pose (N, 6) in place along the schedule; fitness (N,) is updated.

    Parameters
    ----------
    sigmas : (S, V) soft kernel width per step and view (pixels; ignored for hard steps)
    kinds : (S,) int, 0 = soft step, 1 = hard step, 2 = soft step on the position only
    scales : (S,) gate of hard steps in units of tau
    mode : int, the view term (:data:`evopose.kernels.PAPER`, ``ROBUST`` or ``MUTUAL``)
    """
    N = poses.shape[0]
    M = model.shape[0]
    V = intr.shape[0]
    typed, P_max = typed_views(mz, pz, offsets)
    u = np.empty(M)
    v = np.empty(M)
    usable = np.empty(M, np.bool_)
    J = np.empty((M, 2, 6))
    w_pair = np.empty((M, P_max))
    row = np.empty(P_max)
    img_nn = np.empty(P_max, np.int64)
    mod_nn = np.empty(M, np.int64)
    mod_d2 = np.empty(M)
    R = np.empty((3, 3))
    Rc = np.empty((3, 3))
    H = np.empty((6, 6))
    A = np.empty((6, 6))
    g = np.empty(6)
    s = np.empty(6)
    s_try = np.empty(6)
    step_free = np.empty(6, np.bool_)
    clamp = np.empty(6)
    for n in range(N):
        for d in range(6):
            s[d] = poses[n, d]
        f_start = fitness[n]
        f_cur = f_start
        lam = damping
        for step in range(kinds.shape[0]):
            H[:, :] = 0.0
            g[:] = 0.0
            for d in range(6):
                step_free[d] = free[d] and (kinds[step] != 2 or d < 3)
            for k in range(V):
                if weights[k] == 0.0:
                    continue
                project_pose(s, model, normals, use_normals, intr[k], cfw[k], u, v, usable, R, Rc)
                pose_jacobian(s, model, intr[k], cfw[k], usable, step_free, J)
                a, b = offsets[k], offsets[k + 1]
                px = pts[a:b, 0]
                py = pts[a:b, 1]
                pz_k = pz[a:b]
                w_k = weights[k]
                if kinds[step] != 1:
                    _soft_accumulate(u, v, mz[k], J, usable, px, py, pz_k, sigmas[step, k], outlier, w_k, w_k, H, g,
                                     w_pair, row)
                else:
                    gate = scales[step] * taus[k]
                    _hard_accumulate(u, v, mz[k], J, usable, px, py, pz_k, typed[k], gate * gate, w_k, w_k, H, g,
                                     img_nn, row, mod_nn, mod_d2, mode == MUTUAL)
            # damped step (Levenberg–Marquardt), fixed parameters held
            for i in range(6):
                for j in range(i):
                    H[j, i] = H[i, j]
            delta = _bounded_step(H, g, s, lo, hi, periodic, step_free, lam, A, clamp)
            for d in range(6):
                s_try[d] = s[d] + delta[d]
            to_bounds(s_try, lo, hi, periodic)
            if kinds[step] != 1:
                for d in range(6):
                    s[d] = s_try[d]
                f_cur = np.inf  # unknown until the next hard step or the end
                continue
            if not np.isfinite(f_cur):
                f_cur = fitness_one(s, model, normals, use_normals, intr, cfw, weights, taus, pts, pz, mz, typed,
                                    offsets, mode, u, v, usable, row, mod_d2, R, Rc)
            f_try = fitness_one(s_try, model, normals, use_normals, intr, cfw, weights, taus, pts, pz, mz, typed,
                                offsets, mode, u, v, usable, row, mod_d2, R, Rc)
            if f_try <= f_cur:
                for d in range(6):
                    s[d] = s_try[d]
                f_cur = f_try
                lam = max(lam * 0.3, 1e-6)
            else:
                lam = min(lam * 10.0, 1e4)
        if not np.isfinite(f_cur):
            f_cur = fitness_one(s, model, normals, use_normals, intr, cfw, weights, taus, pts, pz, mz, typed,
                                offsets, mode, u, v, usable, row, mod_d2, R, Rc)
        if f_cur <= f_start:  # never worse than the input
            for d in range(6):
                poses[n, d] = s[d]
            fitness[n] = f_cur
