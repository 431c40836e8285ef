"""The target's body in a camera image: where its marks can be (docs/design.md, "The feature front-end").

The marks lie on the body's paint. A pixel shows that paint under any light when the dichromatic reflection model
fits it (:func:`paint_pixels`; a channel the camera clipped only bounds the fit, :func:`censored_share`); a glossy
face whose paint carries less of its light is paint where it touches the surely painted pixels
(:func:`connected_paint`); the region a mark may lie in is that paint closed over the marks' holes and notches
(:func:`body_region`). Images are linear-light BGR float32 (H, W, 3).
"""

from __future__ import annotations

import cv2
import numpy as np

from collections.abc import Callable

from .ring_pixels import ring_pixels
from .spot_outline import outline_radius

#: Which pixels (bool (H, W)) are hued like the body, given its sure paint (bool (H, W)).
HuedLikeBody = Callable[[np.ndarray], np.ndarray]

#: Body context (:func:`paint_pixels`): the largest residual of a paint pixel's fit, relative to the pixel, and the
#: least share of its light the paint carries (a low sun's gloss on a red body's top face leaves it ~0.45; grey
#: ground ~0.05).
PAINT_RESIDUAL, PAINT_SHARE, PAINT_NOISE = 0.12, 0.3, 0.01
#: A face whose paint carries less of its light (a low sun's sky gloss on a red top face seen at a grazing angle
#: leaves ~0.2; grey ground up to ~0.16 in 1 of 1000 pixels) is paint where it touches the surely painted pixels
#: (:func:`connected_paint`: hysteresis, as Canny's edges): this share and up, connected to a pixel of PAINT_SHARE.
PAINT_SHARE_CONNECTED = 0.18
#: How far above the ground's own paint share (its 90th percentile) the hysteresis starts (:func:`connected_share`).
GROUND_SHARE_MARGIN = 0.05
#: The ground's share is read this far (pixels) and more from the sure paint.
GROUND_AWAY_PX = 12
#: An 8-bit channel this high is clipped (the sensor's or the encoder's top, within JPEG's error).
CLIPPED = 250


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """sRGB values in [0, 1] in linear light (float32)."""
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)


#: :func:`srgb_to_linear` of the 256 values of an 8-bit channel (an image is decoded by look-up, not by power).
LINEAR_OF_BYTE = srgb_to_linear(np.arange(256, dtype=np.float32) / np.float32(255.0))


def clipped_channels(bgr: np.ndarray) -> np.ndarray:
    """Which channels of a camera image (BGR uint8 (H, W, 3), as the camera gave it) were lit past its range (bool
    (H, W, 3)): :data:`CLIPPED` and up. Such a channel is a lower bound of its light, not its value: a saturated face
    over-exposed keeps its hue only in its other channels (a yellow face clipped in red and green is lemon)."""
    return np.asarray(bgr) >= CLIPPED


