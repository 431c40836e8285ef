"""Which 2-4 px candidate spots are marks: a scorer fitted on rendered frames with known marks.

At the paper's scale (docs/design.md, "The feature front-end") a mark is 2-4 px of paint, 3-5 px from the next,
its chroma halved by the encoder. No single test separates it from the body's own detail (a glossy edge, a seam,
the shading beside a wheel): each of the front-end's measures (the spot's contrast, the share of its deviation
its paint colour explains, the body paint around it, its step in luminance) alone ranks marks above the rest with
an area under the ROC curve of 0.75-0.87. Together they do better, so the front-end takes its small candidates
with lenient bars and this scorer keeps those a logistic model of the measures calls marks:

    p = 1 / (1 + exp(-(w . q(z) + b))),   z = (f - mean) / scale,   q(z) = (z, z_i z_j for i <= j)

on the :data:`FEATURES` of each candidate. The model is fitted (:func:`fit`, L2-regularised maximum likelihood) by
``evopose train-scorer`` on datasets whose truth gives each mark's projection: a candidate within the match radius
of a mark's projected centre is a mark. The shipped model (``mark_scorer.json``) was fitted on the Pioneer's
training worlds of ``benchmarks/photoreal_worlds.py --set train`` (other helicopter positions and suns than the
benchmark's), the 12 recoloured robots of ``--set palettes`` (the Pioneer's shape, random body and mark paints)
and the 12 random robots of ``--set bodies`` (other shapes, with dark wheels, bumpers and top plates beside their
paint: benchmarks/random_bodies.py), each frame also developed through two random camera looks (``--looks 2
--seed 1``), and is measured on the benchmark's worlds through the named looks and on the second robot, whose
frames it never saw. The random bodies were added after the second robot's false points were seen to lie at its
dark parts, so that kind of body is not held out. Against the fit without them (``bench_photoreal_looks.py
--scorer --front-ends contrast``, paper scale, 3 frames, side by side): the second robot's precision +1.6 to +7.7
points through the eight named looks (its reference look 0.281 -> 0.326), recall -0.5 to -2.9 points; the
Pioneer's recall -0.7 to +0.8 points, precision -1.6 to +1.9 points.

The scorer knows nothing of a scene's particular numbers or of a palette: its measures are ratios (contrast over
the image's own noise, shares, pixels at the mark's scale) and differences taken along the direction from the
body's paint to the spot's labelled paint, so one scorer serves any marked target; a camera unlike the
renderer's (another sensor or encoder) may need its own fit from frames with known marks.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from .body_paint import paint_around
from .spot_colour import ring_colours, to_ycrcb

#: The measures of a candidate spot, in the order of a feature row. Every one is relative to the image, the body's
#: paint or the spot's own label, never an absolute colour, so that one scorer serves any palette on any body: the
#: colours enter only as the direction from the body's paint to the labelled paint (``toward``; ``across``: the
#: rest of the difference).
FEATURES = (
    "log_contrast",        # log of the response over the level's threshold (blobs: k_sigma robust spreads)
    "label_confidence",    # 1 - best colour's misfit over the second's (vision.spot_colour)
    "radius_px",           # the scale's mark radius
    "explained",           # share of the spot's deviation from its ring its colour explains (spot_colour)
    "explained_second",    # the same for the second-best colour
    "misfit",              # the best colour's residual, 8-bit Y Cr Cb units
    "misfit_ratio",        # second-best colour's misfit over the best's
    "paint_around",        # share of the ring 1-2 px outside the spot that is body paint (glossy faces included)
    "sure_paint_around",   # the same, only the sure paint
    "luma_step_toward",    # spot minus ring, Y (8-bit), signed towards the label's paint (a dark paint: - step)
    "chroma_step",         # |spot minus ring| in Cr Cb (8-bit)
    "neighbours",          # other candidates within NEIGHBOUR_PX
    "relative_contrast",   # own contrast over the strongest within NEIGHBOUR_PX (1: the strongest)
    "nearest_px",          # distance to the nearest other candidate (at most FAR_PX)
    "from_centre",         # distance from the candidates' weighted centre over the target's extent in pixels
    "paint_depth_px",      # signed distance to the sure paint's outline (inside positive)
    "dog_fine_toward", "dog_fine_across",   # L*a*b* at the spot's scale minus 1.26x that scale: along the body ->
    "dog_wide_toward", "dog_wide_across",   # label paint direction and the rest; the same against 3x that scale
    "log_edge_ratio",      # log of tr(H)^2 / det(H) of the fine difference's Hessian (4: a round spot; an edge: large)
)
#: The edge ratio's cap (a saddle or an edge: det(H) <= 0).
MAX_EDGE_RATIO = 100.0
#: Candidates this close count as one another's neighbours (pixels), and the nearest distance is capped here.
NEIGHBOUR_PX, FAR_PX = 3.5, 20.0
#: Where the model file lies.
SHIPPED = Path(__file__).with_name("mark_scorer.json")
#: A standardised feature is held within this many standard deviations before it is scored: the quadratic model
#: knows nothing past the data it was fitted on, and extrapolated it can turn over (a clean, noise-free image's
#: contrast 14 sd over the fitted mean scored a plain mark 6e-6). Set after reading the committed camera frames'
#: range (6.6 sd at the paper's scale, 3.4 at telephoto), so not held out from them; no output of theirs moved.
Z_LIMIT = 6.0


def blur_box(px: np.ndarray, sigma: float, width: int, height: int) -> tuple[int, int, int, int]:
    """The box ``(x0, y0, x1, y1)`` (ends excluded) of an image ``width`` x ``height`` that holds pixels ``px`` (N, 2)
    (u, v) with their 3 x 3 neighbourhoods and every pixel a Gaussian blur of ``sigma`` or less reaches from them
    (OpenCV's kernel for float images reaches 4 sigma): a blur of the box equals the whole image's there."""
    reach = int(np.ceil(4 * sigma)) + 2
    x0, y0 = np.maximum(px.min(axis=0) - reach, 0)
    x1, y1 = np.minimum(px.max(axis=0) + reach + 1, [width, height])
    return int(x0), int(y0), int(x1), int(y1)


def candidate_features(bgr: np.ndarray, lab: np.ndarray, points: np.ndarray, radius: np.ndarray,
                       contrast: np.ndarray, labels: np.ndarray, confidence: np.ndarray, misfit: np.ndarray,
                       explained: np.ndarray, paint: np.ndarray, sure: np.ndarray, extent_px: float,
                       palette_bgr: np.ndarray, body_bgr: tuple[int, int, int]) -> np.ndarray:
    """The :data:`FEATURES` of K candidates, (K, len(FEATURES)).

    ``bgr`` (H, W, 3) uint8 and ``lab`` (H, W, 3) float32 L*a*b* of the same crop; ``points`` (K, 2) (u, v) px,
    ``radius`` (K,) px, ``contrast`` (K,) over the threshold; ``labels`` (K,) in [0, C), ``confidence`` (K,);
    ``misfit`` and ``explained`` (K, C) of :func:`vision.spot_colour.spot_misfits`; ``paint`` and ``sure``
    (H, W) bool: the body's paint with its glossy faces and the sure paint; ``extent_px`` the target's extent;
    ``palette_bgr`` (C, 3) uint8 the paint colours, ``body_bgr`` the body's."""
    k, c = misfit.shape
    rows = np.arange(k)
    out = np.zeros((k, len(FEATURES)))
    if k == 0:
        return out
    # the direction from the body's paint to each labelled paint, unit (C, 3) in L*a*b* and its sign in luma
    paints = np.vstack([np.asarray(palette_bgr, np.uint8).reshape(-1, 3), np.asarray(body_bgr, np.uint8)[None]])
    paint_lab = cv2.cvtColor(paints[None].astype(np.float32) / 255.0, cv2.COLOR_BGR2Lab)[0]
    towards = paint_lab[:-1] - paint_lab[-1]
    towards /= np.maximum(np.linalg.norm(towards, axis=1, keepdims=True), 1e-9)
    darker = np.sign(to_ycrcb(paints)[:-1, 0] - to_ycrcb(paints)[-1, 0])          # (C,): +1 a lighter paint
    order = np.sort(np.where(np.isfinite(misfit), misfit, 1e3), axis=1)
    second = order[:, 1] if c > 1 else order[:, 0]
    ycc = to_ycrcb(bgr)
    h, w = bgr.shape[:2]
    px = np.clip(np.round(points).astype(int), 0, [w - 1, h - 1])
    step = ycc[px[:, 1], px[:, 0]] - ring_colours(ycc, points, radius)
    apart = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=2)
    np.fill_diagonal(apart, np.inf)
    near = apart < NEIGHBOUR_PX
    strongest = np.where(near, contrast[None, :], 0.0).max(axis=1)
    centre = np.average(points, axis=0, weights=np.minimum(contrast, 3.0))
    sure8 = sure.astype(np.uint8)
    depth = (cv2.distanceTransform(sure8, cv2.DIST_L2, 3) - cv2.distanceTransform(1 - sure8, cv2.DIST_L2, 3))
    dog = np.zeros((k, 7))
    sigma = np.maximum(radius / np.sqrt(2), 0.5)
    inner = np.clip(px, 1, [w - 2, h - 2])
    for s in np.unique(sigma):
        at = np.nonzero(sigma == s)[0]
        # blurred over the spots' box, not the whole crop: the same values at the spots, a fraction of the pixels
        x0, y0, x1, y1 = blur_box(px[at], 3.0 * float(s), w, h)
        box = lab[y0:y1, x0:x1]
        blurred = cv2.GaussianBlur(box, (0, 0), float(s))
        fine = blurred - cv2.GaussianBlur(box, (0, 0), float(s) * 1.26)
        bx, by = px[at, 0] - x0, px[at, 1] - y0
        dog[at, :3] = fine[by, bx]
        dog[at, 3:6] = blurred[by, bx] - cv2.GaussianBlur(box, (0, 0), float(s) * 3.0)[by, bx]
        x, y = inner[at, 0] - x0, inner[at, 1] - y0
        d = fine[y, x] / np.maximum(np.linalg.norm(fine[y, x], axis=1, keepdims=True), 1e-9)       # (N, 3)
        oy, ox = np.mgrid[-1:2, -1:2]
        patch = np.einsum("nijc,nc->nij", fine[y[:, None, None] + oy, x[:, None, None] + ox], d)   # (N, 3, 3)
        dxx = patch[:, 1, 2] - 2 * patch[:, 1, 1] + patch[:, 1, 0]
        dyy = patch[:, 2, 1] - 2 * patch[:, 1, 1] + patch[:, 0, 1]
        dxy = (patch[:, 2, 2] - patch[:, 2, 0] - patch[:, 0, 2] + patch[:, 0, 0]) / 4
        det = dxx * dyy - dxy * dxy
        ratio = (dxx + dyy) ** 2 / np.where(det > 1e-12, det, 1.0)
        dog[at, 6] = np.log(np.where(det > 1e-12, np.minimum(ratio, MAX_EDGE_RATIO), MAX_EDGE_RATIO))
    toward = towards[labels]                                                        # (K, 3)
    relative = []
    for diff in (dog[:, 0:3], dog[:, 3:6]):
        along = np.einsum("kc,kc->k", diff, toward)
        relative += [along, np.linalg.norm(diff - along[:, None] * toward, axis=1)]
    out[:] = np.column_stack([
        np.log(np.maximum(contrast, 1e-6)), confidence, radius, explained[rows, labels],
        np.sort(explained, axis=1)[:, -2] if c > 1 else 0.0, order[:, 0], np.minimum(second / np.maximum(
            order[:, 0], 1e-9), 10.0), paint_around(paint, points, radius), paint_around(sure, points, radius),
        step[:, 0] * np.where(darker[labels] < 0, -1.0, 1.0), np.linalg.norm(step[:, 1:], axis=1), near.sum(axis=1),
        contrast / np.maximum(strongest, contrast), np.minimum(apart.min(axis=1), FAR_PX),
        np.linalg.norm(points - centre, axis=1) / max(extent_px, 1e-9), depth[px[:, 1], px[:, 0]],
        *relative, dog[:, 6]])
    return out


