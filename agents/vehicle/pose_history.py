"""A camera's pose at the instant its image was taken, from a pose topic's recent messages (their header stamps).

A ROS 2 camera driver and the pose source (odometry, motion capture, the mirror's ``PoseStamped``) publish on their
own: a pose may arrive before or after its image, at another rate, and a moving camera's newest pose is not the
one its image was taken at (at 10 m/s, 10 ms is 10 cm). So, as tf2 looks a transform up at an image's stamp, the
pose of an image is the pose *at its header stamp* (both stamps come from the robot's clock): a pose with that stamp,
else interpolated between the two that bracket it (position linearly, attitude by slerp; at most twice
:data:`MAX_POSE_GAP_S` apart), else the nearest one within :data:`MAX_POSE_GAP_S`. When the image's instant is
newer than every pose, a pose at or after it is waited for up to ``wait_s`` (the pose may be on its way). No pose
within the gap: no pose for this image (the tick is skipped).

State: the last :data:`KEEP` poses by stamp; one writer (the topic's worker, :meth:`PoseHistory.add`), readers
under its condition. Pure: no Zenoh (agents/vehicle/ros_camera.py feeds it).
"""

from __future__ import annotations

import bisect
import threading

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

#: Poses kept (a 100 Hz pose topic: 0.6 s).
KEEP = 64
#: Furthest a pose's stamp may lie from an image's when none brackets it (s): beyond, the image has no pose.
MAX_POSE_GAP_S = 0.1


def interpolated(before: tuple[int, np.ndarray], after: tuple[int, np.ndarray], stamp_ns: int) -> np.ndarray:
    """The pose (4, 4) at ``stamp_ns`` between two stamped poses ``(stamp_ns, world_from_camera (4, 4))``: the
    position linearly, the attitude by spherical interpolation."""
    (t0, m0), (t1, m1) = before, after
    if t1 == t0:
        return m0.copy()
    w = (stamp_ns - t0) / (t1 - t0)
    out = np.eye(4)
    out[:3, 3] = (1.0 - w) * m0[:3, 3] + w * m1[:3, 3]
    out[:3, :3] = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([m0[:3, :3], m1[:3, :3]])))([w]).as_matrix()[0]
    return out


class PoseHistory:
    """The last :data:`KEEP` camera poses (4, 4) by header stamp (ns)."""

    def __init__(self, keep: int = KEEP, max_gap_s: float = MAX_POSE_GAP_S) -> None:
        self.keep, self.max_gap_ns = int(keep), int(max_gap_s * 1e9)
        self._stamps: list[int] = []
        self._poses: list[np.ndarray] = []
        self._lock = threading.Condition()

    def add(self, stamp_ns: int, world_from_camera: np.ndarray) -> None:
        """One pose (4, 4) stamped ``stamp_ns``; a second pose of one stamp replaces the first."""
        with self._lock:
            at = bisect.bisect_left(self._stamps, stamp_ns)
            if at < len(self._stamps) and self._stamps[at] == stamp_ns:
                self._poses[at] = world_from_camera
            else:
                self._stamps.insert(at, stamp_ns)
                self._poses.insert(at, world_from_camera)
                if len(self._stamps) > self.keep:   # the oldest stamp goes
                    del self._stamps[0], self._poses[0]
            self._lock.notify_all()

    def at(self, stamp_ns: int, wait_s: float = 0.0) -> np.ndarray | None:
        """The pose (4, 4) at ``stamp_ns`` (see the module's docstring), waiting up to ``wait_s`` for a pose at or
        after it; None: no pose within :data:`MAX_POSE_GAP_S` of it."""
        with self._lock:
            self._lock.wait_for(lambda: bool(self._stamps) and self._stamps[-1] >= stamp_ns, wait_s)
            stamps, poses = self._stamps, self._poses
            if not stamps:
                return None
            at = bisect.bisect_left(stamps, stamp_ns)
            if at < len(stamps) and stamps[at] == stamp_ns:
                return poses[at].copy()
            if 0 < at < len(stamps) and stamps[at] - stamps[at - 1] <= 2 * self.max_gap_ns:
                return interpolated((stamps[at - 1], poses[at - 1]), (stamps[at], poses[at]), stamp_ns)
            # no bracket, or one too wide to interpolate across (a gap in the topic, a stray stamp): the nearest
            near = min((i for i in (at - 1, at) if 0 <= i < len(stamps)), key=lambda i: abs(stamps[i] - stamp_ns))
            return poses[near].copy() if abs(stamps[near] - stamp_ns) <= self.max_gap_ns else None


__all__ = ["KEEP", "MAX_POSE_GAP_S", "PoseHistory", "interpolated"]
