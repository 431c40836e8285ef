"""What a sane team-mate cannot send, rejected (and counted) before it reaches the estimator (issue 12).

The wire format (:mod:`protocol`) already refuses what is malformed: wrong types, non-finite numbers, sizes
over the limits, a sender that is not the key's vehicle. What is well-formed but physically absurd passes it:
an attitude with sigma 1e308, a camera 1e300 m away, a hint outside the operating area, a frame stamped an hour
ahead. :class:`Plausibility` judges those against the vehicle's own operating area; each check returns the
reason a message is refused (a short counter name) or None.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from evopose import Bounds

#: Focal lengths a real camera may have, pixels.
FOCAL_RANGE_PX = (10.0, 100_000.0)
#: An IMU's attitude sigma, radians: above 0 (a perfect sensor would fix the attitude exactly) and at most 0.5.
ATTITUDE_SIGMA_RANGE = (1e-5, 0.5)


@dataclass(frozen=True)
class Plausibility:
    """The limits of one vehicle: the operating area and how far team-mates' clocks may run ahead.

    Attributes
    ----------
    bounds : Bounds
        The search box (world frame); poses and hints must lie in it (angles are free).
    operating_radius_m : float
        Cameras must be within this distance of the box's centre.
    max_clock_offset_s : float
        A stamp may be at most this far in the future (team-mates' clocks are synchronised to within it).
    """

    bounds: Bounds
    operating_radius_m: float = 1000.0
    max_clock_offset_s: float = 0.5

    @property
    def centre(self) -> np.ndarray:
        return 0.5 * (self.bounds.lo[:3] + self.bounds.hi[:3])

    def stamp(self, stamp_ns: int, now_ns: int) -> str | None:
        if stamp_ns - now_ns > self.max_clock_offset_s * 1e9:
            return "future-stamp"
        return None

    def position(self, xyz) -> str | None:
        offset = np.asarray(xyz, float)[:3] - self.centre
        if not np.all(np.abs(offset) <= self.operating_radius_m) or np.linalg.norm(offset) > self.operating_radius_m:
            return "outside-operating-area"
        return None

    def pose_in_box(self, pose) -> str | None:
        """A pose of the target (a hint, an estimate): finite and inside the search box (position)."""
        pose = np.asarray(pose, float)
        if pose.shape != (6,) or not np.all(np.isfinite(pose)):
            return "non-finite-pose"
        if np.any(pose[:3] < self.bounds.lo[:3]) or np.any(pose[:3] > self.bounds.hi[:3]):
            return "outside-search-box"
        return None

    def camera(self, info) -> str | None:
        """A team-mate's camera (``protocol.CameraInfo``): plausible focal lengths, inside the operating area."""
        lo, hi = FOCAL_RANGE_PX
        if not (lo <= info.fx <= hi and lo <= info.fy <= hi):
            return "implausible-focal-length"
        return self.position(info.world_from_camera)

    def attitude(self, message) -> str | None:
        """An IMU reading (``protocol.Attitude``): finite angles, sigma in :data:`ATTITUDE_SIGMA_RANGE`."""
        lo, hi = ATTITUDE_SIGMA_RANGE
        if not all(lo <= s <= hi for s in message.sigma):
            return "implausible-sigma"
        if not np.all(np.isfinite([message.roll, message.pitch, message.yaw])):
            return "non-finite-attitude"
        return None

    def feature_set(self, message) -> str | None:
        reason = self.camera(message.camera)
        best = getattr(message, "best", None)
        if reason is None and best is not None:
            reason = self.pose_in_box(best)
        return reason


__all__ = ["Plausibility"]
