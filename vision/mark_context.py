"""Which telephoto spots are marks, from their context: a fitted model over what surrounds each spot (the default).

Where marks are 3 px and more (:data:`vision.spot_position.SMALL_SPOT_PX`) the contrast front-end
(:mod:`vision.blobs`) can keep a spot by a cascade of hand-set bars (``scorer="bars"``), each chosen on the
Pioneer: a ring of the body's paint around it, one paint it stands out from all round, the marks' common scale and contrast
(:mod:`vision.mark_selection`). On robots it never met those bars cost precision: 12 random robots at telephoto
(``benchmarks/random_bodies.py``) through the named looks, recall 0.74-0.84 / precision 0.75-0.91; the second
robot 0.62-0.90 / 0.27-0.74. The same measures weighed together by a logistic model on their quadratic expansion
(:class:`vision.mark_scorer.MarkScorer`, ``evopose train-scorer --scale telephoto``), fitted on the Pioneer's
telephoto training worlds and the random robots through random looks, its threshold keeping 98 % of their marks
(the issue's recall bar) with each geometry held out, raised precision on worlds it never saw (BENCHMARKS.md, "The
telephoto context model beside the hand-set bars"): the second robot +4.7 to +20 points in every named look, at a
recall 5.6 points lower through AgX and ``hable-faded``. Real agents weighed that trade (BENCHMARKS.md, "the
telephoto context model as the default, side by side"): on the second robot through ``flat-cool`` good on 36 of 48
frames against the bars' 29-31, one frame fewer through ``vivid-warm``, the rest a frame either way. So it is the
default (``detect_contrast_marks(..., scorer="shipped")``); ``scorer="bars"``, ``evopose agent --mark-scorer bars``,
asks for the bars.

The shipped model is fitted on marks placed at their whole blob's centre (:func:`vision.spot_position.blob_centroids`),
its two rings (``paint_around``, ``surrounded``) following an oblique mark's blob along its length
(:mod:`vision.spot_outline`: a ring of the spot's radius crossed a 4:1 mark and read its own colour as no paint), at a
keep of 0.99 (chosen on development robots, after the second robot's figures at 0.98 were seen; the comparisons
above are of earlier fits). On what it was never fitted on (BENCHMARKS.md, "context rings along an oblique mark"):
the second robot at telephoto recall 0.82-0.96, precision 0.90-0.98 through the named looks (0.87-0.96 with the label
rules chosen since on its worlds through corner looks: BENCHMARKS.md, "the lit-paint share", "a dark paint's fit"),
six random robots outside its fit recall 0.82-0.93, precision 0.82-0.92, the Pioneer's benchmark worlds recall
0.94-1.00 / precision 0.90-0.99.

Every measure is relative to the spot itself, to the others of its image or to the target's extent, never a
colour: one model serves any robot and palette. Shapes: points (K, 2) pixels ``(u, v)``, per-spot arrays (K,).
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from .body_paint import paint_around
from .mark_scorer import MarkScorer, feature_names, load, shipped
from .mark_selection import surrounded

#: The context model's measures of a spot (:func:`context_features`), in this order.
CONTEXT_FEATURES = (
    "paint_around",        # share of a 1 px ring 1-3 px outside the spot that is the body's paint (the best gap)
    "surrounded",          # share of 16 directions in which the spot's surroundings are their usual colour
    "log_scale_ratio",     # log of its radius over the marks' scale (the contrast-weighted median radius)
    "log_contrast_ratio",  # log of its contrast over the strong spots' (the 80th percentile)
    "label_misfit",        # its fitted paint colour's misfit (vision.spot_label)
    "label_confidence",    # the margin of its label over the next
    "depth_radii",         # its centre's depth in the body's silhouette, in its radii (capped at 5)
    "log_contrast",        # log of its contrast over its level's threshold
    "log_radius_extent",   # log of its radius over the target's extent in pixels
    "nearest_radii",       # the nearest other spot, in its radii (capped at 10)
)
#: The shipped context model (``evopose train-scorer --scale telephoto``; the default, see the module's docstring).
SHIPPED_CONTEXT = Path(__file__).with_name("mark_context.json")


def context_features(lab: np.ndarray, paint: np.ndarray, depth: np.ndarray, points: np.ndarray,
                     radius: np.ndarray, contrast: np.ndarray, misfit: np.ndarray, confidence: np.ndarray,
                     ring_gaps: tuple[float, ...], extent_px: float, long_axis: np.ndarray | None = None
                     ) -> np.ndarray:
    """The :data:`CONTEXT_FEATURES` (K, 10) of the spots at ``points`` of ``radius``, ``contrast``, label
    ``misfit`` and ``confidence`` in an image whose CIE Lab is ``lab`` (H, W, 3) float32, the body's paint ``paint``
    (H, W) bool and each pixel's depth into the body's closed silhouette ``depth`` (H, W) px (its distance
    transform); the paint ring's share is the best of the rings ``ring_gaps`` px beyond each radius; ``extent_px``
    the target's largest extent in pixels; ``long_axis`` (K, 2) each spot's blob's long half-axis, which the rings
    follow (:mod:`vision.spot_outline`; None: round spots)."""
    points = np.asarray(points, float).reshape(-1, 2)
    radius, contrast = np.asarray(radius, float), np.asarray(contrast, float)
    if not len(points):
        return np.zeros((0, len(CONTEXT_FEATURES)))
    share = paint_around(paint, points, radius, ring_gaps, long_axis)
    around = surrounded(lab, points, radius, long_axis=long_axis)
    order = np.argsort(radius)
    weight = np.cumsum(contrast[order] ** 2)
    scale = float(radius[order][np.searchsorted(weight, 0.5 * weight[-1])])
    strong = float(np.quantile(contrast, 0.8))
    u = np.clip(np.rint(points[:, 0]).astype(int), 0, depth.shape[1] - 1)
    v = np.clip(np.rint(points[:, 1]).astype(int), 0, depth.shape[0] - 1)
    apart = np.hypot(*(points[:, None, :] - points[None, :, :]).transpose(2, 0, 1))
    np.fill_diagonal(apart, np.inf)
    nearest = apart.min(axis=1) / radius if len(points) > 1 else np.full(len(points), np.inf)
    return np.stack([share, around, np.log(radius / scale), np.log(np.maximum(contrast, 1e-6) / max(strong, 1e-6)),
                     np.asarray(misfit, float), np.asarray(confidence, float), np.minimum(depth[v, u] / radius, 5.0),
                     np.log(np.maximum(contrast, 1e-6)), np.log(radius / max(extent_px, 1.0)),
                     np.minimum(nearest, 10.0)], axis=1)


def is_context_model(scorer: object) -> bool:
    """Whether ``scorer`` is a context model (its features are :data:`CONTEXT_FEATURES`), not a small-spot one."""
    return isinstance(scorer, MarkScorer) and scorer.names == CONTEXT_FEATURES


@lru_cache(maxsize=1)
def shipped_context() -> MarkScorer | None:
    """The shipped context model, read once (None when the file is absent)."""
    return load(SHIPPED_CONTEXT) if SHIPPED_CONTEXT.is_file() else None


#: The names ``scorer`` takes beside a :class:`MarkScorer` (see :func:`vision.blobs.detect_contrast_marks`).
SCORER_NAMES = ("shipped", "bars", "all")


def resolve_scorers(scorer: MarkScorer | str | None, names: tuple[str, ...]
                    ) -> tuple[MarkScorer | str | None, MarkScorer | str | None]:
    """The small-spot scorer and the context model that ``scorer`` names for a palette of ``names`` (None: the
    hand-set bars there; see :func:`vision.blobs.detect_contrast_marks`). A model given replaces the shipped one of
    its kind and keeps the other; the shipped small-spot scorer serves any palette whose features it was fitted on
    (else the bars). ValueError for an unknown name or a small-spot scorer fitted on other features."""
    if isinstance(scorer, str) and scorer not in SCORER_NAMES:
        raise ValueError(f"scorer must be a MarkScorer, {', '.join(map(repr, SCORER_NAMES))} or None, got {scorer!r}")
    if scorer is None or scorer == "bars":
        return None, None
    if scorer == "all":
        return "all", "all"
    context = scorer if is_context_model(scorer) else shipped_context()
    if scorer == "shipped" or is_context_model(scorer):
        fitted = shipped()
        return (fitted if fitted is not None and fitted.names == feature_names(names) else None), context
    if scorer.names != feature_names(names):
        raise ValueError(f"the mark scorer was fitted on the features {', '.join(scorer.names)}; the front-end "
                         f"computes {', '.join(feature_names(names))}")
    return scorer, context


__all__ = ["CONTEXT_FEATURES", "SCORER_NAMES", "SHIPPED_CONTEXT", "context_features", "is_context_model",
           "resolve_scorers", "shipped_context"]
