"""Eq. (4)'s view weights ``W_k`` from each view's own evidence (issue 13; the paper's "future work", §V).

The paper weighs the views of eq. (4), ``d = sum_k W_k d^(k)``, equally (``W_1 = W_2 = 0.5`` in Experiment 2)
or by a step function: a view whose term exceeds a threshold "may not be reliable, or not contain the object
looked for", and gets ``W_k = 0`` (:func:`evopose.fitness.step_weights`). It leaves the weights' computation
to future work, naming "confidence in the data and/or in the quality of the hardware producing it" and the
"quality of the point of view". Three rules, :data:`ViewWeighting`:

``equal``    — the views' own weights (``W = 1/V`` in the agents), never changed.
``step``     — the paper's step rule at the current best pose.
``adaptive`` — the step rule, then a graded reliability per view (:func:`adaptive_weights`).

The adaptive rule. At the current best pose ``s`` each view ``k`` is judged on what it alone says
(:func:`view_evidence`, the mutual pairs of :mod:`evopose.covariance`):

* **explained share** ``a_k = (m_k + K) / (P_k + K)``: of its ``P_k`` image points, the ``m_k`` matched one to one
  to a model mark within the view's tau. Clutter and distractor blobs in the mark colours are image points no
  mark explains: they do not move a one-to-one fit's residual, but they are what pulls a search into a wrong
  basin, so a cluttered view is trusted less. ``K`` (:data:`PRIOR_POINTS`) pseudo-points shrink the share towards
  1 when a view has few points: a handful of points is not evidence of clutter.
* **information share** ``g_k``: the Gauss-Newton information about ``s`` of the view's matched pairs at its own
  residual variance, ``I_k = J_m^T J_m / s_k^2`` (``s_k^2`` corrected for the truncation at tau and at least the
  nominal point noise ``sigma_0^2``, as in :func:`evopose.covariance.covariance`), against the information the
  same camera would give if every visible mark were matched at the nominal noise, ``N_k = J_v^T J_v / sigma_0^2``;
  ``g_k`` is the geometric mean of the generalised eigenvalues of ``(I_k + P, N_k + P)``, i.e.
  ``(det(I_k + P) / det(N_k + P))^(1/n)`` (D-optimality; ``P`` the box prior of the covariance, so a direction no
  view of one camera determines does not divide by 0). In [0, 1]: 1 for a sharp, unoccluded view; an occluder
  (marks lost, the informative ones weigh most), blur (centroids shifted, marks merged: a larger ``s_k``) and
  missing marks lower it. Dividing by the camera's own nominal information makes it scale free: a far camera or
  a short lens is not a degraded one, and the per-view terms of eq. (4), root mean squares, already scale
  with each camera's geometry.

Reliability ``q_k = a_k g_k``. The rule keeps the paper's step as its first stage and is bounded:

1. a view whose normalised term ``d^(k) / tau_k`` exceeds the step threshold *and* that matches fewer than
   :data:`PRESENT_MARKS` marks one to one gets ``W_k = 0`` (:func:`evopose.fitness.step_weights` on those views).
   The paper's step rule drops a view on its term alone; but a view that matches several marks shows the target,
   and its large term is clutter or blur: the graded stage weighs it down without discarding what its marks tell
   (dropping a view discards its baseline: at the paper's scale, one view alone leaves the depth loose);
2. every other view keeps ``W_k = B_k rho_k``, ``rho_k = clip(q_k / max_j q_j, 1 / R, 1)`` with ``B_k`` its base
   weight and ``R`` = :data:`MAX_RATIO`: the most reliable view keeps its base weight and no view is pushed below
   ``1/R`` of its own. A view is silenced only by the step rule's evidence, never by a graded judgement on one
   frame: a wrong best pose early in a search misjudges every view, and a bounded weight cannot lock it in.
   ``rho_k`` is rounded to :data:`LEVELS_PER_OCTAVE` levels per halving, and :func:`settled` keeps the weights in
   force unless one view moves against another by a factor :data:`HYSTERESIS` or more, so the search's fitness
   is not rescored every generation (a rescore restarts its consensus count) and a view near a level's edge
   does not flip back and forth.

When. In a search (:func:`evopose.solve`) the first stage runs every generation from the second on, like the
paper's step rule, and the graded weights are applied once, at the end, to the best pose: the final polish
refines it under them (:func:`evopose.solver.solution_of`). Graded weights during the search were measured worse
(``benchmarks/bench_weights.py``, synthetic paper-scale problems with H2 degraded: right basin 60 % against 67 %
with equal weights): judged at a best pose that may still be in a wrong basin, a degraded view is weighed down
exactly when its marks are what rules that basin out. Which basin is a question for all the evidence; how
precisely the pose sits in it, for the reliable evidence.

Sum: ``sum_k W_k <= sum_k B_k`` (equal to it when the views are equally reliable); only ratios matter to the
search and to :attr:`evopose.fitness.Match.mismatch`. With ``R = 1`` the rule is the step rule exactly (the
degenerate case; ``present_marks = inf`` makes the first stage the paper's exactly), and equally reliable views
keep their base weights.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from .covariance import JACOBIAN_STEP, MIN_RESIDUAL_VARIANCE, mutual_matches, untruncated_variance
from .fitness import POINT_NOISE_PX, PoseObjective, step_weights

ViewWeighting = Literal["equal", "step", "adaptive"]
VIEW_WEIGHTINGS: tuple[str, ...] = ("equal", "step", "adaptive")
#: Largest ratio between the weight of the most reliable view and that of any other kept view (relative to
#: their base weights).
MAX_RATIO = 4.0
#: Pseudo image points, all explained, added to each view's count (shrinks the explained share to 1 with few points).
PRIOR_POINTS = 2.0
#: A view matching at least this many marks one to one shows the target: the step stage does not drop it.
PRESENT_MARKS = 5
#: Quantisation of ``rho_k``: levels per halving (log2 steps of 1/2).
LEVELS_PER_OCTAVE = 2
#: New weights replace those in force only when two views' ratio changes by at least this factor.
HYSTERESIS = 2.0


@dataclass(frozen=True, eq=False)
class ViewEvidence:
    """What each view alone says about a pose (all arrays shape (V,)).

    Attributes
    ----------
    residual : array
        The view's term of eq. (4) over its tau, ``d^(k) / tau_k`` (bounded kinds; the paper's kind: pixels).
    matched : int array
        Model marks matched one to one to an image point within tau.
    visible : int array
        Model marks in front of the camera and facing it.
    image : int array
        Image points.
    information : array
        ``g_k`` in [0, 1]: the view's information over its nominal information (module docstring).
    """

    residual: np.ndarray
    matched: np.ndarray
    visible: np.ndarray
    image: np.ndarray
    information: np.ndarray

    @property
    def explained(self) -> np.ndarray:
        """``a_k``: share of the image points explained by a mark, shrunk towards 1 by :data:`PRIOR_POINTS`."""
        return (self.matched + PRIOR_POINTS) / (self.image + PRIOR_POINTS)

    @property
    def reliability(self) -> np.ndarray:
        """``q_k = a_k g_k`` in [0, 1]."""
        return np.clip(self.explained * self.information, 0.0, 1.0)


def _jacobian_all(objective: PoseObjective, k: int, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel derivatives of every model point in view ``k`` w.r.t. ``s`` (M, 2, 6) and their usability (M,)."""
    steps = np.diag(JACOBIAN_STEP)
    probes = np.concatenate([pose[None], pose + steps, pose - steps])  # (13, 6)
    proj = objective.project(k, probes)
    objective.counter.add(len(probes))
    du = (proj.u[1:7] - proj.u[7:]) / (2 * JACOBIAN_STEP[:, None])  # (6, M)
    dv = (proj.v[1:7] - proj.v[7:]) / (2 * JACOBIAN_STEP[:, None])
    return np.stack([du.T, dv.T], axis=1), proj.usable[0]


