"""Which of a front-end's spots are the target's marks (:mod:`vision.blobs`): one per mark's disc, one scale, ringed
by one paint, one cluster. A target's marks do not overlap, share a scale and a paint at one distance, stand out
from the face they are painted on, and lie within its extent; what a camera's look, the ground's texture, the
body's shading or its outline adds does not.

Points are pixels ``(u, v)``, shape (K, 2); scores, radii and contrasts (K,).
"""

from __future__ import annotations

import numpy as np

from .spot_position import coverage_centroids
from .spot_outline import outline_radius

#: Where marks are 3 px and more: least radius of a spot as a share of the marks' own scale (:func:`one_scale`).
SCALE_CONSENSUS = 0.55
#: ... and least contrast as a share of the strong spots' (the 80th percentile): a target's marks are painted
#: alike, what a look or the ground's texture adds is weak (telephoto-g1-high through flat-cool and hable-faded, and
#: the Husky's frames, a one-off analysis: marks 1.6-9, specks 1.0-2.7).
RELATIVE_CONTRAST = 0.35
#: Two peaks of one label this many of their larger radius apart, or nearer, may be one oblique mark's two ends
#: (:func:`one_mark_between`): a disc at 75 deg from its normal is ~4 times as long as wide.
ONE_MARK_REACH = 4.0
#: ... when the colour between them is mostly the mark's (its share on the line paint -> mark) and near that line.
#: Set by hand, then tried on the telephoto training worlds t1, t2 through 16 random looks (``bench_photoreal_looks
#: --random-looks 16 --frames 2 --front-ends contrast``): reach 3-5 and cover 0.5 / 0.7 gave precision 0.9749-0.9758
#: (0.9715 without the rule), recall 0.9785 throughout; never tuned on a named look's frames beyond the Pioneer's
#: reference look (BENCHMARKS.md says which looks are held out).
MIN_COVER_BETWEEN, MAX_ACROSS_BETWEEN = 0.6, 0.3


def one_per_disc(pts: np.ndarray, score: np.ndarray, disc_radius_px: float) -> np.ndarray:
    """Indices (sorted) of the candidates ``pts`` (K, 2) kept when each mark's disc yields one: in order of
    ``score`` (K,), a candidate closer than ``disc_radius_px`` to a kept one is dropped.

    Two marks of the model do not overlap, so two candidates within one mark's radius of each other are one
    mark seen twice: a 2-4 px mark peaks in several channels and scales a pixel or two apart (the channel peaks
    of :func:`vision.blobs._detect`), and the copy counts once more in eq. 1's sum, pulling the pose towards its offset
    centre. Cycles paper-scale sweep (benchmarks/bench_photoreal_features.py, 9 worlds): visible marks'
    projections lie 3.0 px or more apart, while 70 of 234 false detections lay within 2 px of another
    detection."""
    order = np.argsort(-np.asarray(score, float), kind="stable")
    taken: list[int] = []
    for i in order.tolist():
        if not taken or np.min(np.hypot(*(pts[taken] - pts[i]).T)) >= disc_radius_px:
            taken.append(i)
    return np.array(sorted(taken), int)


def one_scale(radius: np.ndarray, contrast: np.ndarray, share: float = SCALE_CONSENSUS) -> np.ndarray:
    """Indices (sorted) of the spots whose ``radius`` (K,) is at least ``share`` of the marks' own scale: the median
    radius of the spots weighed by their ``contrast`` (K,) squared (the marks stand out; specks are many but weak),
    and whose contrast is at least :data:`RELATIVE_CONTRAST` of the strong spots'.

    The prior's radius range spans the whole operating area and every facing (2.5-12 px at telephoto), while the
    marks of one target at one distance share a radius within their foreshortening (a disc at 70 deg keeps ~0.6
    of its scale). What a camera's look adds on the body (its paint's JPEG blocks, noise made visible by a
    saturation gain, a grazing face's texture) peaks at the finest scales, weaker. Telephoto-g1-high through
    flat-cool (a one-off analysis, where 0.55 was chosen; that look is therefore not held out for this rule): true
    marks 4.7-9.4 px, false spots on the body 2.3-4.7 px."""
    radius, contrast = np.asarray(radius, float), np.asarray(contrast, float)
    order = np.argsort(radius)
    weight = np.cumsum(contrast[order] ** 2)   # the median radius weighed by contrast squared
    scale = float(radius[order][np.searchsorted(weight, 0.5 * weight[-1])])
    strong = float(np.quantile(contrast, 0.8))
    return np.nonzero((radius >= share * scale) & (contrast >= RELATIVE_CONTRAST * strong))[0]