def censored_share(lin: np.ndarray, clipped: np.ndarray, body_linear: np.ndarray) -> np.ndarray:
    """:func:`paint_share` of pixels (N, 3) linear BGR some of whose channels were clipped (``clipped`` (N, 3) bool,
    at least one channel not): ``p = a c + b w``, ``a >= 0``, ``b`` (at least minus the tolerance), fitted within
    :data:`PAINT_RESIDUAL` on the channels not clipped and at least as bright as each clipped one (the light was more
    than the sensor held), with the least paint ``a`` consistent with both (the least share: a blown white glare is
    not paint); -1 where none is (float32 (N,))."""
    c = np.asarray(body_linear, np.float64)
    p = np.asarray(lin, np.float64)
    clipped = np.asarray(clipped, bool)
    share = np.full(len(p), -1.0)
    tol = PAINT_RESIDUAL * np.linalg.norm(p, axis=1) + PAINT_NOISE                   # (N,)
    code = clipped.astype(np.uint8) @ np.array([1, 2, 4], np.uint8)                  # (N,) which channels, as bits
    for pattern in np.unique(code).tolist():
        m = (pattern >> np.arange(3)) & 1 == 1
        if m.all() or not m.any():
            continue
        at = np.flatnonzero(code == pattern)
        q, t = p[at], tol[at]
        free, over = np.flatnonzero(~m), np.flatnonzero(m)
        mq, mc = q[:, free].mean(axis=1), float(c[free].mean())   # b = mq - a mc fits the free channels' mean
        lo, hi = np.zeros(len(at)), (mq + t) / max(mc, 1e-12)   # a >= 0; b >= -t
        ok = np.ones(len(at), bool)
        for j in over:                          # a c_j + b >= p_j - t
            slope, need = c[j] - mc, q[:, j] - mq - t
            if slope > 1e-9:
                lo = np.maximum(lo, need / slope)
            elif slope < -1e-9:
                hi = np.minimum(hi, need / slope)
            else:
                ok &= need <= 0
        if len(free) == 2:                      # the two free channels' residual, |d - a dc| / sqrt(2) <= t
            i, k = free
            d, dc = q[:, i] - q[:, k], c[i] - c[k]
            if abs(dc) > 1e-9:
                ends = np.sort(np.stack([(d - np.sqrt(2) * t) / dc, (d + np.sqrt(2) * t) / dc]), axis=0)
                lo, hi = np.maximum(lo, ends[0]), np.minimum(hi, ends[1])
            else:
                ok &= np.abs(d) <= np.sqrt(2) * t
        ok &= lo <= hi
        a = lo
        b = np.maximum(mq - a * mc, 0.0)
        paint = a * c.sum()
        share[at] = np.where(ok & (a > 0), paint / np.maximum(paint + 3 * b, 1e-9), np.where(ok, 0.0, -1.0))
    return share.astype(np.float32)


def paint_share(lin: np.ndarray, body_linear: np.ndarray, clipped: np.ndarray | None = None) -> np.ndarray:
    """The share of each pixel's light the body's paint carries (float32 (H, W)), where the pixel shows that paint
    under any light, else -1: the dichromatic reflection model, a pixel ``p = a c + b w`` of the paint's colour
    ``c`` (the body lit by the sun, or only by the sky in a shadow) and the light's own colour ``w`` (neutral in a
    white-balanced image: the gloss reflecting the sky), ``a, b >= 0``, fitted within :data:`PAINT_RESIDUAL` of the
    pixel (grey ground fits ``w`` alone, share ~0; the marks' hues fit neither, -1). ``clipped`` (H, W, 3) bool:
    the channels the camera clipped (:func:`clipped_channels`), whose pixels are fitted by :func:`censored_share`."""
    c = body_linear.astype(np.float32)
    basis = np.stack([c, np.ones(3, np.float32)], axis=1)                       # (3, 2): [c, w]
    coef = lin @ np.linalg.pinv(basis).T.astype(np.float32)                       # (H, W, 2)
    a, b = coef[..., 0], coef[..., 1]
    # b < 0: the best fit without gloss is the paint alone
    alone = np.maximum((lin @ c) / max(float(c @ c), 1e-12), 0)
    a, b = np.where(b < 0, alone, a), np.maximum(b, 0)
    # the pixel's length and its offset from the fit, channel by channel on contiguous planes (the sums of squares
    # in the order an einsum over the channels takes: the same values, a quarter of the time)
    squares, offsets = np.zeros(a.shape, a.dtype), np.zeros(a.shape, a.dtype)
    for channel, paint in zip(cv2.split(np.ascontiguousarray(lin)), c):
        squares += channel * channel
        off = a * paint
        off += b
        np.subtract(channel, off, out=off)
        offsets += off * off
    norm, residual = np.sqrt(squares), np.sqrt(offsets)
    paint = a * float(c.sum())
    share = paint / np.maximum(paint + 3 * b, 1e-9)
    fits = (a > 0) & (residual <= PAINT_RESIDUAL * norm + PAINT_NOISE) & (norm > 0.005)
    share = np.where(fits, share, np.float32(-1)).astype(np.float32)
    if clipped is not None and clipped.any():
        planes = clipped.view(np.uint8)                # the clipped channels per pixel, summed plane by plane (a
        count = planes[..., 0] + planes[..., 1]        # reduction over the short last axis costs ten times more)
        count += planes[..., 2]
        some = (count > 0) & (count < 3)
        if some.any():
            share[some] = censored_share(lin[some], clipped[some], c)
    return share


