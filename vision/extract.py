"""Which image points a target gives EvoPose: its colour marks, or a chessboard's inner corners.

``--features auto`` (the default of ``evopose agent`` and ``evopose solve --image``) is ``contrast`` on camera images
and ``marks`` on drawn worlds (:func:`resolve_features`). ``--features marks`` finds the model's colour
marks by preset hue bands (:func:`vision.features.detect_colour_marks`, the paper's Section IV: flat-coloured
drawings); ``--features contrast`` by their contrast (:func:`vision.blobs.detect_contrast_marks`: camera images);
``--features corners`` finds
Shi-Tomasi corners (:func:`vision.features.detect_corners`) and keeps the X-junctions
(:func:`vision.features.x_junctions`), the inner corners of a chessboard: a board's outline and the corners
of boxes are L-corners and would let a grid shifted by one square fit as well as the true one. Either way the
points are unordered: EvoPose needs no correspondences (eq. 1). Marks come with their colour's index in the
model's palette (:func:`feature_extractor`), the label a point is matched by (our extension of eq. 1,
:attr:`evopose.Model.labels`); corners are untyped. ``contrast`` and ``marks`` look for the marks in a window of
the image (:mod:`vision.window`): around the projection of a pose the target is expected near (``near``: a vehicle's
last good one), else (``contrast``, given the camera and the operating area) around the body's paint found at half
resolution; the whole image when the window gives too few.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Protocol

import numpy as np

from evopose import Bounds, Camera
from vision.blobs import MarkPrior, crop_margin, detect_contrast_marks, mark_prior
from vision.mark_context import resolve_scorers
from vision.camera_look import estimate_look
from vision.look_tracker import LookTracker
from vision.label_chroma import LabelChromaGate, spot_chroma
from vision.features import MarkDetections, colour_ranges, detect_colour_marks, detect_corners, x_junctions
from vision.front_end_pace import FrontEndPace, detect_halved, largest_mark_px
from vision.scale_space import halved_image
from vision.mark_scorer import MarkScorer
from vision.spot_position import SMALL_SPOT_PX
from vision.window import Window, grown, locate_body, target_window
from scenarios.fleet import FEATURE_KINDS
from scenarios.target import TargetModel

#: Shi-Tomasi settings of ``corners``: at most this many corners, quality relative to the strongest, spacing in
#: pixels (a 640 x 480 photo of a 9 x 6 board 0.3-0.4 m away: squares of 30-60 px).
MAX_CORNERS, CORNER_QUALITY, CORNER_SPACING_PX = 150, 0.05, 8.0


class FeatureExtractor(Protocol):
    """``extract(image (H, W, 3) uint8, camera or None, near=None) -> (points (N, 2), labels (N,) or None)``: every
    detector behind one call. ``camera`` (with its ``world_from_camera``) lets a detector know how large the target's
    marks can be in this image (:func:`vision.blobs.mark_prior`); without it a generic range is searched. ``near``, a
    pose (``world_from_target`` (6,)) the target is expected near (the last good estimate): ``contrast`` and ``marks``
    then look in a window around its projection first (:mod:`vision.window`); ``corners`` takes the whole image.
    ``contrast``'s extractor also says whether its last frame ran on the image halved to keep the camera's rate (its
    ``halved`` attribute, :mod:`vision.front_end_pace`)."""

    def __call__(self, image: np.ndarray, camera: Camera | None = None,
                 near: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        ...


Extractor = Callable[[np.ndarray], np.ndarray]


def chessboard_corners(image: np.ndarray) -> np.ndarray:
    """The X-junction corners of a BGR or grey uint8 image, shape (K, 2), pixels."""
    found = detect_corners(image, max_corners=MAX_CORNERS, quality=CORNER_QUALITY, min_distance=CORNER_SPACING_PX)
    return found[x_junctions(image, found)]


def resolve_features(kind: str, camera_images: bool) -> str:
    """The front-end ``kind`` names: ``auto`` is ``contrast`` on camera images (a real camera, a dataset, a world
    with a camera model: any tone curve, white balance or saturation, :mod:`vision.camera_look`) and ``marks`` on
    the project's flat-coloured drawings, where the preset hue bands find every mark (BENCHMARKS.md, "Mark
    front-ends through camera looks"); any other kind is itself."""
    if kind != "auto":
        return kind
    return "contrast" if camera_images else "marks"


#: Once a camera's look is tracked (nine estimates), it is estimated again every this many frames
#: (:class:`vision.look_tracker.LookTracker`).
LOOK_EVERY = 4
#: A window around the expected target (:mod:`vision.window`) that gives fewer marks than this is searched no further:
#: the whole image is, in the same frame (fewer than four points leave a pose from one view undetermined).
MIN_WINDOW_MARKS = 4


