"""Fitness of candidate poses: eq. (1) per view, eq. (4) over views, and two bounded variants.

``mutual`` — (the default) eq. (1)'s distance made one to one and bounded: each image point and each
             visible model point contributes its distance to its *mutual* nearest neighbour when that
             is closer than tau, else tau; the term is the root mean square over all of them (pixels,
             :func:`evopose.kernels.mutual_row`). Squared distances weigh the evidence as Gaussian pixel
             noise does, and one-to-one pairs stop one projected mark from explaining two image points:
             at the paper's image scale (marks 3-5 px apart, 1-2 px noise) this picks the right basin
             where the chamfer sums below prefer a flipped pose (issue 11). With one-to-one pairs, tau
             is an outlier gate tied to the point noise, not to the spacing of the marks.
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

How well a pose matches is one measure, :class:`Match`: ``mismatch`` (eq. 4 over its value when
nothing matches; squared for the mutual kind, a share of squared distances) and ``unmatched`` (share of visible marks without a one-to-one match), both in
[0, 1], 0 perfect. :class:`PoseObjective` is immutable: other weights make another objective.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from typing import Literal

import numpy as np

from .kernel_abi import MUTUAL, PAPER, ROBUST
from .kernel_backend import chamfer_matches, project_poses, view_terms
from .neighbours import nearest_distance
from .problem import Model, PoseProblem, View, label_coordinates

FitnessKind = Literal["mutual", "robust", "paper"]
#: Kernel mode of each fitness kind (:func:`evopose.kernels.view_term_row`).
KERNEL_MODES = {"paper": PAPER, "robust": ROBUST, "mutual": MUTUAL}
#: A view judges a pose's match only if at least this fraction of the model points is visible in it.
MIN_VISIBLE_FRACTION = 0.25
#: Expected 1-sigma noise of image points (pixels): feature centroids at any image scale.
POINT_NOISE_PX = 1.0
#: The smallest automatic tau, in units of the point noise: a right pair lies within 4 sigma with
#: probability 1 - exp(-8) (2-D Gaussian), so noise alone almost never truncates it.
TAU_NOISE_SIGMAS = 4.0
#: Bounds of the automatic truncation distance (pixels).
TAU_MIN_PX, TAU_MAX_PX = TAU_NOISE_SIGMAS * POINT_NOISE_PX, 30.0


def auto_tau(points: np.ndarray, noise: float = POINT_NOISE_PX) -> float:
    """Truncation distance for a view (pixels): half the median nearest-neighbour spacing of its points,
    at least ``TAU_NOISE_SIGMAS`` times the point ``noise`` and at most ``TAU_MAX_PX``.

    At the telephoto scale half the spacing keeps a neighbouring feature from counting as a match (so a
    grid shifted by one row is penalised) while tolerating pixel noise. At the paper's image scale (marks
    3-5 px apart) the floor rules: there tau gates outliers and the one-to-one pairs of the "mutual" kind
    keep neighbours apart. Smaller floors were measured worse on seeded paper-scale problems with 0.5-2 px
    noise (right basin 65 % at 3 px, 78 % at 4 px, 72 % at 5 px; 35 % at 2 px for "robust"), because
    they truncate right pairs at 2 px noise.
    """
    if len(points) < 2:
        return 10.0
    d = nearest_distance(points, points, exclude_self=True)
    return float(np.clip(0.5 * np.median(d), TAU_NOISE_SIGMAS * noise, TAU_MAX_PX))


def image_spread(points: np.ndarray) -> float:
    """Robust size of a point set: median distance to its median centre (pixels, at least 1)."""
    centre = np.median(points, axis=0)
    return max(float(np.median(np.linalg.norm(points - centre, axis=1))), 1.0)


def view_scales(view: View) -> tuple[float, float]:
    """``(auto_tau, image_spread)`` of ``view``'s points (pixels). Kept for the last :data:`KEPT_VIEW_SCALES` point
    sets: a frame's views make several objectives (the search's, the verdict's, the published pose's), often from
    views built anew of the same points."""
    return _scales_of(view.points.tobytes())


#: How many point sets' :func:`view_scales` are kept.
KEPT_VIEW_SCALES = 64


@lru_cache(maxsize=KEPT_VIEW_SCALES)
def _scales_of(points: bytes) -> tuple[float, float]:
    xy = np.frombuffer(points, float).reshape(-1, 2)
    return auto_tau(xy), image_spread(xy)


@dataclass(frozen=True, eq=False)
class ViewProjection:
    """A population projected into one view.

    Attributes
    ----------
    u, v : array, shape (N, M)
        Pixels of every model point under every pose.
    usable : bool array, shape (N, M)
        In front of the camera and (with normals) facing it.
    """

    u: np.ndarray
    v: np.ndarray
    usable: np.ndarray

    @property
    def uv(self) -> np.ndarray:
        """Pixels as pairs, shape (N, M, 2)."""
        return np.stack([self.u, self.v], axis=-1)


def project_into_view(model: Model, view: View, poses: np.ndarray, use_normals: bool = True) -> ViewProjection:
    """Project the model under every pose (N, 6) into ``view`` (:func:`evopose.projection.project_poses`)."""
    cam = view.camera
    with_normals = use_normals and model.normals is not None
    normals = np.ascontiguousarray(model.normals) if with_normals else np.zeros((1, 3))
    u, v, usable = project_poses(np.ascontiguousarray(np.atleast_2d(np.asarray(poses, dtype=float))),
                                 np.ascontiguousarray(model.points), normals, with_normals, cam.intrinsics,
                                 np.ascontiguousarray(cam.camera_from_world))
    return ViewProjection(u, v, usable)


def view_term(proj: ViewProjection, points: np.ndarray, kind: FitnessKind, tau: float,
              labels: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Distance term ``d^(k)`` of one view for every individual, shape (N,) (:func:`evopose.kernels.view_terms`).

    ``labels``: the view's and the model's label coordinates, (P,) and (M,) (:func:`label_coordinates`); untyped
    points when None."""
    pz, mz = labels if labels is not None else (np.zeros(len(points)), np.zeros(proj.u.shape[1]))
    return view_terms(proj.u, proj.v, np.ascontiguousarray(mz, float), proj.usable,
                      np.ascontiguousarray(points[:, 0]), np.ascontiguousarray(points[:, 1]),
                      np.ascontiguousarray(pz, float), float(tau), KERNEL_MODES[kind])


