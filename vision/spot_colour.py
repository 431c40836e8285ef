"""Which paint colour a 2-4 px spot is, seen through the encoder: analysis by synthesis in JPEG's own colour space.

A camera streams JPEG with 4:2:0 chroma: luminance at every pixel, the two chroma channels as means over 2 x 2
blocks. A 5 cm mark 30 m away covers 2-4 px, so its luminance keeps about half its contrast against the body while
its chroma keeps about a tenth (measured on the project's Cycles frames: a cyan mark on the red body moves Y by
+34 and Cr by only -10 of the -120 a full cyan would). A label fitted in RGB, where luminance and chroma are mixed,
then reads the diluted chroma as the body's own: cyan and green came out yellow or magenta (55 % of the paper-scale
labels right, cyan 10 %, green 7 %).

So the label is fitted where the encoder works (docs/design.md, "The feature front-end"): in gamma-encoded Y Cr Cb
(ITU-R BT.601 full range, JPEG's), a spot of paint colour ``c`` at brightness ``k`` over its surroundings ``r`` is

    dY(x) = a g(x) (k Y_c - Y_r)            (luminance: full resolution)
    dC(x) = a S[g](x) (k C_c - C_r)         (chroma, centred on 128: through the 4:2:0 operator S)

with ``g`` the spot's profile (a Gaussian of the detector's scale at the sub-pixel position), ``a`` its coverage
and ``S`` the encoder's block means aligned to even image coordinates, upsampled bilinearly (:func:`chroma_420`).
Scaling linear light by ``s`` scales gamma values by ``s^(1/2.4)``, so ``k`` is exactly a brightness. For each
colour and each ``k`` on a grid the model is linear in ``a``: the best ``a`` in closed form, the misfit the residual
over the spot's window. ``k`` is held near the light on the body: the ring's luminance over the body paint's
(:data:`BRIGHTNESS_SPAN` either way), as marks and body share a face and its light.

The same model says whether a spot is a mark at all: a mark is a patch of one paint, so its colour explains most of
the spot's deviation from the ring where the spot lies. The body's shading (its own red, darker: a gap, a dent, a
shadow's edge) is a change no paint colour at the body's light accounts for, and is dropped
(:data:`MIN_EXPLAINED`).
"""

from __future__ import annotations

import cv2
import numpy as np

from .ring_pixels import ring_pixels

#: Half size of the window the 4:2:0 operator is applied on, and of the window the misfit is taken over (pixels).
PATCH_HALF, FIT_HALF = 5, 3
#: The mark's brightness relative to the body's light lies within this factor either way.
BRIGHTNESS_SPAN = 1.6
#: Without the body's colour: the mark's brightness relative to its palette colour lies in this range.
FREE_BRIGHTNESS = (0.15, 1.6)
#: Brightness steps of the grid, and the largest coverage (a spot may show a little more than its mark: blur).
BRIGHTNESS_STEPS, MAX_COVERAGE = 16, 1.2
#: Least share of a spot's deviation from its ring that its colour explains, where the spot lies (each pixel
#: weighed by the spot's profile): a mark is a patch of one paint; the body's own shading, a highlight on its gloss
#: or its outline blended with the ground changes the pixels in a way no paint colour over the ring accounts for.
#: Cycles paper-scale sweep (nine datasets): at 0.1 precision 0.487 -> 0.595, recall 0.695 -> 0.680. Since a weak mark
#: beside a stronger one is a candidate too (:func:`vision.blobs._detect`, maxima in position), more of the body's
#: shading is: 0.1 -> 0.2 gives precision 0.514 -> 0.606, recall 0.789 -> 0.772, and on the nine 20-frame sequences
#: tracked in process (benchmarks/bench_photoreal_tracking.py) 165 -> 158 good frames, 4 -> 3 of them > 5 deg off.
MIN_EXPLAINED = 0.2


def to_ycrcb(bgr: np.ndarray) -> np.ndarray:
    """uint8 BGR (..., 3) -> float Y, Cr, Cb (..., 3), JPEG's full-range BT.601 (OpenCV's ``COLOR_BGR2YCrCb``)."""
    a = np.asarray(bgr, np.uint8)
    flat = a.reshape(-1, 1, 3)
    return cv2.cvtColor(flat, cv2.COLOR_BGR2YCrCb).reshape(a.shape).astype(np.float64)


