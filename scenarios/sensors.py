"""Sensors beyond the camera: an attitude IMU (XSens MT9 class) and a GPS with degradation and outages.

Every reading draws from its own :class:`numpy.random.Generator` derived from the scenario seed,
a stream number (which sensor on which vehicle) and the frame index, so frame N reads the same
whatever order frames are taken in. The IMU bias is drawn once per run (per seed and stream).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geometry import wrap_angle

#: Salt of the generators of per-run constants (IMU bias) so they differ from per-frame streams.
RUN_CONSTANT = 0x5EED


def stream_rng(seed: int, *keys: int) -> np.random.Generator:
    """The generator of one random stream: ``default_rng([seed, *keys])`` (independent for distinct keys)."""
    return np.random.default_rng([int(seed), *map(int, keys)])


@dataclass(frozen=True)
class ImuModel:
    """Attitude from a small MEMS unit: truth + a constant per-run bias + white noise.

    Attributes
    ----------
    bias_sigma : float
        Standard deviation of the per-axis bias drawn once per run, radians (MT9: about 0.5-1 deg).
    noise_sigma : float
        Standard deviation of the per-reading white noise, radians (MT9: about 0.05-0.2 deg).
    """

    bias_sigma: float = np.deg2rad(0.7)
    noise_sigma: float = np.deg2rad(0.1)

    def bias(self, seed: int, stream: int) -> np.ndarray:
        """The run's ``(roll, pitch, yaw)`` bias, radians, shape (3,)."""
        return self.bias_sigma * stream_rng(seed, RUN_CONSTANT, stream).standard_normal(3)

    def read(self, true_rpy: np.ndarray, seed: int, stream: int, frame: int) -> np.ndarray:
        """Measured ``(roll, pitch, yaw)`` at ``frame``, radians, shape (3,)."""
        noise = self.noise_sigma * stream_rng(seed, stream, frame).standard_normal(3)
        return wrap_angle(np.asarray(true_rpy, float) + self.bias(seed, stream) + noise)


@dataclass(frozen=True)
class GpsModel:
    """Position with white noise, optional degraded windows (noise multiplied) and outages (no fix).

    Attributes
    ----------
    noise_sigma : float
        Metres per axis in normal conditions.
    degraded : tuple of (t0, t1, factor)
        During ``t0 <= t < t1`` (seconds) the noise is multiplied by ``factor``.
    outages : tuple of (t0, t1)
        During ``t0 <= t < t1`` there is no fix.
    """

    noise_sigma: float = 1.5
    degraded: tuple[tuple[float, float, float], ...] = ()
    outages: tuple[tuple[float, float], ...] = ()

    def sigma_at(self, t: float) -> float | None:
        """Noise (m) at time ``t``, or None during an outage."""
        if any(t0 <= t < t1 for t0, t1 in self.outages):
            return None
        factor = 1.0
        for t0, t1, f in self.degraded:
            if t0 <= t < t1:
                factor = max(factor, f)
        return self.noise_sigma * factor

    def read(self, true_xyz: np.ndarray, t: float, seed: int, stream: int, frame: int) -> np.ndarray | None:
        """Measured position (m), shape (3,), or None without a fix."""
        sigma = self.sigma_at(t)
        if sigma is None:
            return None
        return np.asarray(true_xyz, float) + sigma * stream_rng(seed, stream, frame).standard_normal(3)