def information_share(matched_J: np.ndarray, residuals: np.ndarray, visible_J: np.ndarray, tau: float,
                      prior: np.ndarray) -> float:
    """``g_k`` of one view: ``(det(I + P) / det(N + P))^(1/n)`` clipped to [0, 1].

    Parameters
    ----------
    matched_J : array (m, 2, n)
        Jacobians of the matched marks (free parameters only).
    residuals : array (m, 2)
        Their pixel residuals.
    visible_J : array (v, 2, n)
        Jacobians of every visible mark.
    tau : float
        The view's truncation distance (pixels).
    prior : array (n,)
        Prior information per free parameter (the box's, ``12 / width^2``; 0 for a periodic angle).
    """
    n = visible_J.shape[-1]
    if len(visible_J) == 0 or n == 0:
        return 1.0  # nothing to judge by: no evidence against the view
    dof = max(2 * len(matched_J) - n, 1)
    s2 = float(np.sum(residuals ** 2)) / dof if len(matched_J) else np.inf
    s2 = max(untruncated_variance(s2, tau * tau) if np.isfinite(s2) else tau * tau, MIN_RESIDUAL_VARIANCE)
    # a small floor keeps a periodic angle that no single view fixes from making both matrices singular
    P = np.diag(np.maximum(prior, 1e-9))
    info = np.einsum("mai,maj->ij", matched_J, matched_J) / s2 + P if len(matched_J) else P
    nominal = np.einsum("mai,maj->ij", visible_J, visible_J) / POINT_NOISE_PX ** 2 + P
    try:
        L = np.linalg.cholesky(0.5 * (nominal + nominal.T))
        Li = np.linalg.inv(L)
        eig = np.linalg.eigvalsh(Li @ (0.5 * (info + info.T)) @ Li.T)
    except np.linalg.LinAlgError:
        return 1.0
    eig = np.clip(eig, 1e-300, None)
    return float(np.clip(np.exp(np.mean(np.log(eig))), 0.0, 1.0))