def surrounded(lab: np.ndarray, pts: np.ndarray, radius: np.ndarray, directions: int = 16,
               long_axis: np.ndarray | None = None) -> np.ndarray:
    """The share of directions (float (K,)) in which what lies just outside each spot at ``pts`` (K, 2), 2 px beyond
    its outline (``radius`` (K,) px; drawn out along ``long_axis`` (K, 2), :mod:`vision.spot_outline`), is its
    surroundings' usual colour: within half the spot's contrast to them (the median over the directions) in ``lab``
    (H, W, 3) float CIE Lab. A mark is ringed by one paint that it stands out from; a contrast peak on an outline
    between two paints (its centre a blend of them) is not."""
    pts, radius = np.asarray(pts, float).reshape(-1, 2), np.asarray(radius, float).reshape(-1)
    if not len(pts):
        return np.zeros(0)
    angle = np.linspace(0.0, 2 * np.pi, directions, endpoint=False)
    unit = np.stack([np.cos(angle), np.sin(angle)], axis=1)                        # (D, 2)
    reach = outline_radius(np.broadcast_to(unit, (len(pts), directions, 2)), radius, long_axis) + 2.0
    around = _bilinear(lab, pts[:, 0:1] + reach * unit[None, :, 0],
                       pts[:, 1:2] + reach * unit[None, :, 1])                    # (K, D, 3)
    centre = _bilinear(lab, pts[:, 0:1], pts[:, 1:2])                              # (K, 1, 3)
    usual = np.median(around, axis=1, keepdims=True)                               # (K, 1, 3)
    contrast = np.linalg.norm(centre - usual, axis=2)                              # (K, 1)
    return np.mean(np.linalg.norm(around - usual, axis=2) <= 0.5 * contrast, axis=1)