def feature_extractor(kind: str, target: TargetModel, area: Bounds | None = None,
                      scorer: MarkScorer | str | None = None, period_s: float | None = None) -> FeatureExtractor:
    """The :class:`FeatureExtractor` of ``kind`` (one of :data:`FEATURE_KINDS`) for ``target``: ``marks`` and
    ``contrast`` label each mark with its colour's index in the model's palette (the order of
    :meth:`scenarios.target.TargetModel.colour_labels`), except where a camera's 2-4 px marks keep too little of
    their colour for a label (``contrast``: :class:`vision.label_chroma.LabelChromaGate`, labels None); ``area`` is
    the operating area (world x, y, z bounds of the target) from which ``contrast`` derives the marks' size in each
    camera's image. ``scorer``: which spots
    ``contrast`` keeps as marks (:func:`vision.blobs.detect_contrast_marks`: None or ``"shipped"`` the shipped
    scorers, ``"bars"`` the hand-set bars, or a small-spot scorer or context model replacing the shipped one of its
    kind); ValueError when a scorer was fitted on other features than the front-end computes. ``period_s``: the
    camera's frame period, which ``contrast`` keeps by running on the image halved where the target is large and its
    frames at full resolution take too long (:mod:`vision.front_end_pace`; None: always full resolution)."""
    if kind == "auto":
        raise ValueError("resolve 'auto' first (resolve_features): whether the images come from a camera")
    if kind == "corners":
        return lambda image, camera=None, near=None: (chessboard_corners(image), None)
    outline = target.body.vertices if len(target.body.vertices) else target.mark_points
    if kind == "marks":
        ranges = colour_ranges(target.palette)

        def hue_marks(image: np.ndarray, camera: Camera | None = None,
                      near: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
            # hue bands need no ground around the body: the window is the body's projection and the slack
            window = None if near is None or camera is None else target_window(camera, near, outline, 0.0)
            found, points = window_first(lambda part: detect_colour_marks(part, ranges), image, window)
            return points, found.labels

        return hue_marks
    if kind != "contrast":
        raise ValueError(f"features must be one of {', '.join(FEATURE_KINDS)}, got {kind!r}")
    palette, size, body = dict(target.palette), target.size, target.body_colour
    resolve_scorers(scorer, tuple(palette))   # a bad name or file is an error now, not at the first frame

    looks: dict[tuple, LookTracker] = {}   # per camera (its intrinsics): a camera keeps its look
    gates: dict[tuple, LabelChromaGate] = {}   # and its encoder: whether its 2-4 px marks keep their colour
    paces: dict[tuple, FrontEndPace] = {}   # and how long its frames take

    def contrast_marks(image: np.ndarray, camera: Camera | None = None,
                       near: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        start = time.perf_counter()
        prior = MarkPrior() if camera is None or area is None else mark_prior(
            camera, target.mark_radius, size, area.lo[:3], area.hi[:3])
        key = None if camera is None else (camera.fx, camera.fy, camera.cx, camera.cy, camera.width, camera.height)
        tracker = looks.setdefault(key, LookTracker(every=LOOK_EVERY))
        followed = None if near is None or camera is None else target_window(camera, near, outline,
                                                                             crop_margin(prior))
        window = followed
        if window is None and camera is not None and area is not None and body is not None:
            # no pose to look near: the body's paint found at half resolution first (vision.window.locate_body)
            box = locate_body(image, body, tracker.latest)
            window = None if box is None else grown(box, crop_margin(prior), image.shape[1], image.shape[0])
        y0, y1, x0, x1 = window or (0, image.shape[0], 0, image.shape[1])
        part = image[y0:y1, x0:x1]
        # the camera's look from the window when it follows a pose (the body and the ground around it); else from the
        # whole image: a paint-box window's ground, in a cold flat look at the paper's scale, set a look that never
        # let the pair find the robot (looks-long paper-g2-low-flat-cool: 0 good frames of 40 instead of 12)
        seen = image if followed is None else part
        pace = paces.setdefault(key, FrontEndPace(period_s))
        halve = pace.halve(prior, None if near is None or camera is None else
                           largest_mark_px(camera, near, target.mark_radius))
        if tracker.due():   # on the image halved too when the front-end is (a look is the body's colour statistics)
            look = tracker.update(estimate_look(seen, body, prior.extent_px) if not halve else
                                  estimate_look(halved_image(seen), body, prior.extent_px / 2))
        else:
            look = tracker.current()

        def at_full(part: np.ndarray, prior: MarkPrior) -> MarkDetections:
            return detect_contrast_marks(part, palette, prior, body=body, scorer=scorer or "shipped", look=look)

        found, points = window_first(lambda part: detect_halved(at_full, part, prior, look) if halve else
                                     at_full(part, prior), image, window)
        pace.timed(time.perf_counter() - start, halve)
        contrast_marks.halved = bool(halve)
        if prior.radius_px[1] >= SMALL_SPOT_PX:
            return points, found.labels
        gate = gates.setdefault(key, LabelChromaGate())
        carried = gate.update(spot_chroma(image, points, found.radius, look))
        return points, found.labels if carried else None

    contrast_marks.halved = False
    return contrast_marks


def window_first(detect: Callable[[np.ndarray], MarkDetections], image: np.ndarray, window: Window | None
                 ) -> tuple[MarkDetections, np.ndarray]:
    """What ``detect`` finds in ``window`` of ``image`` (H, W, 3), and its points (N, 2) in the whole image's pixels;
    the whole image's when there is no window or it gives fewer than :data:`MIN_WINDOW_MARKS` (the target left it,
    or the pose it was drawn around was wrong)."""
    if window is not None:
        y0, y1, x0, x1 = window
        found = detect(image[y0:y1, x0:x1])
        if len(found.points) >= MIN_WINDOW_MARKS:
            return found, found.points + (x0, y0)
    found = detect(image)
    return found, found.points


def point_extractor(kind: str, target: TargetModel, area: Bounds | None = None) -> Extractor:
    """``image (H, W, 3) uint8 -> points (N, 2)``: :func:`feature_extractor` without the labels or a camera."""
    extract = feature_extractor(kind, target, area)
    return lambda image: extract(image)[0]


__all__ = ["FEATURE_KINDS", "FeatureExtractor", "MIN_WINDOW_MARKS", "chessboard_corners", "feature_extractor",
           "point_extractor", "resolve_features", "window_first"]
