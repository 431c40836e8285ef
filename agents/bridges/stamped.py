"""A pose at the instant an image was taken, from a pose stream's recent messages (their header stamps).

A ROS 2 camera driver and the pose source (odometry, motion capture, the mirror's ``PoseStamped`` or ``/tf``)
publish on their own: a pose may arrive before or after its image, at another rate, and a moving camera's newest
pose is not the one its image was taken at (at 10 m/s, 10 ms is 10 cm). So, as tf2 looks a transform up at an
image's stamp, the pose of an image is the pose *at its header stamp* (both stamps come from the robot's clock): a
pose with that stamp, else interpolated between the two that bracket it (position linearly, attitude along the
shortest rotation; at most twice :data:`MAX_POSE_GAP_S` apart), else the nearest one within :data:`MAX_POSE_GAP_S`;
else none (the image has no pose: its tick is skipped).

:class:`StampedTransforms` is that rule over the last :data:`KEEP` transforms of one stream (no lock: a ``/tf``
link's, under its tree's lock); :class:`PoseHistory` is one stream with its own lock, which waits for a pose at or
after an image's stamp (it may be on its way). Pure: numpy and :mod:`geometry`, no Zenoh.
"""

from __future__ import annotations

import bisect
import threading

import numpy as np

from geometry import rotation_from_rotvec, rotvec_from_rotation

#: Transforms kept per stream (a 100 Hz pose topic: 0.6 s).
KEEP = 64
#: Furthest a pose's stamp may lie from an image's when none brackets it (s): beyond, the image has no pose.
MAX_POSE_GAP_S = 0.1


def interpolated(before: tuple[int, np.ndarray], after: tuple[int, np.ndarray], stamp_ns: int) -> np.ndarray:
    """The transform (4, 4) at ``stamp_ns`` between two stamped rigid transforms ``(stamp_ns, (4, 4))``: the
    translation linearly, the rotation along the shortest rotation from one to the other (slerp)."""
    (t0, m0), (t1, m1) = before, after
    if t1 == t0:
        return m0.copy()
    w = (stamp_ns - t0) / (t1 - t0)
    out = np.eye(4)
    out[:3, 3] = (1.0 - w) * m0[:3, 3] + w * m1[:3, 3]
    out[:3, :3] = m0[:3, :3] @ rotation_from_rotvec(w * rotvec_from_rotation(m0[:3, :3].T @ m1[:3, :3]))
    return out


class StampedTransforms:
    """The last ``keep`` rigid transforms (4, 4) of one stream by header stamp (ns); not thread-safe."""

    def __init__(self, keep: int = KEEP, max_gap_s: float = MAX_POSE_GAP_S) -> None:
        self.keep, self.max_gap_ns = int(keep), int(max_gap_s * 1e9)
        self.stamps: list[int] = []
        self._transforms: list[np.ndarray] = []

    def __len__(self) -> int:
        return len(self.stamps)

    def add(self, stamp_ns: int, transform: np.ndarray) -> None:
        """One transform stamped ``stamp_ns``; a second one of the same stamp replaces the first; beyond ``keep``
        the oldest stamp goes."""
        at = bisect.bisect_left(self.stamps, stamp_ns)
        if at < len(self.stamps) and self.stamps[at] == stamp_ns:
            self._transforms[at] = transform
            return
        self.stamps.insert(at, stamp_ns)
        self._transforms.insert(at, transform)
        if len(self.stamps) > self.keep:
            del self.stamps[0], self._transforms[0]

    def at(self, stamp_ns: int) -> np.ndarray | None:
        """The transform at ``stamp_ns`` (see the module's docstring); None: none within the gap."""
        stamps, transforms = self.stamps, self._transforms
        if not stamps:
            return None
        at = bisect.bisect_left(stamps, stamp_ns)
        if at < len(stamps) and stamps[at] == stamp_ns:
            return transforms[at].copy()
        if 0 < at < len(stamps) and stamps[at] - stamps[at - 1] <= 2 * self.max_gap_ns:
            return interpolated((stamps[at - 1], transforms[at - 1]), (stamps[at], transforms[at]), stamp_ns)
        # no bracket, or one too wide to interpolate across (a gap in the stream, a stray stamp): the nearest
        near = min((i for i in (at - 1, at) if 0 <= i < len(stamps)), key=lambda i: abs(stamps[i] - stamp_ns))
        return transforms[near].copy() if abs(stamps[near] - stamp_ns) <= self.max_gap_ns else None


class PoseHistory:
    """One pose stream's :class:`StampedTransforms` with a lock: one writer (the topic's worker, :meth:`add`),
    readers waiting for a pose at or after an image's stamp (:meth:`at`)."""

    def __init__(self, keep: int = KEEP, max_gap_s: float = MAX_POSE_GAP_S) -> None:
        self._poses = StampedTransforms(keep, max_gap_s)
        self._lock = threading.Condition()

    @property
    def keep(self) -> int:
        return self._poses.keep

    @property
    def max_gap_s(self) -> float:
        return self._poses.max_gap_ns / 1e9

    def add(self, stamp_ns: int, world_from_camera: np.ndarray) -> None:
        with self._lock:
            self._poses.add(stamp_ns, world_from_camera)
            self._lock.notify_all()

    def at(self, stamp_ns: int, wait_s: float = 0.0) -> np.ndarray | None:
        """The pose (4, 4) at ``stamp_ns``, waiting up to ``wait_s`` for a pose at or after it; None: no pose within
        :data:`MAX_POSE_GAP_S` of it."""
        with self._lock:
            self._lock.wait_for(lambda: bool(self._poses) and self._poses.stamps[-1] >= stamp_ns, wait_s)
            return self._poses.at(stamp_ns)


__all__ = ["KEEP", "MAX_POSE_GAP_S", "PoseHistory", "StampedTransforms", "interpolated"]
