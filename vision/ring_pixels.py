"""Which pixels of a window a ring about a sub-pixel centre can reach: the front-end's per-spot windows
(:mod:`vision.spot_colour` a spot's ring, :mod:`vision.body_paint` the paint ring around it, :mod:`vision.spot_position`
a re-centred coverage window) read only these, not the whole square.

A window's pixel ``k`` (per axis, ``k = 0 .. size - 1``) lies at ``first + k`` from a reference pixel, and the centre
lies ``lo`` to ``hi`` from that reference (its sub-pixel fraction: ``[0, 1]`` from a floor, ``[-0.5, 0.5]`` from a
rounding), so the pixel's offset from the centre lies in ``[first + k - hi, first + k - lo]`` on each axis. A pixel is
kept when some centre in that range can put it ``inner`` to ``outer`` px away: a superset of every ring the caller
then selects exactly, so its result is the one the whole window gives.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np


#: The bounds are widened to multiples of this (px) before the look-up: spots' radii are continuous, and a cache
#: keyed by them never hit (0 of 858 calls on the second robot's frames).
GRID_PX = 0.125


def ring_pixels(first: int, size: int, lo: float, hi: float, inner: float, outer: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """The rows and columns (M,) each (window indices ``0 .. size - 1``) that a centre ``lo`` to ``hi`` from the
    reference can have ``inner`` to ``outer`` px away (the module's docstring), the bounds widened to
    :data:`GRID_PX` (a superset still). Cached: the arrays are shared, not to be written."""
    return _ring_pixels(int(first), int(size), _down(lo), _up(hi), _down(inner), _up(outer))


def _down(x: float) -> float:
    return math.floor(x / GRID_PX) * GRID_PX


def _up(x: float) -> float:
    return math.ceil(x / GRID_PX) * GRID_PX


@lru_cache(maxsize=1024)
def _ring_pixels(first: int, size: int, lo: float, hi: float, inner: float, outer: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    k = first + np.arange(size, dtype=float)
    ends = np.stack([k - hi, k - lo])                                        # (2, size): the offset's range
    near = np.where((ends[0] <= 0) & (ends[1] >= 0), 0.0, np.abs(ends).min(axis=0))
    far = np.abs(ends).max(axis=0)
    least, most = np.hypot(near[:, None], near[None, :]), np.hypot(far[:, None], far[None, :])
    rows, cols = np.nonzero((least <= outer + 1e-6) & (most >= inner - 1e-6))
    return rows, cols


__all__ = ["ring_pixels"]