def matches(proj: ViewProjection, points: np.ndarray, labels: tuple[np.ndarray, np.ndarray]):
    """Nearest neighbours both ways for every projected pose (:func:`evopose.kernels.chamfer_matches`), in (u, v,
    label) space; ``labels`` as :func:`view_term`'s."""
    pz, mz = labels
    return chamfer_matches(proj.u, proj.v, np.ascontiguousarray(mz, float), proj.usable,
                           np.ascontiguousarray(points[:, 0]), np.ascontiguousarray(points[:, 1]),
                           np.ascontiguousarray(pz, float))


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




@dataclass(frozen=True)
class Match:
    """How well a pose fits the views: the one match measure, two shares in [0, 1], 0 perfect.

    Attributes
    ----------
    mismatch : float or None
        Eq. (4) at the pose over its value when nothing matches, ``sum_k W_k d^(k) / sum_k W_k tau_k``,
        squared for the mutual kind (:meth:`PoseObjective.mismatch`): 0 every point matched exactly, 1
        nothing within tau. None for the paper's eq. (1), which has no such bound.
    unmatched : float
        Share of the pose's visible marks without a one-to-one image match (false image points do not
        count; 1 when unknown). See :meth:`PoseObjective.unmatched_fraction`.
    """

    mismatch: float | None = None
    unmatched: float = 1.0


class EvaluationCounter:
    """Projections of the model made so far: the budget by which optimisers are compared.

    The one mutable part of an objective, on purpose: an objective and those derived from it
    (:meth:`PoseObjective.with_weights`) count into the same counter, and so does the refinement.
    """

    __slots__ = ("count",)

    def __init__(self, count: int = 0) -> None:
        self.count = int(count)

    def add(self, n: int) -> None:
        self.count += int(n)

    def __repr__(self) -> str:
        return f"EvaluationCounter({self.count})"


@dataclass(frozen=True, eq=False)
class Packed:
    """An objective's views as flat arrays for the compiled kernels (:mod:`evopose.refine_kernel`).

    ``intr`` (V, 9) fx, fy, cx, cy, k1, k2, p1, p2, k3; ``cfw`` (V, 4, 4) camera_from_world;
    ``pts`` (P_total, 2) with view k's points at ``offsets[k]:offsets[k+1]``; ``pz`` (P_total,) and ``mz``
    (V, M) the points' and the marks' label coordinates per view (:func:`label_coordinates`); ``model`` (M, 3);
    ``normals`` (M, 3) (a dummy (1, 3) when unused).
    """

    intr: np.ndarray
    cfw: np.ndarray
    pts: np.ndarray
    pz: np.ndarray
    mz: np.ndarray
    offsets: np.ndarray
    model: np.ndarray
    normals: np.ndarray
    use_normals: bool


