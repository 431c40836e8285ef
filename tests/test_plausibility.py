"""Messages a sane team-mate cannot send are refused and counted before they reach the estimator (issue 12):
unit checks of agents.vehicle.plausibility, and a ground station that survives a hostile IMU reading."""

from __future__ import annotations

import math
import sys
import time

import numpy as np

from agents.vehicle.plausibility import Plausibility
from evopose import Bounds
from protocol import Attitude, CameraInfo, FeatureSet, encode, topic_key
from tests.fleet_procs import Proc, free_port, peer_session, release_when_warm

BOX = Bounds.from_dict({"x": (-3, 3), "y": (-3, 3), "z": (-0.2, 0.5)})
CAMERA = CameraInfo(fx=1700, fy=1700, cx=320, cy=240, width=640, height=480, world_from_camera=(-27, 6, 12, 0, 0, 0))


def test_what_a_sane_team_mate_cannot_send_is_refused():
    check = Plausibility(BOX, operating_radius_m=100.0, max_clock_offset_s=0.5)
    assert check.camera(CAMERA) is None
    assert check.camera(CAMERA.model_copy(update={"fx": 1e9})) == "implausible-focal-length"
    assert check.camera(CAMERA.model_copy(update={"world_from_camera": (1e300, 0, 0, 0, 0, 0)})) \
        == "outside-operating-area"
    assert check.pose_in_box([0.1, 0.2, 0.0, 0, 0, 1.0]) is None
    assert check.pose_in_box([10.0, 0.2, 0.0, 0, 0, 1.0]) == "outside-search-box"
    assert check.pose_in_box([np.nan, 0, 0, 0, 0, 0]) == "non-finite-pose"
    attitude = Attitude(sender="airship", seq=0, stamp_ns=0, body="airship", roll=0.1, pitch=0, yaw=0,
                        sigma=(0.01, 0.01, 0.01))
    assert check.attitude(attitude) is None
    assert check.attitude(attitude.model_copy(update={"sigma": (1e308, 0.01, 0.01)})) == "implausible-sigma"
    assert check.attitude(attitude.model_copy(update={"sigma": (0.0, 0.01, 0.01)})) == "implausible-sigma"
    now = time.time_ns()
    assert check.stamp(now + int(0.1e9), now) is None and check.stamp(now + int(60e9), now) == "future-stamp"
    features = FeatureSet(sender="H1", seq=0, stamp_ns=0, camera=CAMERA, points=b"", best=(50.0, 0, 0, 0, 0, 0))
    assert check.feature_set(features) == "outside-search-box"


def test_a_hostile_imu_reading_is_counted_and_the_station_keeps_going():
    """An Attitude with sigma = 1e308 (valid per the schema) once killed the ground station."""
    port, fleet = free_port(), "hostile-attitude"
    station = Proc([sys.executable, "-m", "agents.cli", "agent", "--scenario", "exp1-airship", "--fleet", fleet,
                    "--vehicle", "ground-station", "--frames", "25", "--epoch-from-stdin", "--listen",
                    f"tcp/127.0.0.1:{port}", "--json"])
    try:
        release_when_warm([station])   # frame 0 a second after the station is warm, as a scenario run starts it
        with peer_session(f"tcp/127.0.0.1:{port}") as session:
            token = session.liveliness().declare_token(f"evopose/{fleet}/@alive/airship")
            key = topic_key(fleet, "airship", "attitude")
            deadline = time.monotonic() + 60
            seq = 0
            while station.popen.poll() is None and time.monotonic() < deadline:
                hostile = Attitude(sender="airship", seq=seq, stamp_ns=time.time_ns(), body="airship", roll=1e308,
                                   pitch=0.0, yaw=0.0, sigma=(1e308, 1e308, 1e308))
                session.put(key, encode(hostile))
                seq += 1
                time.sleep(0.05)
            token.undeclare()
        code = station.wait(60)
    finally:
        station.kill()
    assert code == 0, station.popen.stderr.read()[-1500:]
    records = station.all_records()
    summary = [r for r in records if r.get("event") == "summary"][0]
    frames = [r for r in records if r.get("event") == "frame"]
    assert summary["frames"] == 25 and summary["traffic"]["rejected"].get("implausible-sigma", 0) > 0
    assert all(not r["knowledge"] for r in frames)  # the hostile reading never became eq. (3) knowledge
    assert all(math.isfinite(r["pose"]["x"]) for r in frames)


def test_a_compressed_image_is_decoded_only_within_the_pixel_budget():
    import cv2
    import pytest

    from agents.vehicle.team_views import MAX_DECODED_PIXELS, image_of
    from protocol import ImageFrame

    ok, png = cv2.imencode(".png", np.zeros((64, 64, 3), np.uint8))
    camera = CAMERA.model_copy(update={"width": 64, "height": 64})
    frame = ImageFrame(sender="H2", seq=0, stamp_ns=0, camera=camera, encoding="png", width=64, height=64,
                       channels=3, data=png.tobytes())
    assert image_of(frame).shape == (64, 64, 3)
    side = int(np.sqrt(MAX_DECODED_PIXELS)) + 1
    huge = frame.model_copy(update={"width": side, "height": side,
                                    "camera": camera.model_copy(update={"width": side, "height": side})})
    with pytest.raises(ValueError, match="over the budget"):
        image_of(huge)
    lying = frame.model_copy(update={"width": 32, "height": 32})
    with pytest.raises(ValueError, match="header says 64x64"):
        image_of(lying)
    # a header claiming 20000 x 20000 (Pillow's decompression-bomb limit) in a frame that says 64 x 64
    import struct
    import zlib

    ihdr = b"IHDR" + struct.pack(">II", 20000, 20000) + png.tobytes()[24:29]
    bomb = png.tobytes()[:12] + ihdr + struct.pack(">I", zlib.crc32(ihdr)) + png.tobytes()[33:]
    with pytest.raises(ValueError, match="no readable header"):
        image_of(frame.model_copy(update={"data": bomb}))
