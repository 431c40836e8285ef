"""Medians by one sort: the values ``np.median`` gives, to the bit, in less time.

NumPy 2 sorts float32 and float64 with vectorised instructions, and selects (``np.partition``, which ``np.median``
uses) without them: on the front-end's 10-40 thousand samples a sort takes 0.4-0.5 of the time. The median is the
mean of the same middle element or two either way, so the result is the same value. Inputs hold no NaN.
(``np.quantile`` gains nothing so: its interpolation selects again, on the sorted array too.)
"""

from __future__ import annotations

import numpy as np


def median(a: np.ndarray, axis: int = -1) -> np.ndarray:
    """``np.median(a, axis=axis)`` of a NaN-free array: the mean of the middle element or two of ``a`` sorted along
    ``axis`` (as ``np.median`` takes the mean of the partitioned middle)."""
    ordered = np.sort(a, axis=axis)
    n = ordered.shape[axis]
    if n == 0:
        return np.median(a, axis=axis)
    middle = slice(n // 2, n // 2 + 1) if n % 2 else slice(n // 2 - 1, n // 2 + 1)
    return np.mean(np.take(ordered, np.arange(n)[middle], axis=axis), axis=axis)


__all__ = ["median"]