def _read_only(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class PoseObjective:
    """Eq. (4) over the problem's views for whole populations; immutable.

    Parameters
    ----------
    problem : PoseProblem
    kind : "mutual", "robust" or "paper"
    tau : float, optional
        Truncation distance (pixels) for the bounded kinds; per view automatic when None (:func:`auto_tau`).
    tau_scale : float
        Multiplies tau (a wider tau gives a smoother landscape for screening random starts).
    weights : array (V,), optional
        ``W_k`` of eq. (4); the views' own weights when None. :meth:`with_weights` derives an objective
        with other weights (the step rule's); nothing else changes an objective.
    counter : EvaluationCounter, optional
        Where evaluations are counted (shared by the objectives derived from this one).

    Attributes
    ----------
    label_coordinates : tuple of V pairs (pz (P_k,), mz (M,)), read-only
        Each view's and the model's label coordinates (:func:`label_coordinates`).
    taus, spreads, base_weights, weights : arrays (V,), read-only
        Per view: truncation distance, robust image spread of its points (pixels), its own weight and the
        weight in force.
    """

    problem: PoseProblem
    kind: FitnessKind = "mutual"
    tau: float | None = None
    tau_scale: float = 1.0
    weights: np.ndarray | None = None
    counter: EvaluationCounter = field(default_factory=EvaluationCounter, repr=False)

    def __post_init__(self) -> None:
        if self.kind not in KERNEL_MODES:
            raise ValueError(f"fitness kind must be one of {', '.join(KERNEL_MODES)}, got {self.kind!r}")
        views = self.problem.views
        scales = [view_scales(v) for v in views]
        taus = [tau if self.tau is None else float(self.tau) for tau, _ in scales]
        object.__setattr__(self, "taus", _read_only(self.tau_scale * np.array(taus)))
        object.__setattr__(self, "spreads", _read_only([spread for _, spread in scales]))
        object.__setattr__(self, "label_coordinates",
                           tuple((_read_only(pz), _read_only(mz))
                                 for pz, mz in (label_coordinates(self.problem.model, v) for v in views)))
        base = _read_only([v.weight for v in views])
        if not np.any(base > 0):
            raise ValueError("at least one view needs a weight > 0")
        object.__setattr__(self, "base_weights", base)
        weights = base if self.weights is None else _read_only(self.weights)
        if weights.shape != base.shape or not np.all(np.isfinite(weights)) or np.any(weights < 0):
            raise ValueError(f"weights must be {len(views)} finite numbers >= 0, got {self.weights!r}")
        if not np.any(weights > 0):
            raise ValueError("at least one view needs a weight > 0")
        object.__setattr__(self, "weights", weights)

    def with_weights(self, weights: np.ndarray) -> "PoseObjective":
        """The same objective with other eq. (4) weights ``W_k`` (V,); counts into the same counter.

        The per-view taus and spreads are the same: they are carried over, not computed again."""
        weights = _read_only(np.asarray(weights, float))
        base = self.base_weights
        if weights.shape != base.shape or not np.all(np.isfinite(weights)) or np.any(weights < 0) \
                or not np.any(weights > 0):
            raise ValueError(f"weights must be {len(base)} finite numbers >= 0, not all 0, got {weights!r}")
        other = copy.copy(self)
        object.__setattr__(other, "weights", weights)
        other.__dict__.pop("packed", None)  # a cached_property of the weights
        return other

    @property
    def bounded(self) -> bool:
        """A kind truncated at tau ("mutual", "robust"): its terms lie in [0, tau], visibility uses normals."""
        return self.kind != "paper"

    @property
    def mode(self) -> int:
        """The kind as a kernel mode (:data:`KERNEL_MODES`)."""
        return KERNEL_MODES[self.kind]

    @property
    def n_views(self) -> int:
        return len(self.problem.views)

    @property
    def evaluations(self) -> int:
        """Projections of the model counted so far (:class:`EvaluationCounter`)."""
        return self.counter.count

    @cached_property
    def packed(self) -> Packed:
        """The views as flat arrays for the compiled refinement (computed once per objective)."""
        views = self.problem.views
        model = self.problem.model
        use_normals = self.bounded and model.normals is not None
        labels = [self.labels(k) for k in range(len(views))]
        return Packed(
            intr=np.ascontiguousarray([v.camera.intrinsics for v in views]),
            cfw=np.ascontiguousarray([v.camera.camera_from_world for v in views]),
            pts=np.ascontiguousarray(np.concatenate([v.points for v in views])),
            pz=np.ascontiguousarray(np.concatenate([pz for pz, _ in labels])),
            mz=np.ascontiguousarray([mz for _, mz in labels]),
            offsets=np.cumsum([0] + [len(v.points) for v in views]).astype(np.int64),
            model=np.ascontiguousarray(model.points),
            normals=np.ascontiguousarray(model.normals) if use_normals else np.zeros((1, 3)),
            use_normals=use_normals)

    def labels(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """View ``k``'s and the model's label coordinates, (P_k,) and (M,) (:func:`label_coordinates`; made once,
        with the objective)."""
        return self.label_coordinates[k]

    def project(self, k: int, poses: np.ndarray) -> ViewProjection:
        return project_into_view(self.problem.model, self.problem.views[k], poses,
                                 use_normals=self.bounded)

    def view_terms(self, poses: np.ndarray, only_weighted: bool = False) -> np.ndarray:
        """Every view's term ``d^(k)`` for every pose, shape (N, V).

        With ``only_weighted`` views of weight 0 are skipped (their column is 0).
        """
        poses = np.atleast_2d(poses)
        out = np.zeros((len(poses), self.n_views))
        for k, view in enumerate(self.problem.views):
            if only_weighted and self.weights[k] == 0:
                continue
            out[:, k] = view_term(self.project(k, poses), view.points, self.kind, self.taus[k], self.labels(k))
        self.counter.add(len(poses))
        return out

    def __call__(self, poses: np.ndarray) -> np.ndarray:
        """Eq. (4) ``sum_k W_k d^(k)`` with the objective's weights, shape (N, 6) -> (N,)."""
        return self.view_terms(poses, only_weighted=True) @ self.weights

    @property
    def no_match_fitness(self) -> float | None:
        """Eq. (4) of a pose that matches nothing (bounded kinds): ``sum_k W_k tau_k``; None for the paper's."""
        return float(self.weights @ self.taus) if self.bounded else None

    def mismatch(self, fitness):
        """:attr:`Match.mismatch` of poses whose eq. (4) is ``fitness``: fitness over :attr:`no_match_fitness`,
        squared for the mutual kind (whose terms are root mean squares: the share of squared distances, on the
        scale of the robust kind's share of distances, so one set of thresholds serves both).

        Same shape as ``fitness``; None for the paper's kind.
        """
        scale = self.no_match_fitness
        if scale is None:
            return None
        share = np.asarray(fitness, float) / scale
        return share ** 2 if self.kind == "mutual" else share

    def match(self, pose: np.ndarray, fitness: float | None = None) -> Match:
        """:class:`Match` of one pose (6,) whose eq. (4) is ``fitness`` (computed when None)."""
        if fitness is None:
            fitness = float(self(np.atleast_2d(pose))[0])
        mismatch = self.mismatch(fitness)
        return Match(None if mismatch is None else float(mismatch), self.unmatched_fraction(pose))

    def unmatched_fraction(self, pose: np.ndarray, min_visible_fraction: float = MIN_VISIBLE_FRACTION) -> float:
        """Share of the visible model points without a one-to-one image match at ``pose`` (6,).

        A visible model point is matched when its nearest image point lies within tau and has
        it as its own nearest model point (mutual nearest neighbours). Unlike the fitness,
        this ignores false image points, so it tells a right pose in heavy clutter from a
        wrong one: 0 when every visible mark is matched, 1 when none is. Views are averaged
        with the objective's weights; a view where fewer than ``min_visible_fraction`` of the
        model points (and at least 4) are visible counts as 1. The paper's fitness kind
        gives 1 (no truncation distance to judge a match by).
        """
        if not self.bounded:
            return 1.0
        pose = np.atleast_2d(pose)
        n_model = len(self.problem.model.points)
        need = max(4, int(np.ceil(min_visible_fraction * n_model)))
        out = np.ones(self.n_views)
        for k, view in enumerate(self.problem.views):
            if self.weights[k] == 0:
                continue
            proj = self.project(k, pose)
            img_nn, _, mod_nn, mod_d2 = matches(proj, view.points, self.labels(k))
            visible = proj.usable[0]
            n_visible = int(np.count_nonzero(visible))
            if n_visible < need:
                continue
            m = np.nonzero(visible & (mod_d2[0] <= self.taus[k] ** 2))[0]
            mutual = img_nn[0, mod_nn[0, m]] == m
            out[k] = 1.0 - np.count_nonzero(mutual) / n_visible
        self.counter.add(1)
        return float(out @ self.weights / self.weights.sum())

    def normalised(self, terms: np.ndarray) -> np.ndarray:
        """Terms divided by each view's truncation distance (bounded kinds), shape (..., V)."""
        return terms / self.taus

    def step_rule_weights(self, best_pose: np.ndarray, threshold: float) -> np.ndarray:
        """Eq. (4) weights by the paper's step rule (:func:`step_weights`) at ``best_pose``, shape (V,).

        For the bounded kinds ``threshold`` is a fraction of each view's ``tau``; for the paper's kind it is
        in pixels. The objective is not changed: derive one with :meth:`with_weights`.
        """
        terms = self.view_terms(np.atleast_2d(best_pose), only_weighted=False)[0]
        limit = threshold * self.taus if self.bounded else threshold
        return step_weights(terms, self.base_weights, limit)
