"""Compiled IRLS of the published pose's robust fit: one stage of :func:`evopose.robust_fit.robust_fit` in one call.

Per iteration, as :mod:`evopose.robust_fit` describes it: the mutual pairs within tau of the current pose in every
weighted view (the pairs of :func:`evopose.covariance.mutual_matches`), each weighed by its loss at its view's
cut-off (Tukey's biweight or the trimmed square) and its view's eq. (4) weight, a Gauss-Newton step on the free
parameters (the projection's analytic Jacobian, :func:`evopose.projection.pose_jacobian`), taken whole, by half or by
a quarter when it lowers the robust cost with the pairs matched anew, else the stage ends. The same projection,
nearest-neighbour matching, box projection and small solve as the refinement (:mod:`evopose.refine_kernel`).

Array conventions as :mod:`evopose.refine_kernel`'s (V views, M model points, P_total image points); ``weights`` (V,)
are eq. (4)'s over their mean among the weighted views (:class:`evopose.covariance.Matches`), ``cutoffs`` (V,) each
view's loss cut-off in pixels (:func:`evopose.robust_fit.view_cutoffs`).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .kernel_abi import FASTMATH as _FASTMATH
from .kernels import nearest_row
from .projection import pose_jacobian, project_pose
from .refine_kernel import solve_in_place, to_bounds, typed_views


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def loss_and_weight(d, c, tukey):  # pragma: no cover - compiled
    """The loss ``rho`` and IRLS weight of a pair ``d`` pixels from its mark at cut-off ``c`` (as
    :func:`evopose.robust_fit.loss_and_weight`): the biweight with ``tukey``, else the trimmed square."""
    if tukey:
        if d >= c:
            return c * c / 6.0, 0.0
        t = 1.0 - (d / c) * (d / c)
        return c * c / 6.0 * (1.0 - t * t * t), t * t
    if d < c:
        return 0.5 * d * d, 1.0
    return 0.5 * c * c, 0.0


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def _pairs(s, model, normals, use_normals, intr, cfw, weights, taus, pts, pz, mz, typed, offsets, cutoffs, tukey,
           u, v, usable, img_nn, img_d2, mod_nn, mod_d2, R, Rc, pair_view, pair_model, pair_image,
           visible):  # pragma: no cover - compiled
    """The mutual pairs within tau of pose ``s`` in every weighted view (written to ``pair_*``, ``visible`` per
    view) and their robust cost (:func:`evopose.robust_fit.robust_cost`: each view's losses plus the loss's ceiling for
    each visible mark without a pair, times its weight); returns (cost, number of pairs)."""
    n = 0
    cost = 0.0
    for k in range(intr.shape[0]):
        visible[k] = 0
        if weights[k] == 0.0:
            continue
        a, b = offsets[k], offsets[k + 1]
        project_pose(s, model, normals, use_normals, intr[k], cfw[k], u, v, usable, R, Rc)
        nearest_row(u, v, mz[k], usable, pts[a:b, 0], pts[a:b, 1], pz[a:b], typed[k], img_nn[:b - a],
                    img_d2[:b - a], mod_nn, mod_d2)
        tau2 = taus[k] * taus[k]
        view_cost = 0.0
        paired = 0
        for m in range(model.shape[0]):
            if not usable[m]:
                continue
            visible[k] += 1
            if mod_d2[m] < tau2 and img_nn[mod_nn[m]] == m:
                p = mod_nn[m]
                dx = u[m] - pts[a + p, 0]
                dy = v[m] - pts[a + p, 1]
                view_cost += loss_and_weight(np.sqrt(dx * dx + dy * dy), cutoffs[k], tukey)[0]
                pair_view[n] = k
                pair_model[n] = m
                pair_image[n] = a + p
                n += 1
                paired += 1
        ceiling = loss_and_weight(np.inf, cutoffs[k], tukey)[0]
        cost += weights[k] * (view_cost + ceiling * (visible[k] - paired))
    return cost, n


@nb.njit(cache=True, fastmath=_FASTMATH, nogil=True)
def robust_irls(s, lo, hi, periodic, free, model, normals, use_normals, intr, cfw, weights, taus, pts, pz, mz,
                offsets, cutoffs, tukey, iterations, settled_step, settled_whole_step):  # pragma: no cover
    """One IRLS stage from pose ``s`` (6,), updated in place; returns the iterations taken.

    Parameters
    ----------
    tukey : bool
        The biweight (else the trimmed square).
    iterations : int
        Most Gauss-Newton steps.
    settled_step, settled_whole_step : float
        The stage ends once a step moves no parameter more than the first, or a whole step not more than the second.
    """
    V = intr.shape[0]
    M = model.shape[0]
    typed, P_max = typed_views(mz, pz, offsets)
    u = np.empty(M)
    v = np.empty(M)
    usable = np.empty(M, np.bool_)
    img_nn = np.empty(P_max, np.int64)
    img_d2 = np.empty(P_max)
    mod_nn = np.empty(M, np.int64)
    mod_d2 = np.empty(M)
    R = np.empty((3, 3))
    Rc = np.empty((3, 3))
    J = np.empty((M, 2, 6))
    pair_view = np.empty(V * M, np.int64)
    pair_model = np.empty(V * M, np.int64)
    pair_image = np.empty(V * M, np.int64)
    visible = np.empty(V, np.int64)
    H = np.empty((6, 6))
    A = np.empty((6, 6))
    g = np.empty(6)
    step = np.empty(6)
    moved = np.empty(6)
    n_free = 0
    for d in range(6):
        if free[d]:
            n_free += 1
    cost, n = _pairs(s, model, normals, use_normals, intr, cfw, weights, taus, pts, pz, mz, typed, offsets, cutoffs,
                     tukey, u, v, usable, img_nn, img_d2, mod_nn, mod_d2, R, Rc, pair_view, pair_model, pair_image,
                     visible)
    taken = 0
    for _ in range(iterations):
        H[:, :] = 0.0
        g[:] = 0.0
        weighted = 0
        for k in range(V):  # the normal equations of the current pairs, view by view (one Jacobian per view)
            if weights[k] == 0.0:
                continue
            project_pose(s, model, normals, use_normals, intr[k], cfw[k], u, v, usable, R, Rc)
            pose_jacobian(s, model, intr[k], cfw[k], usable, free, J)
            for i in range(n):
                if pair_view[i] != k:
                    continue
                m = pair_model[i]
                r0 = u[m] - pts[pair_image[i], 0]
                r1 = v[m] - pts[pair_image[i], 1]
                w = loss_and_weight(np.sqrt(r0 * r0 + r1 * r1), cutoffs[k], tukey)[1] * weights[k]
                if w <= 0.0:
                    continue
                weighted += 1
                for a in range(6):
                    g[a] += w * (J[m, 0, a] * r0 + J[m, 1, a] * r1)
                    for b in range(a + 1):
                        H[a, b] += w * (J[m, 0, a] * J[m, 0, b] + J[m, 1, a] * J[m, 1, b])
        if 2 * weighted < n_free:
            break
        trace = 0.0
        for a in range(6):
            for b in range(a):
                H[b, a] = H[a, b]
            if free[a]:
                trace += H[a, a]
        for a in range(6):
            for b in range(6):
                A[a, b] = H[a, b] if (free[a] and free[b]) else 0.0
            if free[a]:
                A[a, a] += 1e-9 * trace / n_free
                step[a] = -g[a]
            else:
                A[a, a] = 1.0
                step[a] = 0.0
        solve_in_place(A, step)
        finite = True
        for a in range(6):
            if not np.isfinite(step[a]):
                finite = False
        if not finite:
            break
        accepted = 0.0
        for fraction in (1.0, 0.5, 0.25):
            for d in range(6):
                moved[d] = s[d] + fraction * step[d]
            to_bounds(moved, lo, hi, periodic)
            moved_cost, moved_n = _pairs(moved, model, normals, use_normals, intr, cfw, weights, taus, pts, pz, mz,
                                         typed, offsets, cutoffs, tukey, u, v, usable, img_nn, img_d2, mod_nn,
                                         mod_d2, R, Rc, pair_view, pair_model, pair_image, visible)
            if moved_cost <= cost:
                accepted = fraction
                break
        if accepted == 0.0:  # the pairs were overwritten by the rejected tries: the stage ends, nothing else reads them
            break
        for d in range(6):
            s[d] = moved[d]
        cost, n = moved_cost, moved_n
        taken += 1
        moved_by = 0.0
        for d in range(6):
            moved_by = max(moved_by, abs(accepted * step[d]))
        if moved_by < settled_step or (accepted == 1.0 and moved_by < settled_whole_step):
            break
    return taken
