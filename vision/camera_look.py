"""What a camera's look did to the target's colours, estimated per frame from the target itself, and undone.

The contrast front-end (:mod:`vision.blobs`, :mod:`vision.body_paint`, :mod:`vision.spot_colour`) compares
what it sees with the model's paint colours. Those comparisons hold in the look it was tuned on, the *reference
look* (the project's camera model: sRGB tone, true white balance, default saturation). A lab's camera has its own:
a white-balance error of tens of percent per channel, a saturation setting, a film-like tone curve that compresses
chroma (Blender's Filmic and AgX), a small hue error. Measured on Cycles frames, those move the body's and the
marks' chroma far more than the front-end's tolerances allow, while the *relations* between the colours stay.

So the look is estimated from the scene (docs/design.md, "Seeing through any camera") in JPEG's own colour space,
where a camera's colour processing is nearly linear per pixel: the chroma over luminance,
``q = (Cr - 128, Cb - 128) / Y`` (BT.601 full range, gamma-encoded). There

- a white-balance error (a gain per channel) moves every colour by nearly the same offset: the image's *neutral*,
  the mode of its least chromatic pixels (:func:`neutral_chroma`), moves off the reference's;
- a saturation setting or a chroma-compressing tone curve scales ``q - neutral``; a hue error turns it.

The target's body, the largest patch of one paint the model names, gives the scale and the turn: its chroma
relative to the neutral, against what the reference look makes of that paint (:func:`reference_body_chroma`,
:data:`REFERENCE_BODY_TURN_DEG`: Cycles' sunlit and shaded faces with their gloss keep ~0.6 of the Pioneer's paint's
chroma, turned ~6 deg, at both scales; a paler paint keeps more of its own, a deeper one less).
:func:`to_reference_look` then maps every pixel back, ``q' = R(-turn) (q - neutral) / gain + neutral - shift``,
a linear map of (Cr, Cb) per pixel given Y, so the encoder's 4:2:0 chroma blocks keep their shape
(:mod:`vision.spot_colour` models them), with only what lies beyond the reference look's own spread over scenes
undone (:data:`DEAD_BAND`, :func:`beyond_band`): the reference look is not re-coloured.

Images are OpenCV BGR ``uint8`` (H, W, 3).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from geometry import angle_difference, wrap_angle

from .body_paint import GROUND_AWAY_PX, pixel_box
from .order_stats import median

#: Pixels whose luma is outside this range carry no chroma worth measuring (black, or clipped).
LUMA_RANGE = (24.0, 245.0)
#: The neutral is the median chroma of this share of the pixels nearest it (iterated from the image's median).
NEUTRAL_SHARE = 0.4
#: What the reference look makes of a body's paint: the 90th percentile of its pixels' chroma relative to the
#: neutral over the paint file's chroma (the sunlit faces, unmixed), and the turn (deg) of the upper half's median.
#: Measured with :func:`body_chroma` on the reference look's Cycles frames of the Pioneer (tests/data/photoreal:
#: paper 0.56-0.65, telephoto 0.68-0.74; turn +2 to +8 deg): within the dead band of both.
REFERENCE_BODY_GAIN, REFERENCE_BODY_TURN_DEG = 0.64, 6.0
#: The paint they were measured on (the Pioneer's body, BGR). Another paint's body reads in the reference look as
#: :func:`reference_body_chroma` says: as its chroma to the power REFERENCE_CHROMA_POWER, not in proportion. A pale
#: paint's sunlit face keeps nearly all its file's chroma, a deep one's 0.6-0.7 (the Pioneer's 0.74): a gain
#: constant over paints reads the reference look's frames of twelve random robots at 0.8-1.4 times the Pioneer's
#: saturation, some at the cap (SATURATION_RANGE), and undoes a washed-out look of such a robot by far less than the
#: same look of the Pioneer. Fitted on the telephoto training frames of those robots and the Pioneer
#: (``benchmarks/bench_reference_chroma.py``; BENCHMARKS.md, "What the reference look makes of a body's paint"): the
#: spread of their log readings about the Pioneer's 0.24 -> 0.10, on the development robots 0.20 -> 0.17.
REFERENCE_PAINT_BGR, REFERENCE_CHROMA_POWER = (40, 40, 150), 0.65
#: The neutral of the reference look's frames (the ground's own slight blue: tests/data/photoreal, all frames
#: within 0.01 of it).
REFERENCE_NEUTRAL = (0.033, -0.064)
#: A body pixel's chroma lies within this turn of the paint's (reference look) direction, and at least this many
#: noise spreads (and this absolute chroma) from the neutral.
BODY_TURN_DEG, BODY_NOISE_SPREADS, BODY_MIN_CHROMA = 35.0, 5.0, 0.05
#: Least pixels of the body patch to measure a look from (the paper's scale: the Pioneer's ~25 px across keeps
#: ~450-600 paint pixels), and the least chroma of its 90th percentile, absolute and in noise spreads: a target's
#: paint stands out; the ground's faint tint in the paint's hue (frames without the target, named and corner looks:
#: mostly 0.05-0.10) does not. A body at the paper's scale through a saturation of 0.4-0.45 and a stop and a half
#: under reads 0.14-0.16: under the bar its look would not be undone and its marks would fall outside its paint. The
#: bar was chosen on the paper-scale training worlds through 16 corner looks (:func:`scenarios.looks.corner_look`)
#: and judged on the benchmark worlds and frames without the target (BENCHMARKS.md, "a dark, washed-out body": its
#: gain at the paper's scale through ``flat-cool``, its cost at telephoto through ``agx-punchy``, whose dark curve
#: leaves one camera's body at 0.12-0.16).
MIN_BODY_PIXELS, MIN_BODY_CHROMA, MIN_BODY_SPREADS = 40, 0.12, 20.0
#: Where the target is LOOK_STRIDE_FROM_EXTENT_PX or more across (the prior's extent), the body's patch is found on
#: every LOOK_STRIDE-th pixel of every LOOK_STRIDE-th row (a quarter of the pixels) of an image at least
#: LOOK_STRIDE_FROM_PX on its shorter side, each pixel unmixed (no averaging); its chroma is then read from the
#: image's own pixels (:func:`body_chroma`). An estimate took a quarter of the front-end's time, finding the patch
#: over the whole image half of it. Not where the target is smaller: at the paper's scale (the Pioneer ~28 px
#: across, its body a few hundred pixels) a first version that also measured the body on the sample moved recall
#: through `hable-faded` by -2.3 points and through `flat-cool` by +1.9, so the bar was set there after that run,
#: from the body's pixel count, not fitted; this version was judged on the sets the first had seen (BENCHMARKS.md,
#: "a large body's look patch on a quarter of the pixels": no named-look figure moved by more than 0.8 points).
LOOK_STRIDE, LOOK_STRIDE_FROM_PX, LOOK_STRIDE_FROM_EXTENT_PX = 2, 64, 100.0
#: A paint colour whose chroma (relative to the neutral) is under this carries no hue: only the neutral is measured.
MIN_PAINT_CHROMA = 0.12
#: How far the reference look itself strays, scene by scene (neutral offset, log saturation, turn in deg): its
#: Cycles frames over 3 geometries x 3 lightings read a saturation of 0.73-1.06, turns of -9 to +3 deg and a
#: neutral up to 0.055 off (a low sun's warm light). Only what lies beyond is undone (soft thresholding): a look
#: within these is left as it is, and a look beyond them is brought back to their edge, never past the front-end's
#: own tolerance, which these frames show.
DEAD_BAND = (0.06, 0.3, 8.0)
#: A neutral further than this from the reference's is no white-balance error (+-30 % per channel moves it up to ~0.2
#: through sRGB) but a picture without grey (a close-up of one paint): the reference neutral is kept, unless...
MAX_NEUTRAL_SHIFT = 0.3
#: ... unless the body's paint is found relative to it (:func:`estimate_look`): up to this shift the neutral is then a
#: cast. A white balance 30 % off per channel, a saturation of 1.5 and a stop and a half under together move it up to
#: 0.57 (the telephoto training worlds t1, t2 through :func:`scenarios.looks.corner_look`; 0.26 through random looks).
MAX_NEUTRAL_SHIFT_WITH_BODY = 0.7
#: A pixel hued like the body (:func:`hued_like_body`) reaches this far (chroma over luma) past the ground's own 90th
#: percentile along the paint's direction. Chosen on the telephoto training worlds t1, t2 through 16 random and 16
#: corner looks: 0.05 (the body's per-pixel least chroma) -> 0.03 gave recall +1.9..+2.6 points in five corner looks,
#: precision -0.7..+0.1; 0.015 a further +0.4..+0.8 in six at -0.3..-1.0 in five random looks.
HUED_MARGIN = 0.03
#: ... read on every this-many-th pixel of every this-many-th row (the ground's percentile and the chroma's noise).
HUED_GROUND_STRIDE = 4
#: The correction is bounded: a saturation gain within this range, a turn within this many degrees. Above 1.6 the
#: gain is a dark tone curve's (AgX Punchy on telephoto-g1-high, a one-off analysis where the cap was chosen: a dark
#: red body's chroma over its small luma read 2.5 on one camera, 1.3 on the other), not a saturation setting:
#: taking it back further washes the marks out.
SATURATION_RANGE, MAX_TURN_DEG = (0.25, 1.6), 30.0


@dataclass(frozen=True)
class Look:
    """A camera's look relative to the reference look: ``neutral`` (2,) the chroma (``q``) of the image's neutral,
    ``saturation`` the chroma gain, ``turn_rad`` the hue turn, ``body_pixels`` how many body pixels measured the
    gain and turn (0: none found; then they are 1 and 0)."""

    neutral: tuple[float, float] = REFERENCE_NEUTRAL
    saturation: float = 1.0
    turn_rad: float = 0.0
    body_pixels: int = 0

    @property
    def is_reference(self) -> bool:
        """Whether the look lies within :data:`DEAD_BAND` of the reference look: nothing of it lies beyond
        (:func:`beyond_band`), so nothing is undone."""
        shift, gain, turn = beyond_band(self)
        return not shift.any() and gain == 1.0 and turn == 0.0


def chroma_of(bgr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Luma ``Y`` (H, W) float32 and chroma over luma ``q`` (H, W, 2) float32 ((Cr - 128, Cb - 128) / Y) of a BGR
    uint8 image (or of palette colours, shape (..., 3))."""
    a = np.asarray(bgr, np.uint8)
    ycc = cv2.cvtColor(a.reshape(-1, 1, 3), cv2.COLOR_BGR2YCrCb).reshape(a.shape)
    y = ycc[..., 0].astype(np.float32)
    q = np.subtract(ycc[..., 1:], np.float32(128.0), dtype=np.float32)
    q /= np.maximum(y, 1.0)[..., None]
    return y, q


