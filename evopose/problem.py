"""The pose problem: a model, one or more views (eq. 4), the search box and the constraints (eq. 3), hints."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from geometry import ANGLE_PARAMS, PARAM_NAMES

from .camera import Camera

TWO_PI = 2 * np.pi


@dataclass(frozen=True, eq=False)
class Model:
    """A target's feature points in the target frame.

    Attributes
    ----------
    points : array, shape (M, 3)
        Metres.
    normals : array, shape (M, 3), optional
        Outward surface normals; when given, a point is visible only from the side its normal faces.
    labels : int array, shape (M,), optional
        Each mark's class (its colour), integers >= 0. A view whose image points carry labels too matches a
        point only to marks of its own class (:func:`label_coordinates`); our extension of eq. (1), whose
        points are untyped. Views without labels match every mark, as in the paper.
    """

    points: np.ndarray
    normals: np.ndarray | None = None
    labels: np.ndarray | None = None

    def __post_init__(self) -> None:
        pts = np.asarray(self.points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0:
            raise ValueError(f"model.points must have shape (M, 3) with M >= 1, got {pts.shape}")
        if not np.all(np.isfinite(pts)):
            raise ValueError("model.points must be finite")
        object.__setattr__(self, "points", pts)
        if self.normals is not None:
            n = np.asarray(self.normals, dtype=float)
            if n.shape != pts.shape or not np.all(np.isfinite(n)):
                raise ValueError(f"model.normals must have shape {pts.shape}, got {n.shape}")
            norm = np.linalg.norm(n, axis=1, keepdims=True)
            if np.any(norm < 1e-12):
                raise ValueError("model.normals must be non-zero vectors")
            object.__setattr__(self, "normals", n / norm)
        if self.labels is not None:
            object.__setattr__(self, "labels", _labels("model.labels", self.labels, len(pts)))

    @property
    def radius(self) -> float:
        """Largest distance of a point from the centroid (metres)."""
        c = self.points.mean(axis=0)
        return float(np.max(np.linalg.norm(self.points - c, axis=1))) or 1e-3


@dataclass(frozen=True, eq=False)
class View:
    """One camera's image feature points (unordered) and its weight in eq. (4).

    Attributes
    ----------
    camera : Camera
    points : array, shape (P, 2)
        Pixels.
    weight : float
        ``W_k`` of eq. (4).
    labels : int array, shape (P,), optional
        Each point's class (the colour of the mark it would be), integers >= 0; see :attr:`Model.labels`.
    """

    camera: Camera
    points: np.ndarray
    weight: float = 1.0
    labels: np.ndarray | None = None

    def __post_init__(self) -> None:
        pts = np.array(self.points, dtype=float)   # a copy of its own, read-only below
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) == 0:
            raise ValueError(f"view points must have shape (P, 2) with P >= 1, got {pts.shape}")
        if not np.all(np.isfinite(pts)):
            raise ValueError("view points must be finite")
        if not np.isfinite(self.weight) or self.weight < 0:
            raise ValueError(f"view weight must be a finite number >= 0, got {self.weight}")
        pts.flags.writeable = False   # a view's points never change (derived scales are kept: fitness.view_scales)
        object.__setattr__(self, "points", pts)
        if self.labels is not None:
            object.__setattr__(self, "labels", _labels("view labels", self.labels, len(pts)))


#: Distance (pixels) between neighbouring classes on the label axis (:func:`label_coordinates`): far beyond any
#: truncation distance, so a point and a mark of different classes never match, and far below the kernels'
#: "no candidate" sentinel, so they still rank below a match.
LABEL_SPACING_PX = 1e6


def _labels(what: str, labels, n: int) -> np.ndarray:
    a = np.asarray(labels)
    if a.shape != (n,) or not np.issubdtype(a.dtype, np.integer) or (n and a.min() < 0):
        raise ValueError(f"{what} must be {n} integers >= 0, got shape {a.shape} of {a.dtype}")
    return a.astype(np.int64)


def label_coordinates(model: Model, view: View) -> tuple[np.ndarray, np.ndarray]:
    """The third coordinate of a view's image points and of the model's marks in the matching kernels, shapes
    (P,) and (M,): ``label * LABEL_SPACING_PX`` when both the view and the model are labelled, zeros otherwise.
    Eq. (1)'s distance ``|p_i - m_j(s)|`` is then taken in (u, v, label) space: unchanged between points of one
    class, and beyond every truncation distance between classes (no derivative: the label does not move with
    the pose)."""
    if view.labels is None or model.labels is None:
        return np.zeros(len(view.points)), np.zeros(len(model.points))
    return view.labels * LABEL_SPACING_PX, model.labels * LABEL_SPACING_PX


@dataclass(frozen=True, eq=False)
class Bounds:
    """Box of admissible poses ``lo <= s <= hi``, shape (6,) each.

    An angle whose range spans a full turn is periodic (wrapped, not clipped).
    A parameter with ``lo == hi`` is fixed (eq. 3 with full reliability).
    """

    lo: np.ndarray
    hi: np.ndarray

    def __post_init__(self) -> None:
        lo = np.asarray(self.lo, dtype=float).reshape(-1)
        hi = np.asarray(self.hi, dtype=float).reshape(-1)
        if lo.shape != (6,) or hi.shape != (6,):
            raise ValueError(f"bounds need 6 values each, got {lo.shape} and {hi.shape}")
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise ValueError("bounds must be finite")
        bad = np.nonzero(lo > hi)[0]
        if len(bad):
            i = int(bad[0])
            raise ValueError(f"bounds of {PARAM_NAMES[i]}: lo {lo[i]} > hi {hi[i]}")
        object.__setattr__(self, "lo", lo)
        object.__setattr__(self, "hi", hi)

    @classmethod
    def from_dict(cls, ranges: dict[str, tuple[float, float]]) -> "Bounds":
        """Bounds from ``{"x": (lo, hi), ...}``; x, y, z are required, missing angles span a full turn."""
        missing = [n for n in PARAM_NAMES[:3] if n not in ranges]
        if missing:
            raise ValueError(f"search range missing for {', '.join(missing)}")
        lo = np.array([-np.pi] * 6)
        hi = np.array([np.pi] * 6)
        for name, (a, b) in ranges.items():
            if name not in PARAM_NAMES:
                raise ValueError(f"unknown pose parameter {name!r}; expected one of {', '.join(PARAM_NAMES)}")
            i = PARAM_NAMES.index(name)
            lo[i], hi[i] = a, b
        return cls(lo, hi)

    @property
    def periodic(self) -> np.ndarray:
        """Bool mask (6,): angles searched over a full turn."""
        mask = np.zeros(6, bool)
        idx = list(ANGLE_PARAMS)
        mask[idx] = (self.hi[idx] - self.lo[idx]) >= TWO_PI - 1e-9
        return mask

    @property
    def free(self) -> np.ndarray:
        """Bool mask (6,): parameters the search may change."""
        return self.hi > self.lo

    @property
    def width(self) -> np.ndarray:
        return self.hi - self.lo

    def constrained(self, name: str, value: float, tolerance: float) -> "Bounds":
        """Eq. (3): hold parameter ``name`` within ``[value - tolerance, value + tolerance]``.

        The result is the intersection with the search box; angles are compared modulo a full turn.
        """
        if tolerance < 0 or not np.isfinite(tolerance) or not np.isfinite(value):
            raise ValueError(f"constraint on {name}: tolerance must be finite and >= 0, value finite")
        i = PARAM_NAMES.index(name)
        lo, hi = self.lo.copy(), self.hi.copy()
        c_lo, c_hi = value - tolerance, value + tolerance
        if i in ANGLE_PARAMS:
            if self.periodic[i]:
                lo[i], hi[i] = c_lo, c_hi
                return Bounds(lo, hi)
            # shift the constraint by whole turns to overlap the box
            shift = TWO_PI * np.round(((lo[i] + hi[i]) / 2 - value) / TWO_PI)
            c_lo, c_hi = c_lo + shift, c_hi + shift
        new_lo, new_hi = max(lo[i], c_lo), min(hi[i], c_hi)
        if new_lo > new_hi:
            raise ValueError(f"constraint on {name} ({value} +- {tolerance}) lies outside its search range "
                             f"[{self.lo[i]}, {self.hi[i]}]")
        lo[i], hi[i] = new_lo, new_hi
        return Bounds(lo, hi)

    def project(self, s: np.ndarray) -> np.ndarray:
        """Bring poses into the box: wrap periodic angles, take the other angles to the turn nearest
        the box, clip the rest. Shape (..., 6)."""
        s = self.nearest_turn(s)
        per = self.periodic
        s[..., per] = self.lo[per] + (s[..., per] - self.lo[per]) % TWO_PI
        keep = ~per
        s[..., keep] = np.clip(s[..., keep], self.lo[keep], self.hi[keep])
        return s

    def nearest_turn(self, s: np.ndarray) -> np.ndarray:
        """Copy of poses (..., 6) whose angles are shifted by whole turns towards the box's middle."""
        s = np.array(s, dtype=float, copy=True)
        idx = list(ANGLE_PARAMS)
        mid = 0.5 * (self.lo[idx] + self.hi[idx])
        s[..., idx] += TWO_PI * np.round((mid - s[..., idx]) / TWO_PI)
        return s

    def contains(self, s: np.ndarray, atol: float = 1e-9) -> np.ndarray:
        """Whether poses (..., 6) lie in the box (angles compared modulo a full turn)."""
        s = self.nearest_turn(s)
        inside = (s >= self.lo - atol) & (s <= self.hi + atol)
        inside[..., self.periodic] = True
        return np.all(inside, axis=-1)

    def uniform(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` poses uniform in the box, shape (n, 6)."""
        return self.lo + rng.random((n, 6)) * self.width


@dataclass(frozen=True, eq=False)
class PoseProblem:
    """Everything the search needs.

    Attributes
    ----------
    model : Model
    views : tuple of View
        One or more cameras (eq. 4).
    bounds : Bounds
        Search box with the eq. (3) constraints already applied.
    hints : array, shape (H, 6)
        External full poses (hint individuals); may be empty.
    """

    model: Model
    views: tuple[View, ...]
    bounds: Bounds
    hints: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))

    def __post_init__(self) -> None:
        views = tuple(self.views)
        if not views:
            raise ValueError("a pose problem needs at least one view")
        object.__setattr__(self, "views", views)
        h = np.asarray(self.hints, dtype=float).reshape(-1, 6) if np.size(self.hints) else np.zeros((0, 6))
        if not np.all(np.isfinite(h)):
            raise ValueError("hints must be finite")
        object.__setattr__(self, "hints", h)

    def with_views(self, views) -> "PoseProblem":
        return PoseProblem(self.model, tuple(views), self.bounds, self.hints)

    def with_hints(self, hints: np.ndarray) -> "PoseProblem":
        return PoseProblem(self.model, self.views, self.bounds, hints)
