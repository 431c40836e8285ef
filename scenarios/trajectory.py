"""Vehicle and target motion: a pose at time ``t`` (seconds) from a start pose, a constant rate and a hover sway.

``pose(t) = start + drive(t) + rate * t + amplitude * sin(2 pi t / period + phase)`` per parameter
``(x, y, z, roll, pitch, yaw)`` (metres, radians). Zero rate and amplitude is a static pose; a
rate is a vehicle moving at constant velocity; the sway models a hovering UAV or an airship drifting.
``drive`` is a ground vehicle driving forward along its heading at ``speed`` while turning at
``turn_rate``: an arc of radius ``speed / turn_rate`` (a straight line when it is 0). The motion is
deterministic: noise belongs to sensors and images, not to the truth.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from geometry import matrix_from_pose, wrap_angle


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Pose as a function of time.

    Attributes
    ----------
    start : array, shape (6,)
        ``world_from_body`` at ``t = 0``.
    rate : array, shape (6,)
        Metres / second and radians / second.
    sway : array, shape (6,)
        Amplitude of the sinusoidal hover sway (metres, radians).
    period : float
        Seconds per sway cycle.
    phase : array, shape (6,)
        Radians; different phases per axis make the sway a loop rather than a line.
    """

    start: np.ndarray
    rate: np.ndarray = field(default_factory=lambda: np.zeros(6))
    sway: np.ndarray = field(default_factory=lambda: np.zeros(6))
    period: float = 4.0
    phase: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.3, 2.1, 0.4, 2.9, 1.7]))
    speed: float = 0.0
    turn_rate: float = 0.0

    @property
    def is_static(self) -> bool:
        return not (np.any(self.rate) or np.any(self.sway) or self.speed)

    def _drive(self, t: float) -> np.ndarray:
        """Offset of the drive at ``t``: the arc from the start heading, shape (6,)."""
        out = np.zeros(6)
        if not self.speed:
            return out
        yaw0, w, v = float(self.start[5]), float(self.turn_rate), float(self.speed)
        if abs(w) < 1e-9:
            out[0], out[1] = v * t * np.cos(yaw0), v * t * np.sin(yaw0)
        else:
            out[0] = v / w * (np.sin(yaw0 + w * t) - np.sin(yaw0))
            out[1] = -v / w * (np.cos(yaw0 + w * t) - np.cos(yaw0))
            out[5] = w * t
        return out

    def pose(self, t: float) -> np.ndarray:
        """``(x, y, z, roll, pitch, yaw)`` at time ``t``, shape (6,); angles wrapped to [-pi, pi)."""
        s = np.asarray(self.start, float) + self._drive(t) + np.asarray(self.rate, float) * t
        s = s + np.asarray(self.sway, float) * np.sin(2 * np.pi * t / self.period + self.phase)
        s[3:] = wrap_angle(s[3:])
        return s

    def matrix(self, t: float) -> np.ndarray:
        """``world_from_body`` at time ``t``, shape (4, 4)."""
        return matrix_from_pose(self.pose(t))


def look_at_rotation(eye: np.ndarray, target: np.ndarray, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """``world_from_camera`` rotation of an optical frame (x right, y down, z forward) at ``eye`` looking at ``target``.

    ``up`` is the world's up direction (z for the scenarios); the image's x axis stays horizontal.
    """
    z = np.asarray(target, float) - np.asarray(eye, float)
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, float))
    if np.linalg.norm(x) < 1e-9:  # looking straight down or up: any horizontal x
        x = np.cross(z, [1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=1)