#: The chroma of :data:`REFERENCE_PAINT_BGR` (the size of its ``q``).
REFERENCE_PAINT_CHROMA = float(np.hypot(*chroma_of(np.array(REFERENCE_PAINT_BGR, np.uint8))[1]))


def neutral_chroma(q: np.ndarray, usable: np.ndarray) -> tuple[np.ndarray, float]:
    """The image's neutral (2,) and the spread of chroma about it (1.4826 MAD of the distance, float): the median
    of the :data:`NEUTRAL_SHARE` of usable pixels nearest the estimate, three times from the median of all."""
    at = np.flatnonzero(usable)
    at = at[::max(1, len(at) // 40000)]
    if not len(at):
        return np.array(REFERENCE_NEUTRAL, np.float32), 0.02
    # the two chroma axes as contiguous columns: a median per axis is the (N, 2) median's, in less time
    qa, qb = q[..., 0].reshape(-1)[at], q[..., 1].reshape(-1)[at]
    n = np.array([median(qa), median(qb)], q.dtype)
    for _ in range(3):
        d = np.hypot(qa - n[0], qb - n[1])
        near = d <= np.quantile(d, NEUTRAL_SHARE)
        n = np.array([median(qa[near]), median(qb[near])], q.dtype)
    return n.astype(np.float32), spread_about(qa, qb, n)


def spread_about(qa: np.ndarray, qb: np.ndarray, neutral: np.ndarray) -> float:
    """The chroma's noise about ``neutral`` (2,): the spread (1.4826 MAD, at least 0.005) of the distances of the
    :data:`NEUTRAL_SHARE` of chroma samples ``qa``, ``qb`` (N,) nearest it."""
    d = np.hypot(qa - neutral[0], qb - neutral[1])
    if not len(d):
        return 0.005
    near = d[d <= np.quantile(d, NEUTRAL_SHARE)]
    return float(max(1.4826 * median(np.abs(near - median(near))), 0.005))


def body_mask(q: np.ndarray, usable: np.ndarray, neutral: np.ndarray, spread: float, paint_q: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which pixels (bool (H, W)) may show the body's paint in any look within :data:`SATURATION_RANGE` and
    :data:`MAX_TURN_DEG`: chroma ``q`` (H, W, 2) relative to the ``neutral`` clear of the noise (``spread``), in a
    direction within :data:`BODY_TURN_DEG` of the paint's ``paint_q`` (2,) under the reference look; with the
    relative chroma (H, W, 2) and its size (H, W)."""
    rel = q - neutral
    r = np.hypot(rel[..., 0], rel[..., 1])
    expect = np.arctan2(paint_q[1], paint_q[0]) + np.radians(REFERENCE_BODY_TURN_DEG)
    mask = usable & (r >= max(BODY_NOISE_SPREADS * spread, BODY_MIN_CHROMA))
    at = np.flatnonzero(mask)                       # the direction only where the chroma is clear of the noise
    flat = rel.reshape(-1, 2)[at]
    off = np.abs(angle_difference(np.arctan2(flat[:, 1], flat[:, 0]), expect))
    mask.reshape(-1)[at[off > np.radians(BODY_TURN_DEG)]] = False
    return mask, rel, r


def body_chroma(q: np.ndarray, usable: np.ndarray, neutral: np.ndarray, spread: float, paint_q: np.ndarray,
                extent_px: float | None = None, stride: int = 1) -> tuple[np.ndarray | None, int]:
    """The body's chroma relative to the neutral (2,): the 90th percentile of its size, in the direction of the
    upper half's median, over the largest patch of :func:`body_mask`'s pixels no larger than the target's extent
    ``extent_px`` allows; and the patch's pixel count (None, 0: no such patch).

    ``stride`` > 1: the patch is found on every ``stride``-th pixel of every ``stride``-th row (a quarter of the
    pixels at 2), then measured on the image's own pixels within it (one sample around) that pass the same tests
    (the chroma's 90th percentile is the sunlit faces', which the sample would read from a quarter of them)."""
    full_q, full_usable = q, usable
    q, usable = q[::stride, ::stride], usable[::stride, ::stride]
    if extent_px is not None:
        extent_px /= stride
    mask, rel, r = body_mask(q, usable, neutral, spread, paint_q)
    area = stride * stride
    if mask.sum() * area < MIN_BODY_PIXELS:
        return None, 0
    # the patches within the mask's box and 2 px around it (the closing reaches 1 px out), the box starting on even
    # coordinates (the labelling scans 2 x 2 blocks): the same patches, numbered in the same order, as over the image
    y0, y1, x0, x1 = pixel_box(mask)
    y0, x0, y1, x1 = max(y0 - 2, 0) // 2 * 2, max(x0 - 2, 0) // 2 * 2, y1 + 3, x1 + 3
    mask, r, rel = mask[y0:y1, x0:x1], r[y0:y1, x0:x1], rel[y0:y1, x0:x1]
    # the closing bridges 1 px gaps; samples 2 px apart are neighbours across one already
    closed = mask.astype(np.uint8) if stride > 1 else cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_CLOSE,
                                                                         np.ones((3, 3), np.uint8))
    count, labels, stats, _ = cv2.connectedComponentsWithStats(closed, connectivity=8)
    pixels = np.bincount(labels[mask], minlength=count)   # each patch's own pixels (the closing's left out)
    pixels[0] = 0
    if extent_px is not None:   # larger than the target can be: a wall, a floor in the body's hue
        pixels[np.maximum(stats[:, cv2.CC_STAT_WIDTH], stats[:, cv2.CC_STAT_HEIGHT]) > 2.0 * extent_px + 8] = 0
    best = int(np.argmax(pixels))   # the first of the largest
    best_n = int(pixels[best]) * area
    if best_n < MIN_BODY_PIXELS:
        return None, 0
    patch = mask & (labels == best)
    if stride == 1:
        rel_patch, r_patch = rel[patch], r[patch]
    else:
        rel_patch, r_patch = _patch_at_full(full_q, full_usable, stride, patch, (y0, x0), neutral, spread, paint_q)
        best_n = len(r_patch)
        if best_n < MIN_BODY_PIXELS:
            return None, 0
    top = np.quantile(r_patch, 0.9)
    if top < max(MIN_BODY_CHROMA, MIN_BODY_SPREADS * spread):
        return None, 0
    upper = rel_patch[r_patch >= median(r_patch)]
    direction = median(upper, axis=0)
    return direction / max(float(np.hypot(*direction)), 1e-9) * top, best_n


def _patch_at_full(q: np.ndarray, usable: np.ndarray, stride: int, patch: np.ndarray, origin: tuple[int, int],
                   neutral: np.ndarray, spread: float, paint_q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The relative chroma (N, 2) and its size (N,) of the pixels of the image (``q`` (H, W, 2), ``usable`` (H, W))
    within a ``patch`` of its sample at ``stride`` (bool, the sample's rows and columns from ``origin``) grown by one
    sample, that pass :func:`body_mask`'s tests."""
    grown = cv2.dilate(patch.astype(np.uint8), np.ones((3, 3), np.uint8))
    rows, cols = np.flatnonzero(grown.any(axis=1)), np.flatnonzero(grown.any(axis=0))
    gy0, gy1, gx0, gx1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    fy0, fx0 = (origin[0] + gy0) * stride, (origin[1] + gx0) * stride
    fy1, fx1 = (origin[0] + gy1) * stride, (origin[1] + gx1) * stride
    part_q, part_usable = q[fy0:fy1, fx0:fx1], usable[fy0:fy1, fx0:fx1]
    within = np.repeat(np.repeat(grown[gy0:gy1, gx0:gx1], stride, axis=0), stride, axis=1)
    mask, rel, r = body_mask(part_q, part_usable, neutral, spread, paint_q)
    mask &= within[:mask.shape[0], :mask.shape[1]] > 0
    return rel[mask], r[mask]


def reference_body_chroma(paint_chroma: float) -> float:
    """What the reference look makes of a body painted with chroma ``paint_chroma`` (the size of the model file's
    colour's ``q``): its 90th percentile chroma relative to the neutral, :data:`REFERENCE_BODY_GAIN` times the
    chroma for :data:`REFERENCE_PAINT_BGR`'s, growing as the chroma to the power :data:`REFERENCE_CHROMA_POWER` from
    there: a pale paint's sunlit face keeps most of its chroma, a deep one's loses more (to the sky's light and the
    gloss)."""
    return REFERENCE_BODY_GAIN * REFERENCE_PAINT_CHROMA * (max(paint_chroma, 1e-9) / REFERENCE_PAINT_CHROMA) ** \
        REFERENCE_CHROMA_POWER


def body_reading(bgr: np.ndarray, body_bgr: tuple[int, int, int] | None, extent_px: float | None = None
                 ) -> tuple[Look, np.ndarray | None, int]:
    """What :func:`estimate_look` measures in a camera image (BGR uint8 (H, W, 3)) of a target painted ``body_bgr``:
    the :class:`Look` of its neutral alone, and the body's chroma relative to that neutral (2,) with its pixel count
    (:func:`body_chroma`; None, 0: no body found, no body paint given, or not a colour image)."""
    bgr = np.asarray(bgr)
    if bgr.dtype != np.uint8 or bgr.ndim != 3 or bgr.shape[2] != 3 or min(bgr.shape[:2]) < 2:
        return Look(), None, 0   # not a colour image: nothing to measure (the front-end says what is wrong with it)
    y, q = chroma_of(bgr)
    usable = (y >= LUMA_RANGE[0]) & (y <= LUMA_RANGE[1])
    neutral, spread = neutral_chroma(q, usable)
    shift = float(np.hypot(*(neutral - np.asarray(REFERENCE_NEUTRAL))))
    reference = np.asarray(REFERENCE_NEUTRAL, np.float32)
    if shift > MAX_NEUTRAL_SHIFT_WITH_BODY or (shift > MAX_NEUTRAL_SHIFT and body_bgr is None):
        neutral = reference   # no grey in the picture: a scene of one colour
    look = Look(neutral=(float(neutral[0]), float(neutral[1])))
    if body_bgr is None:
        return look, None, 0
    _, paint_q = chroma_of(np.array(body_bgr, np.uint8))
    if float(np.hypot(*paint_q)) < MIN_PAINT_CHROMA:
        return (look if shift <= MAX_NEUTRAL_SHIFT else Look()), None, 0
    # where the target is large its patch is found on a quarter of the pixels (LOOK_STRIDE_FROM_EXTENT_PX)
    stride = LOOK_STRIDE if (min(bgr.shape[:2]) >= LOOK_STRIDE_FROM_PX and extent_px is not None
                             and extent_px >= LOOK_STRIDE_FROM_EXTENT_PX) else 1
    seen, n = body_chroma(q, usable, neutral, spread, paint_q, extent_px, stride)
    if seen is None and shift > MAX_NEUTRAL_SHIFT and neutral is not reference:
        # a neutral this far off is a cast only if the body's paint stands out from it: else the picture's grey is
        # a paint (a close-up), and the reference neutral is kept
        neutral, look = reference, Look()
        seen, n = body_chroma(q, usable, neutral, spread, paint_q, extent_px, stride)
    return look, seen, n


def estimate_look(bgr: np.ndarray, body_bgr: tuple[int, int, int] | None, extent_px: float | None = None) -> Look:
    """The :class:`Look` of a camera image (BGR uint8 (H, W, 3)) of a target whose body is painted ``body_bgr`` (the
    model file's colour; None: the neutral only); ``extent_px``, the target's largest extent in pixels if known:
    the body's chroma read (:func:`body_reading`) against what the reference look makes of its paint
    (:func:`reference_body_chroma`, and :data:`REFERENCE_BODY_TURN_DEG`)."""
    look, seen, n = body_reading(bgr, body_bgr, extent_px)
    if seen is None:
        return look
    _, paint_q = chroma_of(np.array(body_bgr, np.uint8))
    gain = float(np.hypot(*seen)) / reference_body_chroma(float(np.hypot(*paint_q)))
    turn = float(np.arctan2(seen[1], seen[0]) - np.arctan2(paint_q[1], paint_q[0])) \
        - np.radians(REFERENCE_BODY_TURN_DEG)
    turn = float(wrap_angle(turn))
    gain = float(np.clip(gain, *SATURATION_RANGE))
    turn = float(np.clip(turn, -np.radians(MAX_TURN_DEG), np.radians(MAX_TURN_DEG)))
    return Look(neutral=look.neutral, saturation=gain, turn_rad=turn, body_pixels=n)


def hued_like_body(bgr: np.ndarray, look: Look, body_bgr: tuple[int, int, int], sure: np.ndarray,
                   extent_px: float | None = None) -> np.ndarray:
    """Which pixels of a camera image (BGR uint8 (H, W, 3)) are hued like the body painted ``body_bgr`` seen through
    ``look``, bool (H, W): their chroma relative to the look's neutral lies within :data:`BODY_TURN_DEG` of the
    paint's direction in that look, and reaches past what the ground beside the body shows in that direction (its
    90th percentile, from the pixels away from the ``sure`` paint (H, W) bool) by :data:`HUED_MARGIN`, and past
    the noise. A monotone tone curve, a saturation setting and a white balance keep a face's hue where they pull its
    chroma toward grey (a sunlit top face through a film curve's shoulder), so this holds where the body's paint,
    modelled in light, fits too little of it. Such a face is bright: a pixel darker than the sure paint's median luma
    is not taken (the second robot's yellow body beside warm sand under a low sun: its low-sun telephoto world's
    precision, lost by this rule without the bar, came back by +1.5..+1.6 points in three named looks, the Pioneer's
    telephoto benchmark worlds moved by -0.2..+0.5; so that robot is not held out from the bar).

    Only the sure paint's box grown by half the target's ``extent_px`` (when known) is looked at: a face of the body
    reaches no further; the ground and the noise are read on every :data:`HUED_GROUND_STRIDE`-th pixel."""
    _, paint_q = chroma_of(np.array(body_bgr, np.uint8))
    hued = np.zeros(sure.shape, bool)
    box = pixel_box(sure)
    if float(np.hypot(*paint_q)) < MIN_PAINT_CHROMA or box is None:
        return hued
    angle = np.arctan2(paint_q[1], paint_q[0]) + np.radians(REFERENCE_BODY_TURN_DEG) + look.turn_rad
    direction = np.array([np.cos(angle), np.sin(angle)], np.float32)
    normal = np.array([-direction[1], direction[0]], np.float32)
    neutral = np.asarray(look.neutral, np.float32)
    # the ground beside the body, and the chroma's noise, on a sample of the image
    k = HUED_GROUND_STRIDE
    y_s, q_s = chroma_of(np.ascontiguousarray(bgr[::k, ::k]))
    usable_s = (y_s >= LUMA_RANGE[0]) & (y_s <= LUMA_RANGE[1])
    spread = spread_about(q_s[..., 0][usable_s], q_s[..., 1][usable_s], neutral)
    reach = 2 * (GROUND_AWAY_PX // k) + 1   # the ground as vision.body_paint reads it: this far from the sure paint
    away = ~cv2.dilate(sure[::k, ::k].astype(np.uint8), np.ones((reach, reach), np.uint8)).astype(bool) & usable_s
    ground = (q_s[away] - neutral) @ direction
    bar = max(float(np.quantile(ground, 0.9)) if len(ground) else 0.0, 0.0) + HUED_MARGIN
    bar = max(bar, BODY_NOISE_SPREADS * spread)
    grow = int(np.ceil(extent_px / 2)) if extent_px is not None else max(sure.shape)
    y0, y1 = max(box[0] - grow, 0), min(box[1] + grow + 1, sure.shape[0])
    x0, x1 = max(box[2] - grow, 0), min(box[3] + grow + 1, sure.shape[1])
    # (q - neutral) along and across the paint's direction, times the luma: affine in (Y, Cr, Cb), one transform
    ycc = cv2.cvtColor(np.ascontiguousarray(bgr[y0:y1, x0:x1]), cv2.COLOR_BGR2YCrCb)
    affine = np.array([[-float(neutral @ direction), direction[0], direction[1], -128.0 * float(direction.sum())],
                       [-float(neutral @ normal), normal[0], normal[1], -128.0 * float(normal.sum())]], np.float32)
    scaled = cv2.transform(ycc.astype(np.float32), affine)                  # (h, w, 2): along Y, across Y
    y = ycc[..., 0]
    lit = sure[y0:y1, x0:x1] & (y >= LUMA_RANGE[0]) & (y <= LUMA_RANGE[1])
    # a face a tone curve's shoulder bleached is bright: at least the sure paint's median luma
    least = max(float(median(y[lit])) if lit.any() else LUMA_RANGE[0], LUMA_RANGE[0])
    along_y = scaled[..., 0]
    hued[y0:y1, x0:x1] = ((y >= least) & (y <= LUMA_RANGE[1]) & (along_y >= bar * y)
                          & (np.abs(scaled[..., 1]) <= along_y * np.float32(np.tan(np.radians(BODY_TURN_DEG)))))
    return hued


def beyond_band(look: Look) -> tuple[np.ndarray, float, float]:
    """What :func:`to_reference_look` undoes of ``look``: the neutral's shift (2,), the saturation gain and the turn
    (rad), each by as much as it lies beyond :data:`DEAD_BAND` (soft thresholding)."""
    off = np.subtract(look.neutral, REFERENCE_NEUTRAL)
    size = float(np.hypot(*off))
    shift = off * (max(size - DEAD_BAND[0], 0.0) / size) if size > 0 else np.zeros(2)
    log_gain = float(np.log(look.saturation))
    gain = float(np.exp(np.sign(log_gain) * max(abs(log_gain) - DEAD_BAND[1], 0.0)))
    turn = float(np.sign(look.turn_rad) * max(abs(look.turn_rad) - np.radians(DEAD_BAND[2]), 0.0))
    return shift, gain, turn


def to_reference_look(bgr: np.ndarray, look: Look) -> np.ndarray:
    """The image (BGR uint8 (H, W, 3)) as the reference look would show it: each pixel's chroma over luma ``q``
    mapped by ``R(-turn) (q - neutral) / gain + neutral - shift``, its luma kept, with the turn, gain and shift
    that lie beyond the reference look's own spread (:func:`beyond_band`). The image itself when ``look`` is
    within it (:attr:`Look.is_reference`).

    With ``q = (c - 128) / Y`` for a pixel's chroma ``c`` (Cr, Cb) and luma ``Y``, the map is affine in
    ``(Y, Cr, Cb)``: ``c' = 128 + M (c - 128) + Y (n - M n - shift)``, ``M = R(-turn) / gain``, one
    ``cv2.transform`` in float (a black pixel, ``Y = 0``, keeps no chroma: 128)."""
    if look.is_reference:
        return bgr
    shift, gain, turn = beyond_band(look)
    c, s = np.cos(-turn), np.sin(-turn)
    m = np.array([[c, -s], [s, c]]) / gain
    neutral = np.asarray(look.neutral, float)
    affine = np.zeros((3, 4))
    affine[0, 0] = 1.0                                   # Y kept
    affine[1:, 0] = neutral - m @ neutral - shift        # Y (n - M n - shift)
    affine[1:, 1:3] = m                                  # M c
    affine[1:, 3] = 128.0 - m @ (128.0, 128.0)           # 128 - M 128
    affine[:, 3] += 0.5                                  # rounded, then truncated as uint8
    ycc = cv2.cvtColor(bgr, cv2.COLOR_BGR2YCrCb)
    out = cv2.transform(ycc.astype(np.float32), affine.astype(np.float32))
    out = np.clip(out, 0, 255, out=out).astype(np.uint8)
    out[ycc[..., 0] == 0, 1:] = 128
    return cv2.cvtColor(out, cv2.COLOR_YCrCb2BGR)


__all__ = ["Look", "beyond_band", "body_chroma", "body_reading", "chroma_of", "estimate_look", "hued_like_body",
           "neutral_chroma", "reference_body_chroma", "spread_about", "to_reference_look"]
