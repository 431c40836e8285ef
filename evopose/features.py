"""Feature extraction: from a camera image to the unordered image points EvoPose matches.

The paper (Section IV) extracts colour marks with "standard filtering and corner detection".
Two paths, both pure functions of an image (no I/O, no global state):

- :func:`detect_colour_marks`: HSV thresholding per mark colour, connected components, area and
  shape filters, sub-pixel centroids (first image moments of each component), optionally a colour label;
- :func:`detect_corners`: Shi-Tomasi corners (``cv2.goodFeaturesToTrack``) refined by ``cv2.cornerSubPix``,
  for targets without colour marks.

Images are OpenCV BGR ``uint8`` arrays, shape (H, W, 3); points are pixels ``(u, v)`` with the
OpenCV convention that pixel centres have integer coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

#: Half-width of a colour's hue band, OpenCV hue units (0-180 per turn).
HUE_TOLERANCE = 10
#: Least saturation and value (0-255) of a mark pixel.
MIN_SATURATION, MIN_VALUE = 100, 50


@dataclass(frozen=True)
class ColourRange:
    """An HSV box of one mark colour (OpenCV ranges: H 0-179, S and V 0-255).

    A hue band with ``hue_lo > hue_hi`` wraps through 0 (reds).
    """

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
    out = []
    for name, bgr in palette.items():
        h = hue_of(bgr)
        out.append(ColourRange(name, (h - hue_tolerance) % 180, (h + hue_tolerance) % 180, min_saturation, min_value))
    return out


@dataclass(frozen=True)
class MarkDetections:
    """Detected marks.

    Attributes
    ----------
    points : array, shape (K, 2)
        Sub-pixel centroids ``(u, v)``.
    labels : int array, shape (K,)
        Index into ``names`` of each point's colour.
    areas : int array, shape (K,)
        Pixels per component.
    names : tuple of str
        The colour names, in the order of the ranges searched.
    """

    points: np.ndarray
    labels: np.ndarray
    areas: np.ndarray
    names: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.points)

    def colours(self) -> list[str]:
        """Colour name of each point."""
        return [self.names[i] for i in self.labels]


def _to_bgr(image: np.ndarray) -> np.ndarray:
    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise ValueError(f"image must be uint8, got {image.dtype}")
    if image.ndim == 3 and image.shape[2] == 3:
        return image
    if image.ndim == 3 and image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    raise ValueError(f"colour marks need a BGR image of shape (H, W, 3), got {image.shape}")


def detect_colour_marks(image_bgr: np.ndarray, ranges: list[ColourRange], *, min_area: int = 6,
                        max_area: int = 20000, min_fill: float = 0.45, max_elongation: float = 4.0,
                        drop_border: bool = True) -> MarkDetections:
    """Colour marks in an image: thresholding, connected components, sub-pixel centroids.

    Parameters
    ----------
    image_bgr : uint8 array, shape (H, W, 3)
    ranges : list of ColourRange
        One per mark colour (see :func:`colour_ranges`).
    min_area, max_area : int
        Component size limits in pixels (noise specks; large coloured surfaces).
    min_fill : float
        Least fraction of its bounding box a component fills (a disc or ellipse fills ~0.785).
    max_elongation : float
        Largest bounding-box aspect ratio (edges and stripes are rejected).
    drop_border : bool
        Drop components touching the image border (their centroid is cut).

    Returns
    -------
    MarkDetections
        Points sorted by colour then by image row, deterministic for an image. Touching blobs of
        different colours form one component (labelled with its majority colour).
    """
    bgr = _to_bgr(image_bgr)
    names = tuple(r.name for r in ranges)
    if len(ranges) > 254:
        raise ValueError("at most 254 colours")
    h, w = bgr.shape[:2]
    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
    # one colour-index image (0: no mark colour, k + 1: colour k), then one labelling over all colours
    cidx = np.zeros((h, w), np.uint8)
    for k, colour in enumerate(ranges):
        cv2.max(cidx, cv2.bitwise_and(colour.mask(hsv), k + 1), dst=cidx)
    x0, y0, rw, rh = cv2.boundingRect(cidx)
    if rw == 0 or rh == 0:
        return MarkDetections(np.zeros((0, 2)), np.zeros(0, int), np.zeros(0, int), names)
    roi = cidx[y0:y0 + rh, x0:x0 + rw]
    n, labels, stats, centroids = cv2.connectedComponentsWithStatsWithAlgorithm(roi, 8, cv2.CV_32S, cv2.CCL_GRANA)
    x, y, bw, bh, area = (stats[1:, i] for i in range(5))
    keep = (area >= min_area) & (area <= max_area) & (area >= min_fill * bw * bh)
    keep &= np.maximum(bw, bh) <= max_elongation * np.minimum(bw, bh)
    if drop_border:
        keep &= (x + x0 > 0) & (y + y0 > 0) & (x + x0 + bw < w) & (y + y0 + bh < h)
    idx = np.nonzero(keep)[0]
    if len(idx) == 0:
        return MarkDetections(np.zeros((0, 2)), np.zeros(0, int), np.zeros(0, int), names)
    # the colour of a component: the most frequent colour among its pixels
    on = np.flatnonzero(roi)
    votes = np.bincount(labels.ravel()[on] * (len(ranges) + 1) + roi.ravel()[on],
                        minlength=n * (len(ranges) + 1)).reshape(n, len(ranges) + 1)
    lab = np.argmax(votes[1:][idx, 1:], axis=1)
    pts = centroids[1:][idx] + [x0, y0]
    order = np.lexsort((pts[:, 0], pts[:, 1], lab))
    return MarkDetections(pts[order], lab[order], area[idx][order], names)


def detect_corners(image: np.ndarray, *, max_corners: int = 200, quality: float = 0.05, min_distance: float = 6.0,
                   block_size: int = 5, subpix_window: int = 4, mask: np.ndarray | None = None) -> np.ndarray:
    """Shi-Tomasi corners refined to sub-pixel accuracy: the generic path for targets without colour marks.

    Parameters
    ----------
    image : uint8 array, shape (H, W) or (H, W, 3)
    max_corners, quality, min_distance, block_size
        As ``cv2.goodFeaturesToTrack`` (quality relative to the strongest corner; distance in pixels).
    subpix_window : int
        Half-size of the ``cv2.cornerSubPix`` search window (pixels); 0 skips the refinement.
    mask : uint8 array, shape (H, W), optional
        Where to look (non-zero).

    Returns
    -------
    array, shape (K, 2)
        Corners ``(u, v)``, strongest first.
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
    """Greedy one-to-one matching of detected points to true points (nearest pairs first).

    Returns
    -------
    pairs : int array, shape (P, 2)
        ``(detected index, truth index)`` of the pairs closer than ``max_distance`` pixels.
    distances : array, shape (P,)
    """
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
