"""A camera's look over a sequence (:class:`LookTracker`): a camera keeps its white balance, saturation and tone
curve, so one frame's estimate (:func:`vision.camera_look.estimate_look`, which may see one face of the body only)
is steadied by the median of the last ones, and taken again only every few frames once it is known."""

from __future__ import annotations

import numpy as np

from .camera_look import Look


class LookTracker:
    """A camera's look over a sequence: the median of the last ``window`` frames' estimates that found the body
    (a camera keeps its look; one frame's body may show one face only). State: the recent estimates, one writer
    (the vehicle's frame loop). :meth:`update` takes a frame's estimate and returns the tracked look.

    Once ``window`` estimates are in, a new one is :meth:`due` every ``every`` frames only (the look changes as
    slowly as a camera's exposure and white balance; an estimate costs a quarter of the front-end's time)."""

    def __init__(self, window: int = 9, every: int = 1) -> None:
        if window < 1 or every < 1:
            raise ValueError(f"window and every must be at least 1, got {window} and {every}")
        self.window, self.every = window, every
        self._recent: list[Look] = []
        self._frames = 0

    def due(self) -> bool:
        """Whether this frame's look should be estimated (:meth:`update`), else :meth:`current` is the look."""
        return len(self._recent) < self.window or self._frames % self.every == 0

    @property
    def latest(self) -> Look:
        """The tracked look so far (the reference look before any estimate), without counting a frame."""
        return self._tracked() if self._recent else Look()

    def current(self) -> Look:
        """The tracked look without a new estimate (counts the frame)."""
        self._frames += 1
        return self._tracked() if self._recent else Look()

    def update(self, look: Look) -> Look:
        self._frames += 1
        if look.body_pixels > 0:
            self._recent = [*self._recent[-(self.window - 1):], look] if self.window > 1 else [look]
        return self._tracked() if self._recent else look

    def _tracked(self) -> Look:
        neutral = np.median([lk.neutral for lk in self._recent], axis=0)
        return Look(neutral=(float(neutral[0]), float(neutral[1])),
                    saturation=float(np.median([lk.saturation for lk in self._recent])),
                    turn_rad=float(np.median([lk.turn_rad for lk in self._recent])),
                    body_pixels=int(np.median([lk.body_pixels for lk in self._recent])))


__all__ = ["LookTracker"]