def feature_names(colours: tuple[str, ...]) -> tuple[str, ...]:
    """The columns of :func:`candidate_features`: the same for every palette of ``colours`` (the features are
    relative to the body's paint and the spot's label, :data:`FEATURES`)."""
    return FEATURES


def quadratic(z: np.ndarray) -> np.ndarray:
    """``z`` (K, F) and its products ``z_i z_j`` for i <= j: (K, F + F (F + 1) / 2)."""
    i, j = np.triu_indices(z.shape[1])
    return np.concatenate([z, z[:, i] * z[:, j]], axis=1)


@dataclass(frozen=True)
class MarkScorer:
    """A fitted logistic model on the quadratic expansion of standardised features (see the module docstring).

    ``names``: the feature columns (:data:`FEATURES` and ``label_<colour>``); ``mean``, ``scale`` (F,): the
    standardisation; ``weights`` (F + F (F + 1) / 2,), ``bias``; ``threshold``: the probability a mark must reach;
    ``fitted_on``: what it was fitted on (a sentence)."""

    names: tuple[str, ...]
    mean: np.ndarray
    scale: np.ndarray
    weights: np.ndarray
    bias: float
    threshold: float
    fitted_on: str = ""

    def __post_init__(self) -> None:
        f = len(self.names)
        if self.mean.shape != (f,) or self.scale.shape != (f,) or self.weights.shape != (f + f * (f + 1) // 2,):
            raise ValueError(f"mark scorer: {f} features need mean and scale ({f},) and weights "
                             f"({f + f * (f + 1) // 2},), got {self.mean.shape}, {self.scale.shape}, "
                             f"{self.weights.shape}")
        if not 0.0 < self.threshold < 1.0:
            raise ValueError(f"mark scorer: threshold must lie in (0, 1), got {self.threshold}")

    def probability(self, features: np.ndarray) -> np.ndarray:
        """Each candidate's probability of being a mark, (K,) from ``features`` (K, F)."""
        features = np.asarray(features, float)
        if features.ndim != 2 or features.shape[1] != len(self.names):
            raise ValueError(f"mark scorer: expected (K, {len(self.names)}) features, got {features.shape}")
        z = np.clip((features - self.mean) / self.scale, -Z_LIMIT, Z_LIMIT)
        return 1.0 / (1.0 + np.exp(-np.clip(quadratic(z) @ self.weights + self.bias, -50.0, 50.0)))

    def marks(self, features: np.ndarray) -> np.ndarray:
        """Which candidates are marks, bool (K,)."""
        return self.probability(features) >= self.threshold

    def to_dict(self) -> dict:
        return {"format": "evopose-mark-scorer/1", "names": list(self.names), "mean": self.mean.tolist(),
                "scale": self.scale.tolist(), "weights": self.weights.tolist(), "bias": self.bias,
                "threshold": self.threshold, "fitted_on": self.fitted_on}

    @classmethod
    def from_dict(cls, doc: dict) -> MarkScorer:
        if not isinstance(doc, dict):
            raise ValueError(f"mark scorer: expected a JSON object, got {type(doc).__name__}")
        if doc.get("format") != "evopose-mark-scorer/1":
            raise ValueError(f"mark scorer: format must be 'evopose-mark-scorer/1', got {doc.get('format')!r}")
        missing = [k for k in ("names", "mean", "scale", "weights", "bias", "threshold") if k not in doc]
        if missing:
            raise ValueError(f"mark scorer: missing field {missing[0]!r}")
        names = doc["names"]
        if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
            raise ValueError("mark scorer: field names: expected a list of feature names")
        f = len(names)

        def numbers(key: str, what: str, ndim: int) -> np.ndarray:
            try:
                values = np.asarray(doc[key], float)
            except (TypeError, ValueError):
                values = None
            if values is None or values.ndim != ndim or not np.all(np.isfinite(values)):
                raise ValueError(f"mark scorer: field {key}: expected {what}, got {str(doc[key])[:40]}")
            return values

        vector = f"{f} numbers"
        return cls(tuple(names), numbers("mean", vector, 1), numbers("scale", vector, 1),
                   numbers("weights", f"{f + f * (f + 1) // 2} numbers", 1), float(numbers("bias", "a number", 0)),
                   float(numbers("threshold", "a number", 0)), str(doc.get("fitted_on", "")))

    def save(self, path: Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=1) + "\n", encoding="utf-8")


