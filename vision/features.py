"""Feature extraction: from a camera image to the unordered image points EvoPose matches.

The paper (Section IV) extracts colour marks with "standard filtering and corner detection".
Two paths, both pure functions of an image (no I/O, no global state):

- :func:`detect_colour_marks`: HSV thresholding (a palette, named hues or any saturated hue), components of one
  colour each, shape filters, coverage-weighted sub-pixel centroids; marks 15 px down to 2-4 px across;
- :func:`detect_corners`: Shi-Tomasi corners (``cv2.goodFeaturesToTrack``) refined by ``cv2.cornerSubPix``,
  for targets without colour marks.

Images are OpenCV BGR ``uint8`` arrays, shape (H, W, 3); points are pixels ``(u, v)`` with the
OpenCV convention that pixel centres have integer coordinates.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Union

import cv2
import numpy as np

#: Half-width of a colour's hue band, OpenCV hue units (0-180 per turn).
HUE_TOLERANCE = 10
#: Least saturation and value (0-255) of a mark pixel.
MIN_SATURATION, MIN_VALUE = 100, 50
#: Twelve 30-degree hue sectors (centred on OpenCV hues 0, 15, ...): labels of marks found without a palette.
HUE_NAMES = ("red", "orange", "yellow", "chartreuse", "green", "spring", "cyan", "azure", "blue", "violet",
             "magenta", "rose")
#: Half-width of a hue mode's band when searching any hue (at 2-4 px a fringe drifts to the background's hue).
ANY_HUE_TOLERANCE = 20
#: Distance from the line background -> mark colour (units of the mark's contrast) where a pixel's weight is 0.
OFF_LINE = 0.5
#: Largest misfit (units of contrast) of a blend of a neighbour and backgrounds: a fringe (green on red reads yellow).
BLEND_TOLERANCE = 0.16
_K3, _K5 = np.ones((3, 3), np.uint8), np.ones((5, 5), np.uint8)


@dataclass(frozen=True)
class ColourRange:
    """An HSV box of one mark colour (OpenCV: H 0-179, S and V 0-255); ``hue_lo > hue_hi`` wraps through 0."""

    name: str
    hue_lo: int
    hue_hi: int
    sat_lo: int = MIN_SATURATION
    val_lo: int = MIN_VALUE

    def mask(self, hsv: np.ndarray) -> np.ndarray:
        """uint8 mask (0/255), shape (H, W), of the pixels of ``hsv`` in this range."""
        if self.hue_lo <= self.hue_hi:
            return cv2.inRange(hsv, (self.hue_lo, self.sat_lo, self.val_lo), (self.hue_hi, 255, 255))
        low = cv2.inRange(hsv, (0, self.sat_lo, self.val_lo), (self.hue_hi, 255, 255))
        high = cv2.inRange(hsv, (self.hue_lo, self.sat_lo, self.val_lo), (179, 255, 255))
        return cv2.bitwise_or(low, high)


def hue_of(bgr) -> int:
    """OpenCV hue (0-179) of one BGR colour."""
    return int(cv2.cvtColor(np.uint8([[bgr]]), cv2.COLOR_BGR2HSV)[0, 0, 0])


def colour_ranges(palette: dict[str, tuple[int, int, int]], hue_tolerance: int = HUE_TOLERANCE,
                  min_saturation: int = MIN_SATURATION, min_value: int = MIN_VALUE) -> list[ColourRange]:
    """HSV ranges of the mark colours of a palette (name -> BGR), a hue band of +-``hue_tolerance`` each."""
    return [ColourRange(name, (hue_of(bgr) - hue_tolerance) % 180, (hue_of(bgr) + hue_tolerance) % 180, min_saturation,
                        min_value) for name, bgr in palette.items()]


def named_hue_ranges(names: Sequence[str], hue_tolerance: int = HUE_TOLERANCE) -> list[ColourRange]:
    """HSV ranges of named hues (:data:`HUE_NAMES`), e.g. ``["blue", "yellow"]`` from ``--colours blue,yellow``."""
    if unknown := [n for n in names if n.strip().lower() not in HUE_NAMES]:
        raise ValueError(f"unknown colour(s) {', '.join(unknown)}; known: {', '.join(HUE_NAMES)}")
    hues = [15 * HUE_NAMES.index(n.strip().lower()) for n in names]
    return [ColourRange(HUE_NAMES[h // 15], (h - hue_tolerance) % 180, (h + hue_tolerance) % 180) for h in hues]


def any_hue_ranges(image_bgr: np.ndarray, *, tol: int = ANY_HUE_TOLERANCE, separation: int = 16,
                   min_pixels: int = 2) -> list[ColourRange]:
    """Hue bands of every saturated colour in an image (uint8, (H, W, 3)), one per mode of its smoothed hue
    histogram (fixed sectors would cut a mark on a sector boundary in two), from the mode to the valley towards
    the next, at most ``tol`` away. Modes are over ``separation`` apart, a weaker maximum nearer is a blend's bump
    (12 admits mark-body blends; 20 loses blurred yellow marks on the Pioneer's red body at paper scale).
    Labels: :data:`HUE_NAMES` sectors, ``"<name>-h<hue>"`` for a second mode in one sector."""
    hsv = cv2.cvtColor(to_bgr(image_bgr), cv2.COLOR_BGR2HSV)
    hist = np.bincount(hsv[..., 0][(hsv[..., 1] >= MIN_SATURATION) & (hsv[..., 2] >= MIN_VALUE)], minlength=180) * 1.0
    smooth = sum(np.exp(-0.5 * (o / 2.0) ** 2) * np.roll(hist, -o) for o in range(-6, 7))
    mass = np.convolve(np.concatenate([hist[-tol:], hist, hist[:tol]]), np.ones(2 * tol + 1), "valid")
    peaks: list[int] = []   # local maxima, strongest first
    for p in sorted(range(180), key=lambda q: -smooth[q]):
        if (smooth[p] > smooth[p - 1] and smooth[p] >= smooth[(p + 1) % 180] and mass[p] >= min_pixels
                and all(min((p - q) % 180, (q - p) % 180) > separation for q in peaks)):
            peaks.append(p)
    peaks.sort()
    out, names = [], [HUE_NAMES[round(p / 15) % 12] for p in peaks]
    for i, p in enumerate(peaks):   # stop at the valleys towards the next and the previous mode
        up, down = (peaks[(i + 1) % len(peaks)] - p) % 180 or 180, (p - peaks[i - 1]) % 180 or 180
        hi = min(tol, int(np.argmin(smooth[(p + np.arange(up)) % 180]))) if len(peaks) > 1 else tol
        lo = min(tol, int(np.argmin(smooth[(p - np.arange(down)) % 180])) - 1) if len(peaks) > 1 else tol
        out.append(ColourRange(names[i] if names[i] not in names[:i] else f"{names[i]}-h{p}", (p - lo) % 180,
                               (p + hi) % 180))
    return out


@dataclass(frozen=True)
class MarkDetections:
    """Detected marks: ``points`` (K, 2) sub-pixel ``(u, v)``; ``labels`` (K,) index into ``names`` (colours, search
    order); ``areas`` (K,) pixels; ``touching`` (K,) bool: split off a one-colour component or 8-adjacent to a mark
    of another colour (a neighbour may pull its centroid)."""

    points: np.ndarray
    labels: np.ndarray
    areas: np.ndarray
    names: tuple[str, ...]
    touching: np.ndarray = field(default=None)  # type: ignore[assignment]  # None: no mark touches another

    def __post_init__(self) -> None:
        if self.touching is None:
            object.__setattr__(self, "touching", np.zeros(len(self.points), bool))

    def __len__(self) -> int:
        return len(self.points)

    def colours(self) -> list[str]:
        """Colour name of each point."""
        return [self.names[i] for i in self.labels]


def to_bgr(image: np.ndarray) -> np.ndarray:
    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise ValueError(f"image must be uint8, got {image.dtype}")
    if image.ndim == 3 and image.shape[2] in (3, 4):
        return image if image.shape[2] == 3 else cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    raise ValueError(f"colour marks need a BGR image of shape (H, W, 3), got {image.shape}")


Colours = Union[Sequence[ColourRange], Mapping[str, tuple[int, int, int]], Sequence[str], None]


def detect_colour_marks(image_bgr: np.ndarray, ranges: Colours = None, *, min_area: int = 2, max_area: int = 20000,
                        min_fill: float = 0.3, max_elongation: float = 4.0, drop_border: bool = True,
                        split_touching: bool = True) -> MarkDetections:
    """Colour marks in an image (uint8, (H, W, 3)): components of one colour, coverage-weighted sub-pixel centroids.

    ``ranges``: ColourRanges (:func:`colour_ranges`), a palette (name -> BGR), hue names (:func:`named_hue_ranges`)
    or, by default, every saturated hue in the image (:func:`any_hue_ranges`). ``min_area``, ``max_area``: limits
    in thresholded pixels (a 3 px mark thresholds to 2-9); ``min_fill``: least fraction of its box a component fills
    (a disc ~0.785, two blurred marks joined by a fringe ~0.4); ``max_elongation``: largest box aspect (edges,
    stripes); ``drop_border``: drop cut components; ``split_touching``: split a one-colour component at separate
    peaks. Points come sorted by colour then row. Dropped: a painted surface enclosing 3+ marks (the Pioneer's red
    body when any hue is searched), then a smaller neighbour's blend with the backgrounds (its fringe)."""
    bgr = to_bgr(image_bgr)
    if ranges is None:
        ranges = any_hue_ranges(bgr)
    elif isinstance(ranges, Mapping):
        ranges = colour_ranges(dict(ranges))
    elif len(ranges) and all(isinstance(r, str) for r in ranges):
        ranges = named_hue_ranges(ranges)
    names = tuple(r.name for r in ranges)
    if len(ranges) > 254:
        raise ValueError("at most 254 colours")
    h, w = bgr.shape[:2]
    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
    cidx = np.zeros((h, w), np.uint8)   # 0: no mark colour, k + 1: colour k (a later range wins an overlap)
    for k, colour in enumerate(ranges):
        cv2.max(cidx, cv2.bitwise_and(colour.mask(hsv), k + 1), dst=cidx)

    def passes(x: int, y: int, bw: int, bh: int, area: int) -> bool:
        return (min_area <= area <= max_area and area >= min_fill * bw * bh and max(bw, bh) <= max_elongation
                * min(bw, bh) and (not drop_border or (x > 0 and y > 0 and x + bw < w and y + bh < h)))

    ids, cands = _candidates(cidx, len(ranges), passes, min_area)
    pts, labs, areas, touch = [], [], [], []
    if cands:
        ids, img, shift = _pack(bgr, ids, cands)
        n, sizes = len(cands), np.array([0] + [c[5] for c in cands])
        st = _region_stats(img, ids, n)
        nbrs = st["pairs"]

        def drop(more: list[bool]) -> None:   # dropped candidates become background: measure again
            nonlocal ids, st
            if any(more):
                dropped[1:] |= more
                ids = np.where(dropped[np.maximum(ids, 0)] & (ids > 0), 0, ids).astype(np.int32)
                st = _region_stats(img, ids, n)

        dropped = np.zeros(n + 1, bool)   # painted surfaces first (marks on them have no background), then fringes
        drop([len(nbrs[i]) >= 3 and _encloses(ids, i, nbrs[i], sizes) for i in range(1, n + 1)])
        ok, ends = np.einsum("ij,ij->i", st["cb"], st["cb"]) > 1e-6, list(zip(st["b"], st["cb"]))
        drop([not dropped[i] and (not ok[i] or any(not dropped[j] and ok[j] and sizes[j] >= sizes[i]
                                                   and _is_blend(ends[i], ends[j]) for j in nbrs[i]))
              for i in range(1, n + 1)])
        for i in np.nonzero(~dropped[1:])[0] + 1:
            touching = any(not dropped[j] for j in nbrs[i])
            _, x, y, bw, bh, _ = cands[i - 1]
            x, y = x - int(shift[i, 0]), y - int(shift[i, 1])    # in the mosaic
            win = (slice(max(y - 2, 0), y + bh + 2), slice(max(x - 2, 0), x + bw + 2))
            two = split_touching and st["maxima"][i] > 1   # two coverage maxima: maybe two marks of one colour
            parts = _split(img[win], ids[win], i, st["b"][i], st["cb"][i]) if two else []
            parts = [(uv + (win[1].start, win[0].start), a) for uv, a in parts] or (
                [(st["sums"][i, 1:] / st["sums"][i, 0], sizes[i])] if st["sums"][i, 0] > 0 else [])
            for uv, area in parts:
                pts.append(uv + shift[i])
                labs.append(cands[i - 1][0]), areas.append(area), touch.append(len(parts) > 1 or touching)
    pts_a, lab_a = np.array(pts, float).reshape(-1, 2), np.array(labs, int)
    order = np.lexsort((pts_a[:, 0], pts_a[:, 1], lab_a))
    return MarkDetections(pts_a[order], lab_a[order], np.array(areas, int)[order], names, np.array(touch, bool)[order])


def _candidates(cidx: np.ndarray, n_colours: int, passes, min_area: int) -> tuple[np.ndarray, list[tuple[int, ...]]]:
    """One-colour components passing ``passes(x, y, w, h, area)``: ids (H, W) int32 (index + 1) and ``(colour, x,
    y, w, h, area)`` each. One labelling of all mark pixels, then one per colour in each component's box."""
    ids = np.zeros(cidx.shape, np.int32)
    x0, y0, rw, rh = cv2.boundingRect(cidx)
    if rw == 0 or rh == 0:
        return ids, []
    roi = cidx[y0:y0 + rh, x0:x0 + rw]
    n, lab, stats, _ = cv2.connectedComponentsWithStatsWithAlgorithm((roi > 0).view(np.uint8), 8, cv2.CV_32S,
                                                                     cv2.CCL_GRANA)
    on = np.flatnonzero(roi)
    votes = np.bincount(lab.ravel()[on] * (n_colours + 1) + roi.ravel()[on],
                        minlength=n * (n_colours + 1)).reshape(n, n_colours + 1)[:, 1:]
    cands: list[tuple[int, ...]] = []
    for j in np.nonzero(stats[1:, 4] >= min_area)[0] + 1:   # a part is no bigger than its component
        x, y, bw, bh, _ = stats[j].tolist()
        sl = (slice(y, y + bh), slice(x, x + bw))
        for k in (colours := np.nonzero(votes[j])[0]):
            if len(colours) == 1:   # the usual case: the component is of one colour
                sub_lab, sub_stats = (lab[sl] == j).view(np.uint8), [[0, 0, bw, bh, int(stats[j, 4])]]
            else:
                _, sub_lab, sub_stats, _ = cv2.connectedComponentsWithStats(
                    ((lab[sl] == j) & (roi[sl] == k + 1)).view(np.uint8), connectivity=8)
                sub_stats = sub_stats[1:].tolist()
            for q, (sx, sy, sw, sh, sa) in enumerate(sub_stats, 1):
                if passes(x0 + x + sx, y0 + y + sy, sw, sh, sa):
                    ids[y0 + y:y0 + y + bh, x0 + x:x0 + x + bw][sub_lab == q] = len(cands) + 1
                    cands.append((int(k), x0 + x + sx, y0 + y + sy, sw, sh, sa))
    return ids, cands


def _pack(bgr: np.ndarray, ids: np.ndarray, cands: list[tuple[int, ...]],
          pad: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The candidates' surroundings (boxes grown by ``pad``, the widest ring read; overlapping ones merged)
    stacked into a mosaic, so array statistics cost what marks cover, not the frame: ids (h, w) int32 (-1:
    outside), image (h, w, 3) float32, shift ``(du, dv)`` (n + 1, 2) from mosaic to image per candidate."""
    h, w = ids.shape
    boxes: list[list] = []
    for i, (_, x, y, bw, bh, _) in sorted(enumerate(cands), key=lambda c: c[1][1]):   # sweep left to right
        box = [max(x - pad, 0), max(y - pad, 0), min(x + bw + pad, w), min(y + bh + pad, h), [i + 1]]
        while hit := [o for o in boxes if o[2] > box[0] and o[0] < box[2] and o[3] > box[1] and o[1] < box[3]]:
            for other in hit:   # until the merged box overlaps no other
                boxes.remove(other)
                box = [min(box[0], other[0]), min(box[1], other[1]), max(box[2], other[2]), max(box[3], other[3]),
                       box[4] + other[4]]
        boxes.append(box)
    m_ids = np.full((sum(b[3] - b[1] + pad for b in boxes), max(b[2] - b[0] for b in boxes)), -1, np.int32)
    m_img = np.zeros((*m_ids.shape, 3), np.float32)
    shift, top = np.zeros((len(cands) + 1, 2)), 0
    for x0, y0, x1, y1, members in boxes:
        m_ids[top:top + y1 - y0, :x1 - x0] = ids[y0:y1, x0:x1]
        m_img[top:top + y1 - y0, :x1 - x0] = bgr[y0:y1, x0:x1]
        shift[members] = (x0, y0 - top)
        top += y1 - y0 + pad
    return m_ids, m_img, shift


def _encloses(ids: np.ndarray, i: int, nbrs: set[int], sizes: np.ndarray) -> bool:
    """Whether candidate ``i`` (ids (h, w)) encloses 3+ neighbours a third its size or less (marks on a body)."""
    if len(small := [j for j in nbrs if 3 * sizes[j] <= sizes[i]]) < 3:
        return False
    contours, _ = cv2.findContours((ids == i).view(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    inside = cv2.drawContours(np.zeros(ids.shape, np.uint8), contours, -1, 1, -1).view(bool)
    return sum(2 * np.count_nonzero(inside & (ids == j)) >= sizes[j] for j in small) >= 3


def _region_stats(img: np.ndarray, ids: np.ndarray, n: int) -> dict:
    """End-members, neighbours, weighted moments of all candidates (rows 1..n of (n + 1, 3) arrays): ``b`` background,
    median of the free ring 2 px out (0 if none: crowded marks); ``cb`` = ``c - b``, ``c`` the mean of pixels within
    80 % of the farthest from ``b``; ``sums`` ``(sum a, sum a u, sum a v)`` of :func:`mark_coverage` over pixels and 1 px
    fringe; ``pairs`` the 8-adjacent ids of each; ``maxima`` (n + 1,) local maxima of the smoothed coverage.
    img (h, w, 3) float32, ids (h, w) int32 (index + 1; 0 free; -1 out)."""
    def owners(mask: np.ndarray, hi: np.ndarray, lo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        pix = np.flatnonzero(mask)   # and their owners: the highest and lowest id around (a shared pixel counts twice)
        a, c = hi.ravel()[pix].astype(np.int64), lo.ravel()[pix].astype(np.int64)
        return np.concatenate([pix, pix[(c != a) & (c <= n)]]), np.concatenate([a, c[(c != a) & (c <= n)]])

    idf = np.maximum(ids, 0).astype(np.float32)
    low = np.where(ids > 0, idf, np.float32(n + 1))
    near_hi, near_lo = cv2.dilate(idf, _K3), cv2.erode(low, _K3)
    flat, free = img.reshape(-1, 3), (ids == 0) & (near_hi == 0)
    ring_hi = cv2.dilate(idf, _K5)   # b: median per owner and channel of integers: sort keys owner * 256 + value
    r_pix, r_id = owners(free & (ring_hi > 0), ring_hi, cv2.erode(low, _K5))
    c, b = np.bincount(r_id, minlength=n + 1), np.zeros((n + 1, 3), np.float32)
    keys = np.sort(r_id[:, None] * 256 + flat[r_pix].astype(np.int64), axis=0)
    b[c > 0] = keys[np.minimum(np.cumsum(c) - c + c // 2, len(r_id) - 1)][c > 0] % 256 if len(r_id) else 0
    o_id = ids.ravel()[(o_pix := np.flatnonzero(ids > 0))].astype(np.int64)
    d = flat[o_pix] - b[o_id]
    far = (d * d).sum(axis=1)
    top = np.zeros(n + 1, np.float32)   # the farthest pixel per candidate
    np.maximum.at(top, o_id, far)
    sel = far >= 0.64 * top[o_id]
    o_sel, d_sel = o_id[sel], d[sel]
    cb = np.stack([np.bincount(o_sel, d_sel[:, ch], n + 1) for ch in range(3)], axis=1)
    cb = (cb / np.maximum(np.bincount(o_sel, minlength=n + 1), 1)[:, None]).astype(np.float32)
    nb, mine = np.concatenate([near_hi.ravel()[o_pix], near_lo.ravel()[o_pix]]).astype(np.int64), np.tile(o_id, 2)
    pairs: list[set[int]] = [set() for _ in range(n + 1)]   # the ids 8-adjacent to each
    for code in np.unique((mine * (n + 2) + nb)[(nb != mine) & (nb <= n)]).tolist():
        pairs[code // (n + 2)].add(code % (n + 2))
    f_pix, f_id = owners((ids == 0) & (near_hi > 0), near_hi, near_lo)
    pix, own = np.concatenate([o_pix, f_pix]), np.concatenate([o_id, f_id])
    a, w = mark_coverage(flat[pix] - b[own], cb[own]), img.shape[1]
    sums = np.stack([np.bincount(own, a, n + 1), np.bincount(own, a * (pix % w), n + 1),
                     np.bincount(own, a * (pix // w), n + 1)], axis=1)
    # local maxima of the smoothed coverage: where two marks may touch
    cover = cv2.GaussianBlur(np.bincount(pix, a, ids.size).reshape(ids.shape).astype(np.float32), (0, 0), 0.7)
    maxima = np.bincount(ids[(cover >= cv2.dilate(cover, _K3)) & (ids > 0) & (cover > 0.1)], minlength=n + 1)
    return {"b": b, "cb": cb, "sums": sums, "pairs": pairs, "maxima": maxima}


def mark_coverage(d: np.ndarray, cb: np.ndarray, top: float = 1.0) -> np.ndarray:
    """Fraction of a pixel its mark covers (at most ``top``), from ``d = p - b``, ``cb = c - b`` (shapes (..., 3)).
    Anti-aliasing and blur mix linearly, ``p = a c + (1 - a) b``, so ``a = d.cb / |cb|^2``: the a-weighted centroid
    is the covered area's, where 2-4 px binary moments are off by up to 1/3 px. Pixels off the line ``b`` -> ``c``
    (a neighbour: pure green projects 0.7 onto yellow minus red) lose weight with the distance, 0 at OFF_LINE."""
    norm = np.maximum(np.einsum("...k,...k->...", cb, cb), 1e-6)
    a = np.einsum("...k,...k->...", d, cb) / norm
    off = np.sqrt(np.maximum(np.einsum("...k,...k->...", d, d) / norm - a * a, 0.0))
    return np.clip(a, 0.0, top) * np.clip(1.0 - off / OFF_LINE, 0.0, 1.0)


def _is_blend(small: tuple, big: tuple, tol: float = BLEND_TOLERANCE) -> bool:
    """Whether ``small``'s colour mixes ``big``'s and both backgrounds (``(b, c - b)`` pairs, (3,) each): at a body's
    edge a fringe blends green mark, red body, ground. ``c_small - b_small ~ s (c_big - b_small) + r (b_big -
    b_small)``, least squares, ``r`` then held to [0, 1] (ill-conditioned for near-equal backgrounds) and ``s``
    refitted; a blend has a fraction ``s`` (a mark is purer than a fringe) and fits within ``tol``."""
    b, cb_small = small
    towards, other_bg = big[0] + big[1] - b, big[0] - b
    tt, to, oo = float(towards @ towards), float(towards @ other_bg), float(other_bg @ other_bg)
    if tt < 1e-6:
        return False
    det = tt * oo - to * to
    r = (tt * float(other_bg @ cb_small) - to * float(towards @ cb_small)) / det if det > 1e-6 * tt * oo else 0.0
    r = min(max(r, 0.0), 1.0)
    s = float((cb_small - r * other_bg) @ towards) / tt
    return 0.05 < s < 0.95 and float(np.linalg.norm(cb_small - s * towards - r * other_bg)) < tol * np.sqrt(tt)


def _split(patch: np.ndarray, ids: np.ndarray, me: int, b: np.ndarray, cb: np.ndarray) -> list[tuple[np.ndarray, int]]:
    """Coverage-weighted centroids ``(u, v)`` (patch px) and sizes of a candidate's parts split at separate peaks (a
    pixel to the nearest: touching marks of one colour are of similar size); [] for one peak or a big convex blob
    (one oblique disc). Shapes: patch (h, w, 3) float32, ids (h, w) int32, b and cb (3,)."""
    own = ids == me
    if own.sum() >= 80:   # solidity: outline area over convex hull area
        outline = max(cv2.findContours(own.view(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)[0],
                      key=cv2.contourArea)
        if cv2.contourArea(outline) >= 0.9 * cv2.contourArea(cv2.convexHull(outline)):
            return []
    support = cv2.dilate(own.view(np.uint8), _K3).view(bool) & ((ids == 0) | own)
    alpha = (mark_coverage(patch - b, cb) * support).astype(np.float32)
    peak = (mark_coverage(patch - b, cb, np.inf) * support).astype(np.float32)   # unclipped: peaks stay peaks
    sigma = max(0.6, 0.25 * float(np.sqrt(own.sum() / np.pi)))   # mask density (necks) plus coverage (dips):
    score = cv2.GaussianBlur(own.astype(np.float32) * 0.3 + peak, (0, 0), sigma)
    rows, cols = np.nonzero((score >= cv2.dilate(score, _K3)) & own & (score >= 0.25 * score.max()))
    peaks: list[tuple[int, int]] = []
    for q in np.argsort(-score[rows, cols], kind="stable")[:12]:   # a peak: the line to each stronger one dips
        r, c = int(rows[q]), int(cols[q])
        lines = [(max(abs(pr - r), abs(pc - c)) + 1, pr, pc) for pr, pc in peaks]
        if all(k > 2 and score[np.rint(np.linspace(r, pr, k)).astype(int), np.rint(np.linspace(c, pc, k)).astype(int)]
               .min() < 0.93 * score[r, c] for k, pr, pc in lines):
            peaks.append((r, c))
    if len(peaks) < 2:
        return []
    rr, cc = np.mgrid[:own.shape[0], :own.shape[1]]
    nearest = np.argmin(np.stack([(rr - r) ** 2 + (cc - c) ** 2 for r, c in peaks]), axis=0)
    return [(np.array([(w * cc).sum(), (w * rr).sum()]) / w.sum(), int((own & (nearest == q)).sum()))
            for q in range(len(peaks)) if (w := alpha * (nearest == q)).sum() > 0]


def detect_corners(image: np.ndarray, *, max_corners: int = 200, quality: float = 0.05, min_distance: float = 6.0,
                   block_size: int = 5, subpix_window: int = 4, mask: np.ndarray | None = None) -> np.ndarray:
    """Shi-Tomasi corners refined to sub-pixel accuracy: the generic path for targets without colour marks.

    ``image`` uint8 (H, W) or (H, W, 3); ``max_corners``, ``quality``, ``min_distance``, ``block_size`` as
    ``cv2.goodFeaturesToTrack`` (quality relative to the strongest; pixels); ``subpix_window`` half-size of the
    ``cv2.cornerSubPix`` window (0: no refinement); ``mask`` uint8 (H, W), where to look. Returns corners
    ``(u, v)``, shape (K, 2), strongest first.
    """
    image = np.asarray(image)
    if image.dtype != np.uint8 or image.ndim not in (2, 3):
        raise ValueError(f"corners need a uint8 grey or BGR image, got {image.dtype} {image.shape}")
    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image
    found = cv2.goodFeaturesToTrack(grey, max_corners, quality, min_distance, mask=mask, blockSize=block_size)
    if found is None:
        return np.zeros((0, 2))
    corners = found.astype(np.float32)
    if subpix_window > 0:
        criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 30, 0.01)
        corners = cv2.cornerSubPix(grey, corners, (subpix_window, subpix_window), (-1, -1), criteria)
    return corners.reshape(-1, 2).astype(float)


def x_junctions(image: np.ndarray, corners: np.ndarray, radius: float = 5.0, samples: int = 32) -> np.ndarray:
    """Which corners are X-junctions (a chessboard's inner corners), not L-corners of an outline.

    Around an X-junction the intensity on a circle of ``radius`` pixels crosses its mean
    four times (dark, light, dark, light); around the corner of a box or of the board's
    border it crosses twice. Shapes: image (H, W) or (H, W, 3) uint8, corners (K, 2) -> (K,) bool.
    """
    image = np.asarray(image)
    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image
    grey = grey.astype(np.float32)
    corners = np.asarray(corners, float).reshape(-1, 2)
    if len(corners) == 0:
        return np.zeros(0, bool)
    angles = np.linspace(0, 2 * np.pi, samples, endpoint=False)
    xs = (corners[:, :1] + radius * np.cos(angles)).astype(np.float32)
    ys = (corners[:, 1:] + radius * np.sin(angles)).astype(np.float32)
    ring = cv2.remap(grey, xs, ys, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)  # (K, samples)
    centred = ring - ring.mean(axis=1, keepdims=True)
    contrast = np.percentile(np.abs(centred), 75, axis=1)
    sign = np.where(np.abs(centred) > 0.25 * contrast[:, None], np.sign(centred), 0.0)
    crossings = np.zeros(len(corners), int)
    for k in range(len(corners)):  # count sign changes around the ring, ignoring near-mean samples
        s_k = sign[k][sign[k] != 0]
        if len(s_k) > 1:
            crossings[k] = int(np.count_nonzero(s_k != np.roll(s_k, 1)))
    return crossings == 4


def match_to_truth(detected: np.ndarray, truth: np.ndarray, max_distance: float = 3.0) -> tuple[np.ndarray, np.ndarray]:
    """Greedy one-to-one matching of detected points to true points (nearest pairs first): ``pairs`` (P, 2) of
    ``(detected index, truth index)`` closer than ``max_distance`` pixels, and their ``distances`` (P,)."""
    detected, truth = np.asarray(detected, float).reshape(-1, 2), np.asarray(truth, float).reshape(-1, 2)
    if not len(detected) or not len(truth):
        return np.zeros((0, 2), int), np.zeros(0)
    d = np.linalg.norm(detected[:, None, :] - truth[None, :, :], axis=2)
    order = np.argsort(d, axis=None, kind="stable")
    used_d, used_t, pairs, dist = set(), set(), [], []
    for flat in order:
        i, j = divmod(int(flat), len(truth))
        if d[i, j] > max_distance:
            break
        if i in used_d or j in used_t:
            continue
        used_d.add(i); used_t.add(j)
        pairs.append((i, j)); dist.append(d[i, j])
    return np.array(pairs, int).reshape(-1, 2), np.array(dist)