def view_evidence(objective: PoseObjective, pose: np.ndarray) -> ViewEvidence:
    """:class:`ViewEvidence` of every view of ``objective`` at ``pose`` (6,)."""
    pose = np.asarray(pose, float).reshape(6)
    terms = objective.view_terms(pose[None], only_weighted=False)[0]
    residual = objective.normalised(terms) if objective.bounded else terms
    matches = mutual_matches(objective, pose)
    bounds = objective.problem.bounds
    free = bounds.free
    prior = np.where(bounds.periodic[free], 0.0, 12.0 / np.maximum(bounds.width[free], 1e-300) ** 2)
    V = objective.n_views
    matched = np.array([np.count_nonzero(matches.view == k) for k in range(V)])
    information = np.ones(V)
    for k in range(V):
        J, usable = _jacobian_all(objective, k, pose)
        rows = matches.view == k
        J = J[:, :, free]
        information[k] = information_share(J[matches.model_index[rows]], matches.residuals[rows], J[usable],
                                           float(objective.taus[k]), prior)
    return ViewEvidence(residual, matched, matches.n_visible.astype(int), matches.n_image.astype(int), information)


def _quantised(rho: np.ndarray) -> np.ndarray:
    """``rho`` rounded to :data:`LEVELS_PER_OCTAVE` levels per halving (0 stays 0)."""
    out = np.zeros_like(rho)
    pos = rho > 0
    out[pos] = 2.0 ** (np.round(np.log2(rho[pos]) * LEVELS_PER_OCTAVE) / LEVELS_PER_OCTAVE)
    return out


def adaptive_weights(evidence: ViewEvidence, base: np.ndarray, threshold: float | None,
                     max_ratio: float = MAX_RATIO, present_marks: float = PRESENT_MARKS) -> np.ndarray:
    """Eq. (4) weights by the adaptive rule (module docstring), shape (V,).

    Parameters
    ----------
    evidence : ViewEvidence
    base : array (V,)
        The views' own weights ``B_k``.
    threshold : float or None
        The step rule's threshold on ``evidence.residual`` (None: no step stage).
    max_ratio : float
        ``R`` >= 1.
    present_marks : float
        Views matching at least this many marks are not dropped by the step stage. With ``max_ratio = 1`` and
        ``present_marks = inf`` the rule is the paper's step rule exactly.
    """
    base = np.asarray(base, float)
    if max_ratio < 1:
        raise ValueError(f"max_ratio must be >= 1, got {max_ratio}")
    residual = np.where(evidence.matched >= present_marks, -np.inf, evidence.residual)  # shows the target: kept
    kept = base.copy() if threshold is None else step_weights(residual, base, threshold)
    on = kept > 0
    q = evidence.reliability
    best = float(np.max(q[on])) if np.any(on) else 0.0
    if best <= 0 or max_ratio == 1:
        return kept
    rho = np.clip(q / best, 1.0 / max_ratio, 1.0)
    return np.where(on, kept * _quantised(rho), 0.0)


def rule_weights(objective: PoseObjective, pose: np.ndarray, weighting: ViewWeighting,
                 threshold: float | None, max_ratio: float = MAX_RATIO) -> np.ndarray:
    """The weights of rule ``weighting`` for ``objective``'s views at ``pose`` (6,), shape (V,).

    ``threshold`` is the step rule's (a fraction of each view's tau for the bounded kinds, pixels for the paper's;
    :attr:`evopose.options.SearchOptions.view_reject`). The objective is not changed: derive one with
    :meth:`evopose.fitness.PoseObjective.with_weights`.
    """
    if weighting == "equal" or objective.n_views < 2:
        return np.array(objective.base_weights)
    if weighting == "step":
        if threshold is None:
            return np.array(objective.base_weights)
        return objective.step_rule_weights(pose, threshold)
    if weighting == "adaptive":
        return adaptive_weights(view_evidence(objective, pose), objective.base_weights, threshold, max_ratio)
    raise ValueError(f"view weighting must be one of {', '.join(VIEW_WEIGHTINGS)}, got {weighting!r}")


def settled(current: np.ndarray, proposed: np.ndarray) -> bool:
    """Whether the weights in force may stay: the same views weighted, and no two views' ratio changed by
    :data:`HYSTERESIS` or more."""
    current, proposed = np.asarray(current, float), np.asarray(proposed, float)
    if not np.array_equal(current > 0, proposed > 0):
        return False
    on = current > 0
    if not np.any(on):
        return True
    ratio = np.log2(proposed[on] / current[on])
    return bool(np.ptp(ratio) < np.log2(HYSTERESIS) - 1e-9)


__all__ = ["MAX_RATIO", "VIEW_WEIGHTINGS", "ViewEvidence", "ViewWeighting", "adaptive_weights", "information_share",
           "rule_weights", "settled", "view_evidence"]