def paint_pixels(lin: np.ndarray, body_linear: np.ndarray, min_share: float = PAINT_SHARE) -> np.ndarray:
    """Which pixels (bool (H, W)) show the body's paint, under any light (:func:`paint_share`), the paint carrying
    at least ``min_share`` of their light."""
    return paint_share(lin, body_linear) >= min_share


def connected_paint(lin: np.ndarray, body_linear: np.ndarray) -> np.ndarray:
    """The body's paint with its glossy faces (bool (H, W)): :func:`paint_pixels` at :data:`PAINT_SHARE`, and the
    8-connected patches of pixels at :data:`PAINT_SHARE_CONNECTED` that touch them (hysteresis). ``lin`` (H, W, 3)
    linear BGR, ``body_linear`` (3,)."""
    return body_paint(lin, body_linear)[1]


def connected_share(share: np.ndarray, sure: np.ndarray) -> float:
    """The hysteresis's low threshold for a :func:`paint_share` image (H, W): :data:`PAINT_SHARE_CONNECTED`, or
    above the ground's own share where the ground fits the paint that well (a yellow body on beige ground: the
    ground is yellow paint plus white at a share of 0.1-0.23, the Pioneer's grey ground ~0.05): the 90th percentile
    of the pixels below :data:`PAINT_SHARE` away from the ``sure`` paint (H, W) bool (the ground, not the body's own
    glossy faces; a pixel the paint does not fit counts 0), plus :data:`GROUND_SHARE_MARGIN`."""
    away = ~cv2.dilate(sure.astype(np.uint8), np.ones((2 * GROUND_AWAY_PX + 1,) * 2, np.uint8)).astype(bool)
    below = np.maximum(share[(share < PAINT_SHARE) & away][::7], 0.0)   # a pixel the paint does not fit: share 0
    if not len(below):
        return PAINT_SHARE_CONNECTED
    return float(min(max(PAINT_SHARE_CONNECTED, np.quantile(below, 0.9) + GROUND_SHARE_MARGIN), PAINT_SHARE))


