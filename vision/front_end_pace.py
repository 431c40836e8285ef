"""The contrast front-end keeps a camera's rate (issue 32, deliverable 5): where the target is so large in the image
that its scale space is built halved anyway (:func:`vision.scale_space.halved`: 400 px across and more, the second
robot at telephoto), and the front-end at full resolution takes more of the frame period than a frame can give it,
the front-end runs on the image halved (its paint, look, scale space, colours and context) and places the marks it
keeps at full resolution, and returns to full resolution once the halved frames leave room for it. A camera with a
clock starts halved: its first frames, with no pose to look near and a search from scratch, are its slowest (163-312
ms a frame of the second robot's pair at full resolution), and its halved frames say whether full resolution fits.

The rule is a time budget, not a fitted constant: a frame is the image decoded, the marks found, the pose estimated
(10-16 ms at telephoto, the agents' ``timing_s`` "step") and the result published, so the front-end may take
:data:`FRONT_END_SHARE` of the period. Halved, the second robot's telephoto images give -3.4..+1.5 points of recall
and -3.8..-0.9 of precision against full resolution (the marks kept placed at full resolution,
:func:`placed_at_full`); a frame later than its tick costs the whole frame (the vehicle skips to the newest tick).
On its 20-frame sequence through four looks the pair skips 0-12 ticks of 40 starting halved (4-18 starting at full
resolution, side by side; 12-48 at full resolution throughout), and is good on 90-95 % of frames (BENCHMARKS.md, "the
second robot at 10 fps, halved when it overruns").
State: the recent timings of one camera, one writer (the vehicle's frame loop)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from statistics import median
from typing import TYPE_CHECKING

import numpy as np

from .blobs import ContrastMarks
from .body_paint import LINEAR_OF_BYTE
from .camera_look import Look, to_reference_look
from .spot_colour import ring_colours, spot_colours
from .spot_position import SMALL_SPOT_PX, blob_centroids, coverage_centroids
from .mark_prior import MarkPrior
from .scale_space import halved, halved_image, halved_prior

if TYPE_CHECKING:
    from evopose import Camera

#: Share of the frame period the front-end may take at full resolution before it runs halved.
FRONT_END_SHARE = 0.6
#: Share of the period under which the halved front-end's time, times :data:`FULL_OVER_HALVED`, returns it to full
#: resolution (below FRONT_END_SHARE: a front-end near the bar does not switch back and forth).
RETURN_SHARE = 0.5
#: How much longer a frame takes at full resolution than halved: 1.65 on the second robot's five telephoto worlds
#: (0.152 s against 0.092 s an image through the named looks, runs of different days; BENCHMARKS.md, "the second
#: robot at 10 fps, halved when it overruns"), rounded down so that a front-end returns only with room to spare.
FULL_OVER_HALVED = 1.6
#: The timings a decision takes the median of (one slow frame, a page fault or a team-mate's burst, decides nothing).
RECENT = 3


class FrontEndPace:
    """Whether a camera's next frame runs the front-end halved (:meth:`halve`), from the time its recent frames took
    (:meth:`timed`). ``period_s``: the camera's frame period (None: no clock to keep, never halved); with one, the
    camera starts halved."""

    def __init__(self, period_s: float | None) -> None:
        if period_s is not None and not period_s > 0:
            raise ValueError(f"period_s must be > 0, got {period_s}")
        self.period_s = period_s
        # with a clock to keep, a camera starts halved (where its target is large enough): its first frames, with no
        # window yet and a search from scratch, are its slowest, and its halved frames say whether full resolution fits
        self.halving = period_s is not None
        self._recent: list[float] = []

    def halve(self, prior: MarkPrior, mark_px_now: float | None = None) -> bool:
        """Whether this frame's front-end runs on the image halved: the pace says so and the target, seen with
        ``prior``, is large enough (:func:`vision.scale_space.halved`: the prior's nearest marks), and its largest
        mark where it is tracked now, ``mark_px_now`` (px, :func:`largest_mark_px`; None: not tracked), keeps 3 px
        and more halved: a target far across a deep operating area is not halved however near it could be."""
        return bool(self.halving and halved(prior) and (mark_px_now is None or mark_px_now >= 2 * SMALL_SPOT_PX))

    def timed(self, seconds: float, was_halved: bool) -> None:
        """A frame's front-end took ``seconds``, ``was_halved`` or at full resolution."""
        if self.period_s is None:
            return
        if was_halved != self.halving:   # a frame of a target too small to halve while halving: not this bar's
            return
        self._recent = [*self._recent[-(RECENT - 1):], float(seconds)]
        if len(self._recent) < RECENT:
            return
        typical = median(self._recent)
        if not self.halving and typical > FRONT_END_SHARE * self.period_s:
            self.halving, self._recent = True, []
        elif self.halving and typical * FULL_OVER_HALVED < RETURN_SHARE * self.period_s:
            self.halving, self._recent = False, []


def largest_mark_px(camera: Camera, pose: np.ndarray, mark_radius: float) -> float:
    """The radius (px) a mark of ``mark_radius`` (m) has facing ``camera`` at the target's position of ``pose``
    (``world_from_target`` (6,))."""
    position = camera.camera_from_world[:3, :3] @ np.asarray(pose, float)[:3] + camera.camera_from_world[:3, 3]
    return float(max(camera.fx, camera.fy) * mark_radius / max(float(np.linalg.norm(position)), 1e-6))


def placed_at_full(image: np.ndarray, look: Look | None, points: np.ndarray, radius: np.ndarray,
                   max_radius: float) -> np.ndarray:
    """Each mark's position (K, 2) taken again on the full image (H, W, 3) uint8, from its position ``points``
    (K, 2) and ``radius`` (K,) found on the image halved, ``max_radius`` the largest a mark can have (px): the
    coverage re-centred and the centroid of its whole blob at full resolution
    (:func:`vision.spot_position.blob_centroids`, with its spot's colour and its ring's, in linear light after the
    camera's ``look`` is undone); where no blob of its own is found, the halved position. A halved pixel is two:
    an oblique mark's blob there joins the dark beside it sooner, and the position falls 3-6 px off."""
    if not len(points):
        return points
    # every window the placing reads lies within twice the largest radius and a few pixels of its mark
    reach = 2 * int(np.ceil(max(max_radius, radius.max()))) + 6
    h, w = image.shape[:2]
    x0, y0 = (np.maximum(np.floor(points.min(axis=0)).astype(int) - reach, 0)).tolist()
    x1, y1 = (np.minimum(np.ceil(points.max(axis=0)).astype(int) + reach + 1, [w, h])).tolist()
    part = image[y0:y1, x0:x1]
    lin = LINEAR_OF_BYTE[to_reference_look(part, look) if isinstance(look, Look) else part]
    local = points - (x0, y0)
    at = np.clip(np.rint(local).astype(int), 0, [x1 - x0 - 1, y1 - y0 - 1])
    spot = spot_colours(lin, at[:, 0], at[:, 1], radius)   # as the front-end takes it
    ring = ring_colours(lin, local, radius)
    placed = coverage_centroids(lin, local, radius, spot, ring)
    placed, _ = blob_centroids(lin, placed, spot, ring, max(max_radius, float(radius.max())))
    return placed + (x0, y0)


def detect_halved(detect: Callable[[np.ndarray, MarkPrior], ContrastMarks], image: np.ndarray,
                  prior: MarkPrior, look: Look | None = None) -> ContrastMarks:
    """``detect(image, prior)`` run on ``image`` (H, W, 3) halved (:func:`vision.scale_space.halved_image`) with
    the prior's radii and extent halved; its radii in the full image's pixels and its marks placed at full resolution
    (:func:`placed_at_full`, the camera's ``look`` undone: None, the reference look)."""
    found = detect(halved_image(image), halved_prior(prior))
    radius = found.radius * 2
    points = placed_at_full(image, look, found.points * 2 + 0.5, radius, prior.radius_px[1])
    return dataclasses.replace(found, points=points, radius=radius, areas=np.asarray(found.areas) * 4)


__all__ = ["FRONT_END_SHARE", "FULL_OVER_HALVED", "FrontEndPace", "RETURN_SHARE", "detect_halved",
           "largest_mark_px", "placed_at_full"]
