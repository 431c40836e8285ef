"""External knowledge of pose parameters (eq. 3): a parameter known from another sensor, fixed or held within
``[C - eps, C + eps]``; the search box narrowed accordingly."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from geometry import PARAM_NAMES

from .problem import Bounds


@dataclass(frozen=True)
class Knowledge:
    """External knowledge of one parameter (eq. 3): ``s_k`` is ``value`` within ``tolerance`` (0 fixes it).

    ``name`` is one of ``x, y, z, roll, pitch, yaw``; metres or radians.
    """

    name: str
    value: float
    tolerance: float = 0.0

    def __post_init__(self) -> None:
        if self.name not in PARAM_NAMES:
            raise ValueError(f"knowledge of {self.name!r}: expected one of {', '.join(PARAM_NAMES)}")
        if not np.isfinite(self.value) or not np.isfinite(self.tolerance) or self.tolerance < 0:
            raise ValueError(f"knowledge of {self.name}: value and tolerance must be finite, tolerance >= 0")


def constrained_bounds(bounds: Bounds, knowledge: Sequence[Knowledge]) -> Bounds:
    """``bounds`` narrowed by every piece of ``knowledge`` (eq. 3)."""
    for k in knowledge:
        bounds = bounds.constrained(k.name, k.value, k.tolerance)
    return bounds


__all__ = ["Knowledge", "constrained_bounds"]