def chroma_420(field: np.ndarray, x0: int, y0: int) -> np.ndarray:
    """The encoder's 4:2:0 chroma operator on ``field`` (H, W) whose top-left pixel is image pixel ``(x0, y0)``:
    means over the 2 x 2 blocks of the image's grid (aligned to even coordinates), upsampled bilinearly back to
    (H, W)."""
    ox, oy = x0 % 2, y0 % 2
    h, w = field.shape
    padded = np.pad(field, ((oy, (h + oy) % 2), (ox, (w + ox) % 2)), mode="edge")
    blocks = padded.reshape(padded.shape[0] // 2, 2, padded.shape[1] // 2, 2).mean(axis=(1, 3))
    up = cv2.resize(blocks, (padded.shape[1], padded.shape[0]), interpolation=cv2.INTER_LINEAR)
    return up[oy:oy + h, ox:ox + w]


def spot_colours(image: np.ndarray, xs: np.ndarray, ys: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Each spot's own colour (K, C) in ``image`` (H, W, C) at pixels (``xs``, ``ys``) (K,) int: the pixel itself
    under 1.5 px of ``radius`` (K,), else the centre of its 5 x 5 window blurred at half the radius (the finest blur
    at the centre: the mark's paint, not its edge's blend)."""
    return np.array([image[y, x] if r < 1.5 else cv2.GaussianBlur(image[max(y - 2, 0):y + 3, max(x - 2, 0):x + 3],
                                                                  (0, 0), 0.5 * r)[min(y, 2), min(x, 2)]
                     for y, x, r in zip(np.asarray(ys).tolist(), np.asarray(xs).tolist(),
                                        np.asarray(radius).tolist())]).reshape(-1, image.shape[2])


def ring_colours(image: np.ndarray, points: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """The median colour (K, C) of each spot's ring in ``image`` (H, W, C), ``radius + 1.5`` to ``radius + 3`` px
    from ``points`` (K, 2): the surroundings a spot is blended with (here in Y Cr Cb; :mod:`vision.blobs` in
    linear light). Spots of one radius are taken together (the pixels of a window around each that a ring can
    reach, :func:`vision.ring_pixels.ring_pixels`; outside the ring or the image left out of the median)."""
    h, w = image.shape[:2]
    points, radius = np.asarray(points, float).reshape(-1, 2), np.asarray(radius, float).reshape(-1)
    out = np.zeros((len(points), image.shape[2]))
    for r in np.unique(radius):
        at = np.nonzero(radius == r)[0]
        reach = r + 3.0
        span = int(np.ceil(2 * reach)) + 2   # from floor(centre - reach): the centre lies reach + [0, 1) into it
        rows, cols = ring_pixels(0, span, reach, reach + 1.0, r + 1.5, reach)                   # (M,) each
        u, v = points[at, 0], points[at, 1]
        xs = np.floor(u - reach).astype(int)[:, None] + cols[None, :]                      # (N, M)
        ys = np.floor(v - reach).astype(int)[:, None] + rows[None, :]
        dist = np.hypot(xs - u[:, None], ys - v[:, None])                                  # (N, M)
        sel = (dist >= r + 1.5) & (dist <= reach) & (xs >= 0) & (xs < w) & (ys >= 0) & (ys < h)
        values = image[np.clip(ys, 0, h - 1), np.clip(xs, 0, w - 1)].astype(float)         # (N, M, C)
        values[~sel] = np.nan
        some = sel.any(axis=1)
        if some.any():
            out[at[some]] = _median_of_numbers(values[some])
        for i in at[~some]:
            out[i] = image[int(round(points[i, 1])), int(round(points[i, 0]))]
    return out


def _median_of_numbers(values: np.ndarray) -> np.ndarray:
    """``np.nanmedian(values, axis=1)`` of (N, M, C) values with at least one number per row (N, C), by one sort
    (NaN sorts last) instead of a masked median per row."""
    ordered = np.ascontiguousarray(values.transpose(0, 2, 1))               # (N, C, M): sorted along memory
    ordered.sort(axis=2)
    count = np.count_nonzero(~np.isnan(ordered), axis=2)                     # (N, C)
    lo = np.take_along_axis(ordered, ((count - 1) // 2)[:, :, None], axis=2)[:, :, 0]
    hi = np.take_along_axis(ordered, (count // 2)[:, :, None], axis=2)[:, :, 0]
    return (lo + hi) / 2


def spot_misfits(image_bgr: np.ndarray, points: np.ndarray, radius: np.ndarray, palette_bgr: np.ndarray,
                 body_bgr: tuple[int, int, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """How well each spot (``points`` (K, 2) pixels, ``radius`` (K,) pixels from the detector's scale) is each paint
    colour of ``palette_bgr`` (C, 3) uint8 sRGB, through 4:2:0 chroma (the module's model). Returns

    * ``misfit`` (K, C): the root-sum-square residual over the spot's window, 8-bit Y Cr Cb units (inf for a spot
      too near the border): which colour;
    * ``explained`` (K, C): the share of the window's squared deviation from the ring that the colour explains,
      each pixel weighed by the spot's profile there (``g`` in luminance, ``S[g]`` in chroma: a neighbouring mark
      or the body's shading beside the spot weighs little), the model fitted under those weights (0 at the
      border): whether the spot is a colour at all (:data:`MIN_EXPLAINED`)."""
    ycc = to_ycrcb(image_bgr)
    palette = to_ycrcb(np.asarray(palette_bgr, np.uint8).reshape(-1, 3))            # (C, 3)
    pal_y, pal_c = palette[:, 0], palette[:, 1:] - 128.0
    ring = ring_colours(ycc, points, radius)
    body_y = None if body_bgr is None else float(to_ycrcb(np.array([body_bgr], np.uint8))[0, 0])
    out, explained = np.full((len(points), len(palette)), np.inf), np.zeros((len(points), len(palette)))
    windows = _spot_windows(ycc, points, radius, ring)
    if windows is None:
        return out, explained
    spots, g_inner, sg_inner, d_inner = windows
    ring_ys = ring[spots, 0]
    lo, hi = (np.full(len(spots), FREE_BRIGHTNESS[0]), np.full(len(spots), FREE_BRIGHTNESS[1])) if not body_y else \
        (ring_ys / body_y / BRIGHTNESS_SPAN, ring_ys / body_y * BRIGHTNESS_SPAN)
    brightness = np.geomspace(np.maximum(lo, 1e-3), np.maximum(hi, 2e-3), BRIGHTNESS_STEPS, axis=1)   # (K', G)
    # each colour's unit-coverage model at brightness k, [g (k Y_c - Y_r), S[g] (k C_c - C_r)] over the window, has
    # coefficients (K', C, G) on the spot's profiles: every spot, colour and brightness is fitted at once
    ring_y, ring_c = ring[spots, 0], ring[spots, 1:] - 128.0                             # (K',), (K', 2)
    coef_y = brightness[:, None, :] * pal_y[None, :, None] - ring_y[:, None, None]        # (K', C, G)
    coef_c = brightness[:, None, :, None] * pal_c[None, :, None, :] - ring_c[:, None, None, :]   # (K', C, G, 2)
    dy, dc = d_inner[:, :, 0], d_inner[:, :, 1:]                                         # (K', N), (K', N, 2)
    out[spots] = np.sqrt(_least_squares(coef_y, coef_c, g_inner, sg_inner, dy, dc))
    # each pixel weighed by the spot's profile there: the model and the deviation times sqrt(g) and sqrt(S[g])
    deviation = np.einsum("kn,kn,kn->k", g_inner, dy, dy) + np.einsum("kn,knc,knc->k", sg_inner, dc, dc)
    weighed = _least_squares(coef_y, coef_c, g_inner ** 1.5, sg_inner ** 1.5, dy * np.sqrt(g_inner),
                             dc * np.sqrt(sg_inner)[:, :, None])
    with np.errstate(invalid="ignore", divide="ignore"):
        explained[spots] = np.where(deviation[:, None] > 0, 1.0 - weighed / deviation[:, None], 0.0)
    return out, explained


def _least_squares(coef_y: np.ndarray, coef_c: np.ndarray, profile_y: np.ndarray, profile_c: np.ndarray,
                   dy: np.ndarray, dc: np.ndarray) -> np.ndarray:
    """The least squared residual (K, C) of each spot's deviation from its ring, ``dy`` (K, N) in luminance and ``dc``
    (K, N, 2) in chroma, as ``a m`` with the model ``m = [profile_y coef_y, profile_c coef_c]`` over the window (the
    profiles (K, N); the coefficients (K, C, G) and (K, C, G, 2) per colour and brightness), the coverage ``a`` in
    [0, MAX_COVERAGE] in closed form, the least over the G brightness steps. The model's products with itself and
    with the deviation are its coefficients times five sums over each window; ``|d - a m|^2 = |d|^2 - a (2 m . d - a
    |m|^2)`` gives the residual's size without forming it."""
    size = np.einsum("kn,kn->k", dy, dy) + np.einsum("knc,knc->k", dc, dc)                 # (K,)
    norm = (coef_y ** 2 * np.einsum("kn,kn->k", profile_y, profile_y)[:, None, None]
            + np.sum(coef_c ** 2, axis=3) * np.einsum("kn,kn->k", profile_c, profile_c)[:, None, None])
    dot = (coef_y * np.einsum("kn,kn->k", profile_y, dy)[:, None, None]
           + np.einsum("kcgj,kj->kcg", coef_c, np.einsum("kn,knj->kj", profile_c, dc)))
    a = np.clip(dot / np.maximum(norm, 1e-12), 0.0, MAX_COVERAGE)
    return np.maximum(np.min(size[:, None, None] - a * (2.0 * dot - a * norm), axis=2), 0.0)


def _spot_windows(ycc: np.ndarray, points: np.ndarray, radius: np.ndarray, ring: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """What :func:`spot_misfits` fits, for every spot whose window lies in the image at once: the spots' indices
    (K',), their profiles ``g`` and ``S[g]`` over the fit's window (K', N) and the window's deviation from the ring
    (K', N, 3) (N = (2 FIT_HALF + 1)^2, row by row); None: no such spot. The same values as one window at a time."""
    h, w = ycc.shape[:2]
    points, radius = np.asarray(points, float).reshape(-1, 2), np.asarray(radius, float).reshape(-1)
    span = 2 * PATCH_HALF + 1
    cu, cv = np.rint(points[:, 0]).astype(int), np.rint(points[:, 1]).astype(int)
    x0, y0 = cu - PATCH_HALF, cv - PATCH_HALF
    spots = np.flatnonzero((x0 >= 0) & (y0 >= 0) & (x0 + span <= w) & (y0 + span <= h))
    if not len(spots):
        return None
    x0, y0, u, v = x0[spots], y0[spots], points[spots, 0, None, None], points[spots, 1, None, None]
    xx, yy = x0[:, None, None] + np.arange(span)[None, None, :], y0[:, None, None] + np.arange(span)[None, :, None]
    sigma = np.maximum(radius[spots] / np.sqrt(2), 0.6)[:, None, None]
    g = np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * sigma * sigma))                 # (K', span, span)
    sg = np.empty_like(g)
    for ox in (0, 1):   # chroma_420 of the windows of one parity together (the same block means, upsampled alike)
        for oy in (0, 1):
            at = np.flatnonzero((x0 % 2 == ox) & (y0 % 2 == oy))
            if not len(at):
                continue
            padded = np.pad(g[at], ((0, 0), (oy, (span + oy) % 2), (ox, (span + ox) % 2)), mode="edge")
            n, ph, pw = padded.shape
            blocks = padded.reshape(n, ph // 2, 2, pw // 2, 2).mean(axis=(2, 4))
            for j, block in zip(at.tolist(), blocks):
                sg[j] = cv2.resize(block, (pw, ph), interpolation=cv2.INTER_LINEAR)[oy:oy + span, ox:ox + span]
    inner = slice(PATCH_HALF - FIT_HALF, PATCH_HALF + FIT_HALF + 1)
    fit = 2 * FIT_HALF + 1
    ys = (y0 + PATCH_HALF - FIT_HALF)[:, None, None] + np.arange(fit)[None, :, None]
    xs = (x0 + PATCH_HALF - FIT_HALF)[:, None, None] + np.arange(fit)[None, None, :]
    d = ycc[ys, xs].reshape(len(spots), fit * fit, 3) - ring[spots, None, :]
    return (spots, g[:, inner, inner].reshape(len(spots), -1), sg[:, inner, inner].reshape(len(spots), -1), d)


def label_small_spots(image_bgr: np.ndarray, points: np.ndarray, radius: np.ndarray, palette_bgr: np.ndarray,
                      body_bgr: tuple[int, int, int] | None = None,
                      min_explained: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Each spot's colour (index into ``palette_bgr``, (K,)) and a confidence (K,) in [0, 1], 1 - best misfit over
    the second's (:func:`spot_misfits`). Label -1: no colour can be fitted (at the border), or the best explains
    less than ``min_explained`` (default :data:`MIN_EXPLAINED`) of the spot's deviation from its ring."""
    return labels_of(*spot_misfits(image_bgr, points, radius, palette_bgr, body_bgr), min_explained)


def labels_of(misfit: np.ndarray, explained: np.ndarray, min_explained: float | None = None
              ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`label_small_spots` from :func:`spot_misfits`' ``misfit`` and ``explained`` (K, C)."""
    min_explained = MIN_EXPLAINED if min_explained is None else min_explained
    if misfit.shape[1] == 0 or len(misfit) == 0:
        return np.full(len(misfit), -1, int), np.zeros(len(misfit))
    order = np.argsort(misfit, axis=1)
    best = misfit[np.arange(len(misfit)), order[:, 0]]
    second = misfit[np.arange(len(misfit)), order[:, 1]] if misfit.shape[1] > 1 else np.full(len(misfit), np.inf)
    with np.errstate(invalid="ignore", divide="ignore"):
        confidence = np.where(np.isfinite(best), np.clip(1.0 - best / np.maximum(second, 1e-9), 0.0, 1.0), 0.0)
    colour = explained[np.arange(len(misfit)), order[:, 0]] >= min_explained
    return np.where(np.isfinite(best) & colour, order[:, 0], -1), confidence


__all__ = ["chroma_420", "label_small_spots", "labels_of", "ring_colours", "spot_colours", "spot_misfits",
           "to_ycrcb"]
