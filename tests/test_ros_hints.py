"""A ROS 2 node hints the fleet (docs/ros2.md, "Taking in"): PoseStamped on a ROS topic in the rmw_zenoh format ->
`evopose ros2 --hints-from TOPIC` -> the fleet's 24-byte hints, from the vehicle `--hint-vehicle`. Real processes, a
real router; the ROS side is the project's own rmw_zenoh publisher (no live ROS 2 install was available)."""

from __future__ import annotations

import math
import threading
import time
from types import SimpleNamespace

import numpy as np
import pytest

from agents.bridges import ros_msgs
from agents.bridges.rmw_zenoh import DEFAULT_QOS, Node
from agents.bridges.ros2_node import Ros2Node
from agents.bridges.ros_hints import RefusedPose, pose_from_pose_stamped, rpy_from_quaternion
from protocol.hint import decode_hint
from tests.fleet_procs import client_session, fleet_with_router

TOPIC = "/lab/target_hint"


def stamped(frame: str, position, quaternion):
    point = SimpleNamespace(**dict(zip("xyz", position)))
    orientation = SimpleNamespace(**dict(zip("xyzw", quaternion)))
    return SimpleNamespace(header=SimpleNamespace(frame_id=frame),
                           pose=SimpleNamespace(position=point, orientation=orientation))


@pytest.mark.parametrize("rpy", [(0.0, 0.0, 0.0), (0.1, -0.2, 2.9), (-3.0, 1.4, -0.5), (0.3, -1.5, 1.0)])
def test_quaternion_to_rpy_inverts_the_mirrors_rpy_to_quaternion(rpy):
    q = ros_msgs.quaternion_from_rpy(*rpy)
    assert np.allclose(ros_msgs.matrix_from_rpy(*rpy_from_quaternion(*q)), ros_msgs.matrix_from_rpy(*rpy), atol=1e-12)
    pose = pose_from_pose_stamped(stamped("map", (1.0, -2.0, 0.5), q))
    assert np.allclose(pose[:3], (1.0, -2.0, 0.5)) and np.allclose(pose[3:], rpy, atol=1e-9)


@pytest.mark.parametrize("frame, position, quaternion, reason", [
    ("odom", (0, 0, 0), (0, 0, 0, 1), "frame"),
    ("", (0, 0, 0), (0, 0, 0, 1), "frame"),
    ("map", (math.nan, 0, 0), (0, 0, 0, 1), "non-finite"),
    ("map", (0, 0, 0), (0, 0, 0, math.inf), "non-finite"),
    ("map", (0, 0, 0), (0, 0, 0, 0), "quaternion"),
    ("map", (0, 0, 0), (0, 0, 0, 2), "quaternion"),
])
def test_a_pose_that_is_not_the_targets_in_map_is_refused(frame, position, quaternion, reason):
    with pytest.raises(RefusedPose) as err:
        pose_from_pose_stamped(stamped(frame, position, quaternion))
    assert err.value.reason == reason


@pytest.fixture
def fleet():
    with fleet_with_router("hint-test") as fleet:
        yield fleet


def test_a_ros_node_hints_the_fleet_through_a_pose_stamped_topic(fleet):
    bridge = fleet.start("ros2", "--fleet", fleet.fleet, "--hints-from", TOPIC, "--hint-vehicle", "lab", "--json")
    ready = bridge.next_record(20, lambda r: r.get("event") == "ready")
    assert (ready["hints_from"], ready["hint_vehicle"]) == (TOPIC, "lab")
    received: list[np.ndarray] = []
    sent = [np.array([0.1 * k, -0.2, 0.05, 0.01 * k, -0.02, 0.6 + 0.1 * k]) for k in range(5)]
    #: the last valid pose, published after the refused ones: the bridge forwards in order, so once it arrives
    #: every hint the bridge could forward has arrived, and anything refused would have come before it
    marker = np.array([9.0, 9.0, 9.0, 0.0, 0.0, 0.0])
    matched, marker_in = threading.Event(), threading.Event()

    def on_hint(sample) -> None:
        received.append(decode_hint(sample.payload.to_bytes()))
        if np.allclose(received[-1], marker):
            marker_in.set()

    with client_session(fleet.endpoint) as session, \
            session.declare_subscriber(f"evopose/{fleet.fleet}/lab/hint", on_hint), \
            Ros2Node(session, Node("hinter", "/lab")) as node:
        publisher = node.publisher(TOPIC, ros_msgs.POSE_STAMPED, ros_msgs.type_hash(ros_msgs.POSE_STAMPED), DEFAULT_QOS)
        # the bridge found the publisher's token and subscribed: zenoh's matching status says so
        listener = publisher._publisher.declare_matching_listener(lambda s: matched.set() if s.matching else None)
        if publisher.matched:
            matched.set()
        assert matched.wait(20)
        listener.undeclare()
        now = time.time_ns()
        for pose in sent:
            publisher.publish(ros_msgs.serialize(ros_msgs.pose_stamped(pose, now, "map")))
        publisher.publish(ros_msgs.serialize(ros_msgs.pose_stamped(sent[0], now, "odom")))          # another frame
        publisher.publish(ros_msgs.serialize(ros_msgs.pose_stamped((math.nan, 0, 0, 0, 0, 0), now, "map")))
        publisher.publish(b"\x00\x01\x00\x00garbage")                                                  # not CDR
        publisher.publish(ros_msgs.serialize(ros_msgs.pose_stamped(marker, now, "map")))
        assert marker_in.wait(20)
    code, _ = bridge.stop(timeout=20)
    summary = bridge.next_record(10, lambda r: r.get("event") == "stopped")
    assert code == 0
    assert len(received) == len(sent) + 1
    for got, want in zip(received, [*sent, marker]):
        assert np.allclose(got, want, atol=1e-6)  # hints are float32 on the wire
    assert summary["hints"] == {"forwarded": 6, "refused": {"frame": 1, "non-finite": 1},
                                "undecodable": 1, "dropped": 0}, summary