def load(path: Path = SHIPPED) -> MarkScorer:
    """The scorer in ``path`` (the shipped one by default)."""
    return MarkScorer.from_dict(json.loads(Path(path).read_text(encoding="utf-8")))


_shipped: MarkScorer | None = None


def shipped() -> MarkScorer:
    """The shipped scorer, read once."""
    global _shipped
    if _shipped is None:
        _shipped = load(SHIPPED)
    return _shipped


def fit(features: np.ndarray, is_mark: np.ndarray, names: tuple[str, ...], *, l2: float = 1.0,
        groups: np.ndarray | None = None, keep: float | None = None, threshold: float | None = None,
        fitted_on: str = "") -> MarkScorer:
    """Fit a :class:`MarkScorer` to ``features`` (K, F) and ``is_mark`` (K,) bool: L2-penalised (``l2`` on every
    weight but the bias) logistic regression on the quadratic expansion, by L-BFGS.

    ``threshold`` None: with ``keep``, the highest probability that keeps at least that share of the marks; without,
    where the share of marks kept equals the precision of what is kept (:func:`break_even`). Either on held-out
    data when ``groups`` (K,) names the candidates' worlds: each group scored by a model fitted on the others (a
    world's frames are alike; a model is over-confident on the frames it was fitted on), else on the fitting
    data."""
    x = np.asarray(features, float)
    y = np.asarray(is_mark, bool)
    if x.ndim != 2 or x.shape != (len(y), len(names)) or len(y) < 10 or y.min() == y.max():
        raise ValueError(f"fit needs (K, {len(names)}) features of both classes, got {x.shape} and "
                         f"{int(y.sum())} marks of {len(y)}")
    scorer = _fit(x, y, names, l2, fitted_on)
    if threshold is None:
        held_out = scorer.probability(x)
        if groups is not None and len(set(np.asarray(groups).tolist())) > 1:
            groups = np.asarray(groups)
            for g in set(groups.tolist()):
                out = groups == g
                if y[~out].min() != y[~out].max():
                    held_out[out] = _fit(x[~out], y[~out], names, l2, "").probability(x[out])
        threshold = break_even(held_out, y) if keep is None else keeping(held_out, y, keep)
    return MarkScorer(scorer.names, scorer.mean, scorer.scale, scorer.weights, scorer.bias, float(threshold),
                      fitted_on)


