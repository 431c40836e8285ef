"""A ROS 2 node hints the fleet: ``geometry_msgs/msg/PoseStamped`` on a ROS topic -> the fleet's 24-byte hint.

``evopose ros2 --fleet F --hints-from /topic [--hint-vehicle ros]`` follows the topic in the rmw_zenoh format
(:class:`agents.bridges.listener.Ros2Listener`: the publishers found through their liveliness tokens) and sends each
pose as a hint from the fleet vehicle ``--hint-vehicle``: a team-mate's full pose entering every receiver's
population, where selection keeps it only if it fits (the paper's hints; receivers also drop hints outside their
search box). The pose is the target's in ``map``, the fleet's world frame (docs/ros2.md, "Frames"): a message in
another frame, or with a non-finite position or a quaternion that is not a rotation, is refused and counted, never
forwarded.
"""

from __future__ import annotations

import math
import threading
from collections import Counter

import numpy as np

from geometry import euler_from_quaternion

from agents.bridges.listener import RosSample
from agents.bridges.ros_msgs import POSE_STAMPED
from agents.bridges.names import MAP_FRAME
from agents.transport.bus import FleetBus

#: The ROS 2 type taken in.
HINT_MSGTYPE = POSE_STAMPED
#: How far a quaternion's norm may be from 1 before it is refused rather than normalised.
QUATERNION_NORM_TOLERANCE = 1e-3


class RefusedPose(ValueError):
    """A PoseStamped that is not a pose of the target in ``map``; ``reason`` is its counter's name."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason


def rpy_from_quaternion(x: float, y: float, z: float, w: float) -> tuple[float, float, float]:
    """``(roll, pitch, yaw)`` of a unit quaternion, ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (docs/design.md §2, REP-103)."""
    return tuple(float(a) for a in euler_from_quaternion((x, y, z, w)))  # type: ignore[return-value]


def pose_from_pose_stamped(message) -> np.ndarray:
    """``world_from_target`` ``(x, y, z, roll, pitch, yaw)``, shape (6,), of a PoseStamped in ``map``.

    Raises
    ------
    RefusedPose
        Another frame, a non-finite field, or a quaternion whose norm is not 1.
    """
    frame = message.header.frame_id
    if frame != MAP_FRAME:
        raise RefusedPose("frame", f"frame_id {frame!r}, expected {MAP_FRAME!r} (the fleet's world frame)")
    p, q = message.pose.position, message.pose.orientation
    values = (p.x, p.y, p.z, q.x, q.y, q.z, q.w)
    if not all(math.isfinite(v) for v in values):
        raise RefusedPose("non-finite", "a position or orientation field is not finite")
    norm = math.sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w)
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise RefusedPose("quaternion", f"orientation norm {norm:.6g}, expected 1")
    rpy = rpy_from_quaternion(q.x / norm, q.y / norm, q.z / norm, q.w / norm)
    return np.array([p.x, p.y, p.z, *rpy], float)


class HintForwarder:
    """Each PoseStamped received -> one hint on ``bus`` (``on_message`` of a :class:`Ros2Listener`, its worker
    thread); ``forwarded`` and ``refused`` (per reason) count them."""

    def __init__(self, bus: FleetBus) -> None:
        self.bus = bus
        self.forwarded = 0
        self.refused: Counter[str] = Counter()
        self._lock = threading.Lock()

    def __call__(self, sample: RosSample) -> None:
        if sample.msgtype != HINT_MSGTYPE:
            with self._lock:
                self.refused["type"] += 1
            return
        try:
            pose = pose_from_pose_stamped(sample.message)
        except RefusedPose as err:
            with self._lock:
                self.refused[err.reason] += 1
            return
        self.bus.publish_hint(pose)
        with self._lock:
            self.forwarded += 1

    def counts(self) -> dict:
        with self._lock:
            return {"forwarded": self.forwarded, "refused": dict(self.refused)}


__all__ = ["HINT_MSGTYPE", "HintForwarder", "RefusedPose", "pose_from_pose_stamped", "rpy_from_quaternion"]
