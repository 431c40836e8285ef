"""Fitness of candidate poses: eq. (1) per view, eq. (4) over views, and a robust variant.

``paper``  — the paper's eq. (1): ``d = sum_i min_j |p_i - m_j(s)|`` over every model
             point in front of the camera. Unbounded: one false image point far from
             the target can move its global minimum.
``robust`` — a bounded, two-sided version of the same distance: each image point
             contributes ``min(min_j |p_i - m_j(s)|, tau)`` and each visible model point
             ``min(min_i |m_j(s) - p_i|, tau)``; the term is the mean over all of them
             (pixels). Pooling both directions in one mean matters: averaging each
             direction separately rewards poses that hide most of the model and match the
             few marks left visible.
             False image points and missing marks then add a constant that does not
             depend on the pose, and a grid shifted by one row pays for the unmatched
             row in both directions. Visibility uses the model normals when given.

Eq. (4): ``d = sum_k W_k d^(k)``; :func:`step_weights` is the paper's step-function rule.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.spatial import cKDTree

from .kernels import chamfer_matches, chamfer_sums
from .pose import rotation_from_euler
from .problem import Model, PoseProblem, View

FitnessKind = Literal["robust", "paper"]
#: A view judges a pose's match only if at least this fraction of the model points is visible in it.
MIN_VISIBLE_FRACTION = 0.25
#: Bounds of the automatic truncation distance (pixels).
TAU_MIN_PX, TAU_MAX_PX = 4.0, 30.0


def auto_tau(points: np.ndarray) -> float:
    """Truncation distance for a view: half the median nearest-neighbour spacing of its points, in pixels.

    Half the spacing keeps a neighbouring feature from counting as a match (so a grid
    shifted by one row is penalised) while tolerating pixel noise.
    """
    if len(points) < 2:
        return 10.0
    d, _ = cKDTree(points).query(points, k=2)
    return float(np.clip(0.5 * np.median(d[:, 1]), TAU_MIN_PX, TAU_MAX_PX))


def image_spread(points: np.ndarray) -> float:
    """Robust size of a point set: median distance to its median centre (pixels, at least 1)."""
    centre = np.median(points, axis=0)
    return max(float(np.median(np.linalg.norm(points - centre, axis=1))), 1.0)


@dataclass(frozen=True, eq=False)
class ViewProjection:
    """A population projected into one view.

    Attributes
    ----------
    uv : array, shape (N, M, 2)
    usable : bool array, shape (N, M)
        In front of the camera and (with normals) facing it.
    """

    uv: np.ndarray
    usable: np.ndarray


def project_into_view(model: Model, view: View, poses: np.ndarray, use_normals: bool = True) -> ViewProjection:
    """Project the model under every pose (N, 6) into ``view``."""
    cam = view.camera
    p_cam = cam.to_camera_frame(poses, model.points)
    uv, usable = cam.project_camera_points(p_cam)
    if use_normals and model.normals is not None:
        R_cam_from_target = cam.camera_from_world[:3, :3] @ rotation_from_euler(np.atleast_2d(poses)[:, 3:])
        n_cam = np.matmul(model.normals, np.swapaxes(R_cam_from_target, 1, 2))  # (N, M, 3)
        usable &= np.sum(n_cam * p_cam, axis=-1) < 0.0
    return ViewProjection(uv, usable)


def view_term(proj: ViewProjection, points: np.ndarray, kind: FitnessKind, tau: float) -> np.ndarray:
    """Distance term ``d^(k)`` of one view for every individual, shape (N,)."""
    u = np.ascontiguousarray(proj.uv[..., 0])
    v = np.ascontiguousarray(proj.uv[..., 1])
    px = np.ascontiguousarray(points[:, 0])
    py = np.ascontiguousarray(points[:, 1])
    robust = kind == "robust"
    img_sum, mod_sum, n_usable = chamfer_sums(u, v, proj.usable, px, py, float(tau), robust)
    if not robust:
        return img_sum  # eq. (1)
    return (img_sum + mod_sum) / (len(points) + n_usable)


def step_weights(terms: np.ndarray, weights: np.ndarray, threshold: float | np.ndarray) -> np.ndarray:
    """The paper's step-function rule for eq. (4): a view whose term exceeds ``threshold`` gets weight 0.

    Parameters
    ----------
    terms : array, shape (V,)
        Each view's distance term for the current best pose.
    weights : array, shape (V,)
        Base weights ``W_k``.
    threshold : float or array (V,)

    Returns
    -------
    array, shape (V,)
        New weights; if every view would be dropped, the base weights are kept
        (there is nothing better to trust).
    """
    keep = np.asarray(terms) <= threshold
    if not np.any(keep & (np.asarray(weights) > 0)):
        return np.asarray(weights, float).copy()
    return np.where(keep, weights, 0.0)


class PoseObjective:
    """Eq. (4) over the problem's views for whole populations.

    Parameters
    ----------
    problem : PoseProblem
    kind : "robust" or "paper"
    tau : float, optional
        Truncation distance (pixels) for the robust kind; per view automatic when None.
    tau_scale : float
        Multiplies tau (a wider tau gives a smoother landscape for screening random starts).
    """

    def __init__(self, problem: PoseProblem, kind: FitnessKind = "robust", tau: float | None = None,
                 tau_scale: float = 1.0) -> None:
        if kind not in ("robust", "paper"):
            raise ValueError(f"fitness kind must be 'robust' or 'paper', got {kind!r}")
        self.problem = problem
        self.kind: FitnessKind = kind
        self.taus = tau_scale * np.array([auto_tau(v.points) if tau is None else float(tau) for v in problem.views])
        self.spreads = np.array([image_spread(v.points) for v in problem.views])
        self.base_weights = np.array([v.weight for v in problem.views], float)
        if not np.any(self.base_weights > 0):
            raise ValueError("at least one view needs a weight > 0")
        self.weights = self.base_weights.copy()
        self.evaluations = 0

    @property
    def n_views(self) -> int:
        return len(self.problem.views)

    def project(self, k: int, poses: np.ndarray) -> ViewProjection:
        return project_into_view(self.problem.model, self.problem.views[k], poses,
                                 use_normals=self.kind == "robust")

    def view_terms(self, poses: np.ndarray, only_weighted: bool = False) -> np.ndarray:
        """Every view's term ``d^(k)`` for every pose, shape (N, V).

        With ``only_weighted`` views of weight 0 are skipped (their column is 0).
        """
        poses = np.atleast_2d(poses)
        out = np.zeros((len(poses), self.n_views))
        for k, view in enumerate(self.problem.views):
            if only_weighted and self.weights[k] == 0:
                continue
            out[:, k] = view_term(self.project(k, poses), view.points, self.kind, self.taus[k])
        self.evaluations += len(poses)
        return out

    def __call__(self, poses: np.ndarray) -> np.ndarray:
        """Eq. (4) ``sum_k W_k d^(k)`` with the current weights, shape (N, 6) -> (N,)."""
        return self.view_terms(poses, only_weighted=True) @ self.weights

    def fitness_scale(self) -> float | None:
        """Fitness of a pose that matches nothing (robust kind): ``sum_k W_k tau_k``; None for the paper's."""
        return float(self.weights @ self.taus) if self.kind == "robust" else None

    def unmatched_fraction(self, pose: np.ndarray, min_visible_fraction: float = MIN_VISIBLE_FRACTION) -> float:
        """Share of the visible model points without a one-to-one image match at ``pose`` (6,).

        A visible model point is matched when its nearest image point lies within tau and has
        it as its own nearest model point (mutual nearest neighbours). Unlike the fitness,
        this ignores false image points, so it tells a right pose in heavy clutter from a
        wrong one: 0 when every visible mark is matched, 1 when none is. Views are averaged
        with their current weights; a view where fewer than ``min_visible_fraction`` of the
        model points (and at least 4) are visible counts as 1. The paper's fitness kind
        gives 1 (no truncation distance to judge a match by).
        """
        if self.kind != "robust":
            return 1.0
        pose = np.atleast_2d(pose)
        n_model = len(self.problem.model.points)
        need = max(4, int(np.ceil(min_visible_fraction * n_model)))
        out = np.ones(self.n_views)
        for k, view in enumerate(self.problem.views):
            if self.weights[k] == 0:
                continue
            proj = self.project(k, pose)
            u = np.ascontiguousarray(proj.uv[..., 0])
            v = np.ascontiguousarray(proj.uv[..., 1])
            img_nn, _, mod_nn, mod_d2 = chamfer_matches(u, v, proj.usable, np.ascontiguousarray(view.points[:, 0]),
                                                        np.ascontiguousarray(view.points[:, 1]))
            visible = proj.usable[0]
            n_visible = int(np.count_nonzero(visible))
            if n_visible < need:
                continue
            m = np.nonzero(visible & (mod_d2[0] <= self.taus[k] ** 2))[0]
            mutual = img_nn[0, mod_nn[0, m]] == m
            out[k] = 1.0 - np.count_nonzero(mutual) / n_visible
        self.evaluations += 1
        return float(out @ self.weights / self.weights.sum())

    def normalised(self, terms: np.ndarray) -> np.ndarray:
        """Terms divided by each view's truncation distance (robust kind), shape (..., V)."""
        return terms / self.taus

    def apply_step_rule(self, best_pose: np.ndarray, threshold: float) -> np.ndarray:
        """Update the view weights with :func:`step_weights` at ``best_pose``.

        For the robust kind ``threshold`` is a fraction of each view's ``tau``; for the
        paper's kind it is in pixels. Returns the new weights, shape (V,).
        """
        terms = self.view_terms(best_pose[None], only_weighted=False)[0]
        limit = threshold * self.taus if self.kind == "robust" else threshold
        self.weights = step_weights(terms, self.base_weights, limit)
        return self.weights
