"""Where a 2-12 px spot lies, to a fraction of a pixel (the contrast front-end's positions, :mod:`vision.blobs`):
the sub-pixel peak of its scale-space response, a spot and not an edge by the response's Hessian, and the centroid
of its coverage (the share of each pixel the spot's colour covers, on the line from its ring through it)."""

from __future__ import annotations

import cv2
import numpy as np

from .features import mark_coverage
from .ring_pixels import ring_pixels
from .spot_outline import half_length

#: Spots under this radius (px) are the paper's scale: one centroid step, spots of one radius together.
SMALL_SPOT_PX = 3.0
#: Most re-centrings of a spot's coverage window (:func:`coverage_centroids`).
CENTROID_STEPS = 6
#: Where spots are SMALL_SPOT_PX and more, a pixel a spot's colour covers at least this share of belongs to its
#: blob (:func:`blob_centroids`).
BLOB_COVERAGE = 0.5
#: ... or, where that blob reaches past the largest mark, the first of these coverages at which the centre's blob does
#: not (a mark joined through a blend to an area of its colour beside it); none: the blob is that area's.
SEPARATING_COVERAGE: tuple[float, ...] = (0.6, 0.7, 0.8)


def round_peaks(dog: np.ndarray, lvl: np.ndarray, ys: np.ndarray, xs: np.ndarray, max_edge_ratio: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Which peaks of the difference-of-Gaussian stack ``dog`` (S - 1, H, W, 3) at (``lvl``, ``ys``, ``xs``) (K,)
    are spots, not edges (the Hessian of the response projected on the peak's contrast direction: positive definite,
    its eigenvalues' ratio under ``max_edge_ratio``), and their sub-pixel positions (K, 2) (a quadratic through the
    3 x 3 neighbourhood, at most half a pixel from the peak)."""
    k = len(lvl)
    if k == 0:
        return np.zeros(0, bool), np.zeros((0, 2))
    d = dog[lvl, ys, xs]                                                # (K, 3) the contrast direction
    d_unit = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
    dy, dx = np.mgrid[-1:2, -1:2]
    patch = np.einsum("kijc,kc->kij", dog[lvl[:, None, None], ys[:, None, None] + dy, xs[:, None, None] + dx],
                      d_unit)                                           # (K, 3, 3), peak positive
    dxx = patch[:, 1, 2] - 2 * patch[:, 1, 1] + patch[:, 1, 0]
    dyy = patch[:, 2, 1] - 2 * patch[:, 1, 1] + patch[:, 0, 1]
    dxy = (patch[:, 2, 2] - patch[:, 2, 0] - patch[:, 0, 2] + patch[:, 0, 0]) / 4
    tr, det = dxx + dyy, dxx * dyy - dxy * dxy
    r = max_edge_ratio
    with np.errstate(divide="ignore", invalid="ignore"):
        ok = (det > 0) & (tr * tr / np.where(det > 0, det, 1.0) < (r + 1) ** 2 / r)
    gx, gy = (patch[:, 1, 2] - patch[:, 1, 0]) / 2, (patch[:, 2, 1] - patch[:, 0, 1]) / 2
    safe = np.where(ok, det, 1.0)
    off_x = -(dyy * gx - dxy * gy) / safe                               # the 2 x 2 system solved in closed form
    off_y = -(dxx * gy - dxy * gx) / safe
    pts = np.stack([xs + np.clip(off_x, -0.5, 0.5), ys + np.clip(off_y, -0.5, 0.5)], axis=1)
    return ok, np.where(ok[:, None], pts, 0.0)


def coverage_centroids(lin: np.ndarray, pts: np.ndarray, radius: np.ndarray, spot: np.ndarray,
                        ring: np.ndarray) -> np.ndarray:
    """Each spot's position as the centroid of its coverage (:func:`vision.features.mark_coverage`: a pixel's share
    of the spot's colour on the line ring -> spot, in linear light) within its radius + 1.5 px: the covered
    area's centre, to a tenth of a pixel for 2-4 px marks where a peak's quadratic is coarser. The window is
    re-centred on the centroid (mean shift, :data:`CENTROID_STEPS` at most, within the radius of the peak): a
    disc seen obliquely is an ellipse whose response peaks off its centre along the long axis, and a window
    around the peak cuts it (3 px off on a telephoto top face). Not under :data:`SMALL_SPOT_PX`, where marks 3-5
    px apart would draw the window onto a neighbour (recall 0.73 -> 0.72 on the Cycles paper-scale sweep).
    Shapes: lin (H, W, 3), pts (K, 2), radius (K,), spot and ring (K, 3)."""
    h, w = lin.shape[:2]
    out = pts.copy()
    small = radius < SMALL_SPOT_PX
    for r in np.unique(radius[small]):  # one step, spots of one radius together
        at = np.nonzero(small & (radius == r))[0]
        reach = r + 1.5
        span = int(np.ceil(2 * reach)) + 2
        u, v = pts[at, 0], pts[at, 1]
        xs = np.maximum(np.floor(u - reach).astype(int), 0)[:, None] + np.arange(span)[None, :]
        ys = np.maximum(np.floor(v - reach).astype(int), 0)[:, None] + np.arange(span)[None, :]
        inside = ((xs < w)[:, None, :] & (ys < h)[:, :, None]
                  & (np.hypot(xs[:, None, :] - u[:, None, None], ys[:, :, None] - v[:, None, None]) <= reach))
        window = lin[np.minimum(ys, h - 1)[:, :, None], np.minimum(xs, w - 1)[:, None, :]]   # (N, span, span, 3)
        a = mark_coverage(window - ring[at, None, None, :], (spot[at] - ring[at])[:, None, None, :]) * inside
        total = a.sum(axis=(1, 2))
        some = total > 1e-6
        cx = (a * xs[:, None, :]).sum(axis=(1, 2)) / np.where(some, total, 1.0)
        cy = (a * ys[:, :, None]).sum(axis=(1, 2)) / np.where(some, total, 1.0)
        out[at[some]] = np.stack([cx, cy], axis=1)[some]
    large = np.flatnonzero(~small)
    if len(large):
        out[large] = _recentred(lin, pts[large], radius[large], spot[large], ring[large])
    return out


def blob_centroids(lin: np.ndarray, centres: np.ndarray, spot: np.ndarray, ring: np.ndarray, max_radius: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Each spot's position (K, 2) as the coverage-weighted centroid of its whole blob, and the blob's long half-axis
    (K, 2) px from its second moments (:func:`vision.spot_outline.half_length`; zeros where the centre is kept). The
    blob: the pixels its colour covers :data:`BLOB_COVERAGE` or more of, 8-connected to the one nearest its
    ``centres`` (K, 2), with the blend 1 px around them. A disc seen at a grazing angle is an ellipse up to four
    times as long as wide whose response peaks near one end; a window's mean shift stalls inside such a strip (its
    centroid is its centre wherever the window lies wholly in it), up to 3-4 px from the mark's centre on a large
    robot's side. A blob that reaches past ``max_radius`` of the centre (the largest mark, px) is taken again at the
    higher coverages of :data:`SEPARATING_COVERAGE` (a mark joined through a blend to an area of its colour); one that
    still does, or none at the centre, keeps the centre given: the spot's colour is then paint or shade beside it.
    Shapes: lin (H, W, 3), spot and ring (K, 3)."""
    h, w = lin.shape[:2]
    out = np.asarray(centres, float).copy()
    long_axis = np.zeros_like(out)
    reach = int(np.ceil(max_radius)) + 2
    centre = np.rint(out).astype(int)                                                   # (K, 2)
    # a blob cut by the image's border has no centroid of its own
    at = np.flatnonzero((centre >= reach).all(axis=1) & (centre[:, 0] + reach < w) & (centre[:, 1] + reach < h))
    if not len(at):
        return out, long_axis
    # every window's coverage in one gather (windows of one shape, by flat index)
    offsets = np.arange(-reach, reach + 1)
    index = ((centre[at, 1, None, None] + offsets[None, :, None]) * w
             + centre[at, 0, None, None] + offsets[None, None, :])                      # (N, S, S)
    pixels = np.ascontiguousarray(lin).reshape(h * w, -1)
    base = ring[at].astype(pixels.dtype)                                               # in the image's precision
    cover = mark_coverage(pixels[index] - base[:, None, None, :],
                          (spot[at].astype(pixels.dtype) - base)[:, None, None, :])
    mine = _centre_blobs(cover >= BLOB_COVERAGE)                                        # (N, S, S)
    # a blob reaching the window's edge reaches past the largest mark: paint or shade in the spot's colour, or a mark
    # joined to such an area through the blend between them: cut there at a higher coverage, where the blend is not
    # the spot's colour (the second robot's dark mark beside its dark top plate)
    for level in SEPARATING_COVERAGE if len(mine) else ():
        joined = np.flatnonzero(_reaches_edge(mine))
        if not len(joined):
            break
        mine[joined] = _centre_blobs(cover[joined] >= level)
    own = np.flatnonzero(mine.any(axis=(1, 2)) & ~_reaches_edge(mine))
    if not len(own):
        return out, long_axis
    grown = np.pad(mine[own], ((0, 0), (1, 1), (1, 1)))                                 # with the blend 1 px around
    size = mine.shape[1]
    near = np.zeros_like(mine[own])
    for dy in range(3):
        for dx in range(3):
            near |= grown[:, dy:dy + size, dx:dx + size]
    weight = cover[own] * near                                                          # (B, S, S)
    total = weight.sum(axis=(1, 2))
    mean_u = (weight.sum(axis=1) @ offsets) / total
    mean_v = (weight.sum(axis=2) @ offsets) / total
    du = offsets[None, None, :] - mean_u[:, None, None]
    dv = offsets[None, :, None] - mean_v[:, None, None]
    uu, uv, vv = ((weight * a * b).sum(axis=(1, 2)) / total for a, b in ((du, du), (du, dv), (dv, dv)))
    k = at[own]
    out[k] = centre[k] + np.stack([mean_u, mean_v], axis=1)
    long_axis[k] = half_length(np.stack([np.stack([uu, uv], axis=1), np.stack([uv, vv], axis=1)], axis=1))
    return out, long_axis


def _reaches_edge(blob: np.ndarray) -> np.ndarray:
    """Whether each window's blob (bool (N, S, S)) touches the window's edge, bool (N,)."""
    return blob[:, 0].any(axis=1) | blob[:, -1].any(axis=1) | blob[:, :, 0].any(axis=1) | blob[:, :, -1].any(axis=1)


def _centre_blobs(blob: np.ndarray) -> np.ndarray:
    """The 8-connected component of each window's centre pixel (bool (N, S, S); none where the centre is not set) of
    ``blob`` (bool (N, S, S)): the windows labelled together, laid side by side with a row and a column of unset
    pixels between them, so that no component crosses from one window to the next."""
    n, size = blob.shape[0], blob.shape[1]
    cols = int(np.ceil(np.sqrt(n)))
    rows = -(-n // cols)
    tiles = np.zeros((rows * cols, size + 1, size + 1), np.uint8)
    tiles[:n, :size, :size] = blob
    mosaic = tiles.reshape(rows, cols, size + 1, size + 1).transpose(0, 2, 1, 3).reshape(rows * (size + 1), -1)
    _, labels = cv2.connectedComponents(mosaic, connectivity=8)
    labels = labels.reshape(rows, size + 1, cols, size + 1).transpose(0, 2, 1, 3).reshape(-1, size + 1, size + 1)
    labels = labels[:n, :size, :size]
    middle = labels[:, size // 2, size // 2]                                            # 0: the centre is not set
    return (labels == middle[:, None, None]) & (middle > 0)[:, None, None]


def _recentred(lin: np.ndarray, peaks: np.ndarray, radius: np.ndarray, spot: np.ndarray, ring: np.ndarray
               ) -> np.ndarray:
    """:func:`coverage_centroids` of spots of :data:`SMALL_SPOT_PX` and more (K, 2): each window re-centred on its
    coverage's centroid, never farther than the spot's radius from its peak, until it moves under 0.05 px or after
    :data:`CENTROID_STEPS`. The spots of one radius take each step together, in windows of one shape (the pixels
    within reach and inside the image weigh, the rest count zero)."""
    h, w = lin.shape[:2]
    pixels = np.ascontiguousarray(lin).reshape(h * w, -1)    # gathered by flat index: a quarter of the time
    centre = peaks.astype(float)
    for r in np.unique(radius):
        at = np.flatnonzero(radius == r)
        reach = r + 1.5
        # each spot's coverage once, over a window every re-centred one lies in (the centre stays within the radius
        # of the peak; a window of `span` from floor(u - reach) ends by u + reach + 2): a pixel's coverage is its own
        margin = int(np.ceil(2 * r + 1.5)) + 3
        origin = np.floor(peaks[at]).astype(int) - margin                                  # (N, 2)
        # only the pixels a window can reach (within 2 r + 1.5 of the peak): the rest of the square counts zero
        rows, cols = ring_pixels(-margin, 2 * margin + 2, 0.0, 1.0, 0.0, 2 * r + 1.5)      # (M,) each
        gy, gx = origin[:, 1, None] + rows, origin[:, 0, None] + cols                       # (N, M)
        window = pixels[np.clip(gy, 0, h - 1) * w + np.clip(gx, 0, w - 1)] - ring[at, None, :]
        reached = mark_coverage(window, (spot[at] - ring[at])[:, None, :])
        reached *= (gy >= 0) & (gy < h) & (gx >= 0) & (gx < w)
        coverage = np.zeros((len(at), 2 * margin + 2, 2 * margin + 2))
        coverage[:, rows, cols] = reached
        span = int(np.ceil(2 * reach)) + 2
        offsets = np.arange(span)
        moving = np.arange(len(at))
        for _ in range(CENTROID_STEPS):
            if not len(moving):
                break
            i = at[moving]
            u, v = centre[i, 0], centre[i, 1]
            x0, y0 = np.floor(u - reach).astype(int), np.floor(v - reach).astype(int)
            xg, yg = (x0[:, None] + offsets)[:, None, :], (y0[:, None] + offsets)[:, :, None]   # (N, 1, S), (N, S, 1)
            # within reach: squared distances per axis, summed (not hypot over the whole window)
            inside = np.square(xg - u[:, None, None]) + np.square(yg - v[:, None, None]) <= reach * reach
            a = coverage[moving[:, None, None], yg - origin[moving, 1, None, None],
                         xg - origin[moving, 0, None, None]] * inside
            total = a.sum(axis=(1, 2))
            found = total > 1e-6
            total = np.where(found, total, 1.0)
            moved = np.stack([(a * xg).sum(axis=(1, 2)) / total, (a * yg).sum(axis=(1, 2)) / total], axis=1)
            offset = moved - peaks[i]
            moved = peaks[i] + offset * np.minimum(1.0, r / np.maximum(np.hypot(offset[:, 0], offset[:, 1]),
                                                                       1e-9))[:, None]
            step = np.hypot(*(moved - centre[i]).T)
            centre[i[found]] = moved[found]
            moving = moving[found & (step >= 0.05)]
    return centre


__all__ = ["BLOB_COVERAGE", "CENTROID_STEPS", "SMALL_SPOT_PX", "blob_centroids", "coverage_centroids", "round_peaks"]