def _bilinear(image: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    h, w = image.shape[:2]
    u, v = np.clip(u, 0, w - 1.001), np.clip(v, 0, h - 1.001)
    x0, y0 = np.floor(u).astype(int), np.floor(v).astype(int)
    fx, fy = (u - x0)[..., None], (v - y0)[..., None]
    return ((1 - fx) * (1 - fy) * image[y0, x0] + fx * (1 - fy) * image[y0, x0 + 1]
            + (1 - fx) * fy * image[y0 + 1, x0] + fx * fy * image[y0 + 1, x0 + 1])


def same_spots(pts: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Whether each two peaks ``pts`` (K, 2) of ``radius`` (K,) are one spot, bool (K, K): within the larger radius
    (two scales of one disc), or a small peak on the rim of a much larger one (an oblique disc's ends, its
    anti-aliased outline)."""
    pts, radius = np.asarray(pts, float).reshape(-1, 2), np.asarray(radius, float).reshape(-1)
    k = len(pts)
    same = np.zeros((k, k), bool)
    if k == 0:
        return same
    # only pairs within the farthest reach along u can be one spot: found by sorting on u, not over all K^2 pairs
    # (hundreds of candidate peaks at the paper's scale); each pair's test is the same arithmetic
    reach = max(1.0, 2.6 * float(radius.max())) * (1 + 1e-9)
    order = np.argsort(pts[:, 0], kind="stable")
    u = pts[order, 0]
    lo, hi = np.searchsorted(u, u - reach, "left"), np.searchsorted(u, u + reach, "right")
    counts = hi - lo
    a = np.repeat(np.arange(k), counts)
    b = lo[a] + np.arange(len(a)) - np.repeat(np.cumsum(counts) - counts, counts)
    i, j = order[a], order[b]
    d = np.hypot(pts[i, 0] - pts[j, 0], pts[i, 1] - pts[j, 1])
    big, small = np.maximum(radius[i], radius[j]), np.minimum(radius[i], radius[j])
    same[i, j] = (d <= np.maximum(big, 1.0)) | ((big >= 1.8 * small) & (d < 1.3 * (big + small)))
    return same


def one_mark_between(lin: np.ndarray, pts: np.ndarray, radius: np.ndarray, labels: np.ndarray, spot: np.ndarray,
                     ring: np.ndarray) -> np.ndarray:
    """Whether each two peaks ``pts`` (K, 2) of one label ``labels`` (K,) are the two ends of one oblique mark, bool
    (K, K): within :data:`ONE_MARK_REACH` of their larger ``radius`` (K,) px, and every sample of the segment between
    them nearer their mark's colour (the mean of their ``spot`` colours, (K, 3)) than the paint around them (their
    ``ring`` colours' mean) in ``lin`` (H, W, 3), linear light. A disc seen at a grazing angle is an ellipse whose
    finest scale fits its minor axis: it peaks twice, towards its ends, with no larger scale peaking at its centre
    (the second robot's top-face marks at telephoto); two marks of one colour have paint between them."""
    pts = np.asarray(pts, float).reshape(-1, 2)
    k = len(pts)
    joined = np.zeros((k, k), bool)
    if k < 2:
        return joined
    i, j = np.triu_indices(k, 1)
    d = np.hypot(*(pts[i] - pts[j]).T)
    big, small = np.maximum(radius[i], radius[j]), np.minimum(radius[i], radius[j])
    # two ends fit the minor axis alike (a rim peak beside a whole disc's is :func:`same_spots`')
    near = (labels[i] == labels[j]) & (d <= ONE_MARK_REACH * big) & (d > 0) & (big <= 1.5 * small)
    i, j = i[near], j[near]
    if not len(i):
        return joined
    mark, paint = 0.5 * (spot[i] + spot[j]), 0.5 * (ring[i] + ring[j])                # (N, 3)
    contrast = mark - paint
    span = np.maximum(np.einsum("nc,nc->n", contrast, contrast), 1e-12)
    inside = np.ones(len(i), bool)
    for t in (0.25, 0.5, 0.75):
        p = pts[i] + t * (pts[j] - pts[i])
        off = _bilinear(lin, p[:, 0:1], p[:, 1:2])[:, 0] - paint                     # (N, 3)
        cover = np.einsum("nc,nc->n", off, contrast) / span   # the share of the mark's colour on paint -> mark
        across = np.linalg.norm(off - cover[:, None] * contrast, axis=1) / np.sqrt(span)
        inside &= (cover >= MIN_COVER_BETWEEN) & (across <= MAX_ACROSS_BETWEEN)
    joined[i[inside], j[inside]] = joined[j[inside], i[inside]] = True
    return joined


def densest_cluster(pts: np.ndarray, weight: np.ndarray, radius: float) -> np.ndarray:
    """Indices of the points within ``radius`` of the point whose ``radius`` neighbourhood holds the most weight
    (the target's marks; specks and clutter far from it are dropped)."""
    d = np.linalg.norm(pts[:, None, :] - pts[None, :, :], axis=2)
    near = d <= radius
    centre = int(np.argmax(near @ np.minimum(weight, 3.0)))
    members = near[centre]
    # re-centre once on the members' weighted mean
    mean = np.average(pts[members], axis=0, weights=np.minimum(weight[members], 3.0))
    return np.nonzero(np.linalg.norm(pts - mean, axis=1) <= radius)[0]


def merge_oblique_marks(lin: np.ndarray, pts: np.ndarray, radius: np.ndarray, spot: np.ndarray, ring: np.ndarray,
                        marks: dict[int, list[int]]) -> None:
    """Each oblique mark's peaks (``marks``: the first taken -> the others, :func:`one_mark_between`) made one, in
    place in ``pts`` (K, 2) and ``radius`` (K,) at the first: its radius half its farthest two peaks' span beyond the
    larger peak's, its centre the centroid of its colour's coverage (:func:`vision.spot_position.coverage_centroids`
    in ``lin`` (H, W, 3), with the peaks' ``spot`` and ``ring`` colours (K, 3)) from their middle, as one round
    spot's."""
    for first, more in marks.items():
        peaks = pts[[first, *more]]
        apart = np.hypot(*(peaks[:, None, :] - peaks[None, :, :]).transpose(2, 0, 1))
        a, b = np.unravel_index(int(np.argmax(apart)), apart.shape)
        radius[first] = float(radius[[first, *more]].max()) + 0.5 * float(apart[a, b])
        pts[first] = coverage_centroids(lin, 0.5 * (peaks[a] + peaks[b])[None], radius[first:first + 1],
                                        spot[first:first + 1], ring[first:first + 1])[0]


__all__ = ["densest_cluster", "merge_oblique_marks", "one_mark_between", "one_per_disc", "one_scale", "same_spots",
           "surrounded"]
