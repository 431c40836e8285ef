"""Which image points a target gives EvoPose: its colour marks, or a chessboard's inner corners.

``--features marks`` (the default of ``evopose agent`` and ``evopose solve --image``) finds the model's colour
marks (:func:`evopose.features.detect_colour_marks`, the paper's Section IV); ``--features corners`` finds
Shi-Tomasi corners (:func:`evopose.features.detect_corners`) and keeps the X-junctions
(:func:`evopose.features.x_junctions`), the inner corners of a chessboard: a board's outline and the corners
of boxes are L-corners and would let a grid shifted by one square fit as well as the true one. Either way the
points are unordered: EvoPose needs no correspondences (eq. 1). Marks come with their colour's index in the
model's palette (:func:`feature_extractor`), the label a point is matched by (our extension of eq. 1,
:attr:`evopose.Model.labels`); corners are untyped.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from evopose.features import colour_ranges, detect_colour_marks, detect_corners, x_junctions

#: The kinds of feature points (``--features``).
FEATURE_KINDS = ("marks", "corners")
#: Shi-Tomasi settings of ``corners``: at most this many corners, quality relative to the strongest, spacing in
#: pixels (a 640 x 480 photo of a 9 x 6 board 0.3-0.4 m away: squares of 30-60 px).
MAX_CORNERS, CORNER_QUALITY, CORNER_SPACING_PX = 150, 0.05, 8.0

Extractor = Callable[[np.ndarray], np.ndarray]
#: ``image (H, W, 3) uint8 -> (points (N, 2), labels (N,) or None)``.
FeatureExtractor = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray | None]]


def chessboard_corners(image: np.ndarray) -> np.ndarray:
    """The X-junction corners of a BGR or grey uint8 image, shape (K, 2), pixels."""
    found = detect_corners(image, max_corners=MAX_CORNERS, quality=CORNER_QUALITY, min_distance=CORNER_SPACING_PX)
    return found[x_junctions(image, found)]


def feature_extractor(kind: str, palette: dict[str, tuple[int, int, int]]) -> FeatureExtractor:
    """``image (H, W, 3) uint8 -> (points (N, 2), labels (N,) or None)`` for ``kind`` (one of
    :data:`FEATURE_KINDS`); ``palette`` is the model's mark colours (name -> BGR), used by ``marks``, whose labels
    are each mark's colour index in ``palette`` (the order of :meth:`scenarios.target.TargetModel.colour_labels`)."""
    if kind == "corners":
        return lambda image: (chessboard_corners(image), None)
    if kind != "marks":
        raise ValueError(f"features must be one of {', '.join(FEATURE_KINDS)}, got {kind!r}")
    ranges = colour_ranges(palette)

    def marks(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        found = detect_colour_marks(image, ranges)
        return found.points, found.labels

    return marks


def point_extractor(kind: str, palette: dict[str, tuple[int, int, int]]) -> Extractor:
    """``image (H, W, 3) uint8 -> points (N, 2)``: :func:`feature_extractor` without the labels."""
    extract = feature_extractor(kind, palette)
    return lambda image: extract(image)[0]


__all__ = ["FEATURE_KINDS", "chessboard_corners", "feature_extractor", "point_extractor"]