def body_paint(lin: np.ndarray, body_linear: np.ndarray, clipped: np.ndarray | None = None,
               hued: HuedLikeBody | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The body's paint, bool (H, W) each: the sure pixels (:func:`paint_pixels`) and those with the glossy faces
    touching them (:func:`connected_paint`), from one :func:`paint_share` (``clipped``: its channels the camera
    clipped, (H, W, 3) bool). ``hued``: pixels hued like the body (H, W) given the sure ones
    (:func:`vision.camera_look.hued_like_body`), which join the glossy faces' hysteresis: a face whose paint a
    camera's tone curve bleached (a desaturated, over-exposed sunlit top) fits the paint's light too little, and keeps
    its hue."""
    share = paint_share(lin, body_linear, clipped)
    sure = share >= PAINT_SHARE
    weak = share >= connected_share(share, sure)
    if hued is not None:
        weak |= hued(sure)
    count, patches = cv2.connectedComponents(weak.astype(np.uint8), connectivity=8)
    touching = np.zeros(count, bool)
    touching[np.unique(patches[sure])] = True
    touching[0] = False
    return sure, touching[patches]


def paint_around(paint: np.ndarray, points: np.ndarray, radius: np.ndarray, gap: float | tuple[float, ...] = 1.0,
                 long_axis: np.ndarray | None = None) -> np.ndarray:
    """The share of the ring ``gap`` to ``gap`` + 1 px beyond each spot's outline (``radius`` (K,) px; drawn out along
    ``long_axis`` (K, 2), :mod:`vision.spot_outline`) around each point that is the body's ``paint`` (bool (H, W));
    outside the image counts as no paint; several gaps: the best of their rings, each window read once. ``points``
    (K, 2) (u, v) pixels. A mark on the body is ringed by paint (on a face's outline, about half of it); a spot on
    the body's outline or on the ground beside it is not (float (K,))."""
    h, w = paint.shape
    gaps = tuple(float(g) for g in np.atleast_1d(gap))
    points, radius = np.asarray(points, float).reshape(-1, 2), np.asarray(radius, float).reshape(-1)
    longest = radius if long_axis is None else np.maximum(radius, np.hypot(*np.asarray(long_axis, float).T))
    share = np.zeros(len(points))
    reach = np.ceil(longest + max(gaps) + 1).astype(int)
    for n in np.unique(reach):   # the points whose window has one size together
        at = np.flatnonzero(reach == n)
        # the window -n..n about the point's nearest pixel: the point -0.5..0.5 from it
        yy, xx = ring_pixels(-int(n), 2 * int(n) + 1, -0.5, 0.5, float(radius[at].min() + min(gaps)),
                             float(longest[at].max() + max(gaps)) + 1)
        yy, xx = yy - n, xx - n                                                          # (M,) offsets each
        u, v = points[at, 0, None], points[at, 1, None]
        cu, cv = np.rint(u).astype(int), np.rint(v).astype(int)
        du, dv = xx + cu - u, yy + cv - v                                                # (N, M)
        d = np.hypot(du, dv)
        drawn = long_axis is not None and bool((longest[at] > radius[at]).any())
        outline = (outline_radius(np.stack([du, dv], axis=2), radius[at], long_axis[at]) if drawn
                   else radius[at, None])
        ys, xs = yy + cv, xx + cu
        painted_here = (ys >= 0) & (ys < h) & (xs >= 0) & (xs < w)
        painted_here &= paint[np.clip(ys, 0, h - 1), np.clip(xs, 0, w - 1)] != 0
        for g in gaps:
            inner = g + outline
            ring = (d >= inner) & (d <= inner + 1)
            shares = np.count_nonzero(ring & painted_here, axis=1) / np.maximum(np.count_nonzero(ring, axis=1), 1)
            share[at] = np.maximum(share[at], shares)
    return share


def pixel_box(mask: np.ndarray) -> tuple[int, int, int, int] | None:
    """The first and last row and the first and last column (inclusive) holding a set pixel of ``mask`` (H, W), or
    None (none set): the box of ``np.nonzero(mask)`` without listing the pixels."""
    rows = np.flatnonzero(mask.any(axis=1))
    if not len(rows):
        return None
    cols = np.flatnonzero(mask.any(axis=0))
    return int(rows[0]), int(rows[-1]), int(cols[0]), int(cols[-1])


def body_silhouette(paint: np.ndarray, mark_px: float, gap_px: float = 0.0) -> np.ndarray:
    """The body's silhouette (bool (H, W)): its ``paint`` (bool (H, W): :func:`body_paint`'s sure pixels, or with the
    glossy faces) less single specks, closed with a disc of the largest mark's radius ``mark_px`` (or ``gap_px``, if
    larger) and its holes filled (a mark inside a face is a hole in the paint, a mark on a face's outline a notch).
    Where a mark of 3 px and more has its centre."""
    paint = cv2.morphologyEx(paint.astype(np.uint8), cv2.MORPH_OPEN,
                             np.ones((2, 2), np.uint8))
    silhouette = np.zeros(paint.shape, bool)
    box = pixel_box(paint)
    if box is None:
        return silhouette
    r = max(int(np.ceil(max(mark_px, gap_px))), 1)
    # the rest runs on the paint's box with a margin the closing cannot reach past (the same result, at a fraction
    # of the cost: a telephoto body fills ~5 % of the frame)
    m = 2 * r + 2
    y0, y1 = max(box[0] - m, 0), min(box[1] + m + 1, paint.shape[0])
    x0, x1 = max(box[2] - m, 0), min(box[3] + m + 1, paint.shape[1])
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    # cv2.morphologyEx(..., cv2.MORPH_CLOSE, disc), in a time that does not grow with the disc (r = 20-60 px at
    # telephoto): the erosion is the dilation of the complement, the image's outside counting as paint
    box = paint[y0:y1, x0:x1] > 0
    closed = (~dilate_disc(~dilate_disc(box, disc), disc)).astype(np.uint8)
    # fill the holes: everything the outside (flooded from a padded border) does not reach
    padded = cv2.copyMakeBorder(closed, 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
    outside = padded.copy()
    cv2.floodFill(outside, np.zeros((padded.shape[0] + 2, padded.shape[1] + 2), np.uint8), (0, 0), 2)
    silhouette[y0:y1, x0:x1] = outside[1:-1, 1:-1] != 2
    return silhouette


def dilate_disc(mask: np.ndarray, disc: np.ndarray) -> np.ndarray:
    """``cv2.dilate(mask, disc) > 0`` of a bool (H, W) ``mask`` by an OpenCV ``MORPH_ELLIPSE`` kernel (2r + 1, 2r + 1)
    (rows centred, their widths falling away from the middle row), the image's outside counting as no pixel, in
    O(H W) whatever r. A pixel is reached from the pixels ``dy`` rows away whose row holds a set pixel within that
    row's half width: each pixel's distance along its row to the nearest set pixel gives the rows it reaches
    (``reach``), and a running maximum and minimum down and up each column which of them reach a pixel."""
    h, w = mask.shape
    r = disc.shape[0] // 2
    half = (np.count_nonzero(disc, axis=1) - 1) // 2                               # (2r + 1,) per row offset
    # reach[k]: the farthest row offset whose row's half width is k or more (none: a sentinel no row reaches
    # from); k = r + 1 stands for farther
    none = -(h + 2)
    # the coordinates in 16 bits where they fit (every value below lies within +-(2 max(h, w) + r + 4)): the running
    # extremes take three quarters of the time
    index = np.int16 if 2 * max(h, w) + r + 4 < np.iinfo(np.int16).max else np.int32
    rows_at_least = np.count_nonzero(half[None, :] >= np.arange(r + 2)[:, None], axis=1)   # (r + 2,): 2 dy + 1
    reach = np.where(rows_at_least > 0, (rows_at_least - 1) // 2, none).astype(index)
    far = index(w + r + 2)
    cols = np.arange(w, dtype=index)
    left = np.maximum.accumulate(np.where(mask, cols, -far), axis=1)
    right = np.minimum.accumulate(np.where(mask, cols, far)[:, ::-1], axis=1)[:, ::-1]
    along = np.minimum(np.minimum(cols - left, right - cols), r + 1)                 # (H, W) to the nearest set pixel
    rows_reached = np.take(reach, along)                                             # (H, W)
    rows = np.arange(h, dtype=index)[:, None]
    below = np.maximum.accumulate(rows + rows_reached, axis=0) >= rows
    above = np.minimum.accumulate((rows - rows_reached)[::-1], axis=0)[::-1] <= rows
    return below | above


def body_region(silhouette: np.ndarray, mark_px: float) -> np.ndarray:
    """Where the target's marks can be (bool (H, W)): its :func:`body_silhouette` (bool (H, W)) grown by half the
    largest mark's radius ``mark_px``, at least 2 px (a mark on the outline of a face lies half outside its paint; a
    2-3 px mark's pixels are mixed with what lies beside the body)."""
    region = np.zeros(silhouette.shape, bool)
    box = pixel_box(silhouette)
    if box is None:
        return region
    g = max(2, int(np.ceil(mark_px / 2)))
    y0, y1 = max(box[0] - g, 0), min(box[1] + g + 1, silhouette.shape[0])
    x0, x1 = max(box[2] - g, 0), min(box[3] + g + 1, silhouette.shape[1])
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * g + 1, 2 * g + 1))
    region[y0:y1, x0:x1] = cv2.dilate(silhouette[y0:y1, x0:x1].astype(np.uint8), disc) > 0
    return region


__all__ = ["CLIPPED", "LINEAR_OF_BYTE", "PAINT_SHARE", "PAINT_SHARE_CONNECTED", "body_paint", "body_region",
           "body_silhouette", "censored_share", "clipped_channels", "connected_paint", "dilate_disc", "paint_around",
           "paint_pixels", "paint_share", "pixel_box", "srgb_to_linear"]