def break_even(probability: np.ndarray, is_mark: np.ndarray) -> float:
    """The threshold (0.05-0.95) where the share of marks kept and the precision of the kept are nearest."""
    grid = np.linspace(0.05, 0.95, 91)
    gap = [abs(np.mean(probability[is_mark] >= t) - np.mean(is_mark[probability >= t]))
           if np.any(probability >= t) else np.inf for t in grid]
    return float(grid[int(np.argmin(gap))])


def keeping(probability: np.ndarray, is_mark: np.ndarray, share: float) -> float:
    """The highest threshold (0.01-0.95) that keeps at least ``share`` of the marks."""
    grid = np.linspace(0.01, 0.95, 95)
    kept = np.array([np.mean(probability[is_mark] >= t) for t in grid])
    return float(grid[np.nonzero(kept >= share)[0].max()]) if np.any(kept >= share) else float(grid[0])


def _fit(x: np.ndarray, y: np.ndarray, names: tuple[str, ...], l2: float, fitted_on: str) -> MarkScorer:
    from scipy.optimize import minimize

    mean, scale = x.mean(axis=0), x.std(axis=0)
    scale = np.where(scale > 1e-9, scale, 1.0)
    q = quadratic((x - mean) / scale)
    target = y.astype(float)

    def loss(w: np.ndarray) -> tuple[float, np.ndarray]:
        z = q @ w[:-1] + w[-1]
        p = 1.0 / (1.0 + np.exp(-np.clip(z, -50.0, 50.0)))
        nll = float(np.sum(np.logaddexp(0.0, z) - target * z))
        grad = np.append(q.T @ (p - target) + 2 * l2 * w[:-1], np.sum(p - target))
        return nll + l2 * float(w[:-1] @ w[:-1]), grad

    w = minimize(loss, np.zeros(q.shape[1] + 1), jac=True, method="L-BFGS-B", options={"maxiter": 5000}).x
    return MarkScorer(tuple(names), mean, scale, w[:-1], float(w[-1]), 0.5, fitted_on)


__all__ = ["FEATURES", "MarkScorer", "blur_box", "break_even", "candidate_features", "feature_names", "fit", "keeping",
           "load", "quadratic", "shipped"]
