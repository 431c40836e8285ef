"""A pose at its image's header stamp (agents/bridges/stamped.py), tested by its effect."""

import threading
import time

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from agents.bridges.stamped import KEEP, MAX_POSE_GAP_S, PoseHistory, StampedTransforms

MS = 1_000_000


def pose(x: float, yaw_deg: float) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = Rotation.from_euler("z", yaw_deg, degrees=True).as_matrix()
    m[:3, 3] = (x, 2.0 * x, 10.0)
    return m


def yaw_of(m: np.ndarray) -> float:
    return float(Rotation.from_matrix(m[:3, :3]).as_euler("zyx", degrees=True)[0])


def test_an_images_pose_is_the_one_of_its_stamp_not_the_newest():
    history = PoseHistory()
    for k in range(5):   # a camera moving 1 m and turning 10 deg every 100 ms
        history.add(k * 100 * MS, pose(k, 10.0 * k))
    assert np.array_equal(history.at(200 * MS), pose(2, 20.0))   # exactly its own, not the newest (k = 4)
    between = history.at(250 * MS)   # interpolated: half way in position and attitude
    assert np.allclose(between[:3, 3], (2.5, 5.0, 10.0)) and yaw_of(between) == pytest.approx(25.0)
    assert np.allclose(between[:3, :3] @ between[:3, :3].T, np.eye(3))   # still a rotation
    # past the last pose: the nearest within the gap, else none (the tick is skipped)
    assert np.array_equal(history.at(400 * MS + int(MAX_POSE_GAP_S * 1e9)), pose(4, 40.0))
    assert history.at(400 * MS + int(MAX_POSE_GAP_S * 1e9) + 1) is None
    assert history.at(-int(MAX_POSE_GAP_S * 1e9) - 1) is None and PoseHistory().at(0) is None


def test_poses_out_of_order_and_a_stray_stamp_do_not_move_an_images_pose():
    history = PoseHistory()
    for k in (3, 0, 2, 1):   # arrival order is not stamp order
        history.add(k * 100 * MS, pose(k, 0.0))
    history.add(100 * MS, pose(1, 0.0))   # the same stamp twice: one entry
    history.add(10**18, pose(1000.0, 90.0))   # a stray stamp far ahead: never interpolated across
    assert np.array_equal(history.at(300 * MS), pose(3, 0.0))
    assert np.array_equal(history.at(350 * MS), pose(3, 0.0))   # the nearest, within the gap
    assert history.at(10**17) is None


def test_the_history_is_bounded():
    stream = StampedTransforms()
    for k in range(10 * KEEP):
        stream.add(k * MS, pose(k, 0.0))
    assert len(stream) == KEEP and stream.stamps[0] == (9 * KEEP) * MS


def test_a_pose_published_just_after_its_image_is_waited_for():
    history = PoseHistory()
    history.add(0, pose(0, 0.0))
    late = threading.Timer(0.02, lambda: history.add(100 * MS, pose(1, 0.0)))
    late.start()
    started = time.monotonic()
    try:
        got = history.at(100 * MS, wait_s=2.0)
    finally:
        late.join()
    # the image's own pose (not the older one 100 ms before it), as soon as it came
    assert np.array_equal(got, pose(1, 0.0)) and time.monotonic() - started < 1.0
