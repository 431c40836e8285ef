"""Where to look for the target: a window of the image around it, so that the contrast front-end works on a fraction
of the pixels.

The contrast front-end (:mod:`vision.blobs`) finds the body's paint over the whole image, estimates the camera's look
there and builds its scale space around the body. With its search beside it, a pair of agents on two cores missed
ticks of a 10 fps clock (BENCHMARKS.md, "20-frame sequences at 10 fps, the clock's ticks kept"). In one process, on
the 20-frame datasets' 640 x 480 frames, the whole image's front-end took 34-56 ms of CPU beside the kernel's page
faults (agents/vehicle/memory.py), the window's 25-41 ms once the vehicle has a good pose ("What the camera front-end
costs a vehicle per frame"). The window is where the target is expected:

- around its body's projection at the vehicle's last good pose (:func:`target_window`, the pose from
  :meth:`agents.vehicle.step.VehicleState.near`);
- without a pose, around the body's paint found at half resolution (:func:`locate_body`, :func:`grown`).

The front-end then works on the window alone (:func:`vision.extract.feature_extractor`), and on the whole image again
when the window gives too few marks (the target left it, or the pose was wrong).
"""

from __future__ import annotations

import cv2
import numpy as np

from evopose import Camera

from .body_paint import LINEAR_OF_BYTE, body_paint, clipped_channels, pixel_box, srgb_to_linear
from .camera_look import Look, to_reference_look
from .features import to_bgr

#: Past the body's projection the window reaches the front-end's own margin around the body
#: (:func:`vision.blobs.crop_margin`: the ground whose texture sets its threshold) and this share of the body's
#: projected size, at least WINDOW_SLACK_PX: the target's motion and the pose's error since the pose, and what the
#: front-end's body region takes in beside the body (paint-coloured specks: 42 px past the Pioneer's projection in a
#: committed paper-scale frame, whose whole-image scale space then reaches that far).
#: With the previous frame's true pose for the last good one, 64 px gave the marks the whole image gives in every
#: frame of the 20-frame datasets (datasets/photoreal-long, 38 + 38) and the committed fixtures (tests/data/photoreal
#: paper, telephoto, paper-sequence: 42); 16, 32 and 48 px moved one mark by 0.1 px in 2, 2 and 1 paper-scale frames.
WINDOW_SLACK_SHARE, WINDOW_SLACK_PX = 0.1, 64
#: A window narrower than this (pixels) is the target out of the image: the whole image is searched.
MIN_WINDOW_PX = 16

Window = tuple[int, int, int, int]


def target_window(camera: Camera, pose: np.ndarray, points: np.ndarray, margin_px: float) -> Window | None:
    """The window of ``camera``'s image around the target's ``points`` (M, 3), target frame (its body's vertices)
    at ``pose`` (``world_from_target`` (6,)): their projection's box grown by ``margin_px`` and the slack
    (:data:`WINDOW_SLACK_SHARE`, :func:`grown`). None when the whole image must be searched: a point behind the
    camera, or the window (nearly) outside the image."""
    uv, in_front = camera.project_population(np.asarray(pose, float).reshape(1, 6), np.asarray(points, float))
    if not np.all(in_front) or not np.all(np.isfinite(uv)):
        return None
    lo, hi = uv[0].min(axis=0), uv[0].max(axis=0)
    box = (int(np.floor(lo[1])), int(np.ceil(hi[1])) + 1, int(np.floor(lo[0])), int(np.ceil(hi[0])) + 1)
    return grown(box, margin_px, camera.width, camera.height)


def grown(box: Window, margin_px: float, width: int, height: int) -> Window | None:
    """``box`` ``(y0, y1, x0, x1)`` (rows ``y0:y1``, columns ``x0:x1``) grown on every side by ``margin_px`` and the
    slack (:data:`WINDOW_SLACK_SHARE` of its larger side, at least :data:`WINDOW_SLACK_PX`), within the image
    (``width`` x ``height``), its first row and column even (a JPEG's 4:2:0 chroma blocks stay aligned,
    :mod:`vision.spot_colour`); None when less than :data:`MIN_WINDOW_PX` of it lies in the image."""
    y0, y1, x0, x1 = box
    reach = margin_px + max(WINDOW_SLACK_SHARE * max(y1 - y0, x1 - x0), WINDOW_SLACK_PX)
    y0 = int(np.clip(np.floor(y0 - reach), 0, height)) // 2 * 2
    x0 = int(np.clip(np.floor(x0 - reach), 0, width)) // 2 * 2
    y1, x1 = int(np.clip(np.ceil(y1 + reach), 0, height)), int(np.clip(np.ceil(x1 + reach), 0, width))
    if y1 - y0 < MIN_WINDOW_PX or x1 - x0 < MIN_WINDOW_PX:
        return None
    return y0, y1, x0, x1


def locate_body(image_bgr: np.ndarray, body: tuple[int, int, int], look: Look | None = None
                ) -> Window | None:
    """Where the body's paint is (:func:`vision.body_paint.body_paint`, seen in ``look``), found on a quarter of the
    pixels: the box ``(y0, y1, x0, x1)`` (full-resolution rows ``y0:y1``, columns ``x0:x1``) of every patch of it at
    half resolution, specks under 2 x 2 of its pixels left out; None: no paint. The contrast front-end on a window
    around it (:func:`grown`) builds its scale space where it would on the whole image, without the whole image's
    paint."""
    bgr = to_bgr(image_bgr)
    small = cv2.resize(bgr, (bgr.shape[1] // 2, bgr.shape[0] // 2), interpolation=cv2.INTER_AREA)
    clipped = clipped_channels(small)   # as the camera gave it (vision.blobs.detect_contrast_marks reads it so too)
    small = to_reference_look(small, look) if isinstance(look, Look) else small
    _, paint = body_paint(LINEAR_OF_BYTE[small], srgb_to_linear(np.array(body, np.float32) / 255.0), clipped)
    box = pixel_box(cv2.morphologyEx(paint.astype(np.uint8), cv2.MORPH_OPEN, np.ones((2, 2), np.uint8)))
    return None if box is None else (2 * box[0], 2 * box[1] + 2, 2 * box[2], 2 * box[3] + 2)


__all__ = ["MIN_WINDOW_PX", "WINDOW_SLACK_PX", "WINDOW_SLACK_SHARE", "Window", "grown", "locate_body",
           "target_window"]
