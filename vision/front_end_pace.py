"""The contrast front-end keeps a camera's rate (issue 32, deliverable 5): where the target is so large in the image
that its scale space is built halved anyway (:func:`vision.scale_space.halved`: 400 px across and more, the second
robot at telephoto), and the front-end at full resolution takes more of the frame period than a frame can give it,
the whole front-end runs on the image halved (its paint, positions, colours and context too), and returns to full
resolution once the halved frames leave room for it.

The rule is a time budget, not a fitted constant: a frame is the image decoded, the marks found, the pose estimated
(10-20 ms at telephoto) and the result published, so the front-end may take :data:`FRONT_END_SHARE` of the period.
Halving costs the second robot's telephoto worlds 0-4.6 points of recall and 2.9-5.2 of precision an image; a frame
later than its tick costs the whole frame (the vehicle skips to the newest tick). BENCHMARKS.md, "the second robot at
10 fps, halved when it overruns": ticks skipped 12-42 of 40 -> 4-16, good poses per tick 0.46-0.73 -> 0.68-0.86.
State: the recent timings of one camera, one writer (the vehicle's frame loop)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from statistics import median

import cv2
import numpy as np

from .blobs import ContrastMarks
from .mark_prior import MarkPrior
from .scale_space import halved

#: Share of the frame period the front-end may take at full resolution before it runs halved.
FRONT_END_SHARE = 0.6
#: Share of the period under which the halved front-end's time, times :data:`FULL_OVER_HALVED`, returns it to full
#: resolution (below FRONT_END_SHARE: a front-end near the bar does not switch back and forth).
RETURN_SHARE = 0.5
#: How much longer a frame takes at full resolution than halved: 1.6-1.9 on the second robot's five telephoto worlds
#: (0.152 s against 0.094 and 0.082 s an image through the named looks, runs of different days; BENCHMARKS.md): the
#: lower end, so that a front-end returns to full resolution only with room to spare.
FULL_OVER_HALVED = 1.6
#: The timings a decision takes the median of (one slow frame, a page fault or a team-mate's burst, decides nothing).
RECENT = 3


class FrontEndPace:
    """Whether a camera's next frame runs the front-end halved (:meth:`halve`), from the time its recent frames took
    (:meth:`timed`). ``period_s``: the camera's frame period (None: no clock to keep, never halved)."""

    def __init__(self, period_s: float | None) -> None:
        if period_s is not None and not period_s > 0:
            raise ValueError(f"period_s must be > 0, got {period_s}")
        self.period_s = period_s
        self.halving = False
        self._recent: list[float] = []

    def halve(self, prior: MarkPrior) -> bool:
        """Whether this frame's front-end runs on the image halved: the pace says so and the target, seen with
        ``prior``, is large enough (:func:`vision.scale_space.halved`)."""
        return self.halving and halved(prior)

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


def halved_image(image: np.ndarray) -> np.ndarray:
    """``image`` (H, W, C) halved: each 2 x 2 block's mean (cv2.INTER_AREA; an odd last row or column dropped), its
    pixel (u, v) the full image's (2 u + 0.5, 2 v + 0.5)."""
    h, w = image.shape[:2]
    return cv2.resize(image[:h // 2 * 2, :w // 2 * 2], (w // 2, h // 2), interpolation=cv2.INTER_AREA)


def detect_halved(detect: Callable[[np.ndarray, MarkPrior], ContrastMarks], image: np.ndarray,
                  prior: MarkPrior) -> ContrastMarks:
    """``detect(image, prior)`` run on ``image`` (H, W, 3) halved (cv2.INTER_AREA) with the prior's radii and extent
    halved; its points and radii in the full image's pixels (the halved pixel (u, v) is the full image's
    (2 u + 0.5, 2 v + 0.5))."""
    small = halved_image(image)
    half = MarkPrior((max(prior.radius_px[0] / 2, 0.5), prior.radius_px[1] / 2),
                     None if prior.extent_px is None else prior.extent_px / 2)
    found = detect(small, half)
    radius = None if found.radius is None else found.radius * 2
    return dataclasses.replace(found, points=found.points * 2 + 0.5, radius=radius,
                               areas=np.asarray(found.areas) * 4)


__all__ = ["FRONT_END_SHARE", "FULL_OVER_HALVED", "FrontEndPace", "RETURN_SHARE", "detect_halved", "halved_image"]
