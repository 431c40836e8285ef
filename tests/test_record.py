"""`evopose record` and `evopose replay` (docs/ros2.md): a real fleet recorded into one MCAP file (ROS 2 profile read
back by Foxglove's own ROS 2 decoder, plus the raw channels), then replayed into a fresh receiving agent, which gets
the same messages (same senders, sequence numbers and poses; stamps moved by one offset)."""

from __future__ import annotations

import signal
import sys

import msgpack
import numpy as np
import pytest
import zenoh
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from agents.bridges.names import topic_name
from agents.bridges.recording import restamp
from protocol.codec import decode_sample, encode
from protocol.messages import PoseEstimate
from tests.fleet_procs import Proc, client_session, fleet_with_router, free_port

N = 20


@pytest.fixture
def fleet():
    with fleet_with_router("rec-test") as fleet:
        yield fleet


def test_restamp_moves_only_the_stamp():
    message = PoseEstimate(sender="H1", seq=4, stamp_ns=1_000, pose=(1.0, 2.0, 3.0, 0.1, 0.2, 0.3), fitness=0.5,
                           mismatch=0.1, converged=True, generations=3, seconds=0.25)
    moved = restamp(encode(message), first_stamp_ns=500, start_ns=10_000)
    assert msgpack.unpackb(moved) == {**msgpack.unpackb(encode(message)), "stamp_ns": 10_500}
    assert restamp(encode(message), 500, 10_000, rate=2.0) != moved
    assert msgpack.unpackb(restamp(encode(message), 500, 10_000, rate=2.0))["stamp_ns"] == 10_250
    assert restamp(b"\xc1garbage", 0, 1) == b"\xc1garbage"


def test_record_then_replay_into_a_fresh_agent(fleet, tmp_path):
    out = tmp_path / "run.mcap"
    recorder = fleet.start("record", "--fleet", fleet.fleet, "--out", str(out), "--json")
    recorder.next_record(20, lambda r: r.get("event") == "ready")
    publishers = [fleet.start("publish", "--fleet", fleet.fleet, "--vehicle", "uav-1", "--topic", topic, "--rate",
                              "20", "--count", str(N), "--wait", "10", "--seed", "3") for topic in ("pose", "features")]
    for publisher in publishers:
        assert publisher.wait(60) == 0, publisher.stderr_now()
        assert publisher.all_records()[-1]["matched"] is True
    code, _ = recorder.stop(signal.SIGTERM, timeout=20)
    summary = recorder.next_record(5, lambda r: r.get("event") == "stopped")
    assert code == 0 and summary["rejected"] == 0 and summary["dropped"] == 0

    # the file: ROS 2 profile, ros2msg schemas, CDR that Foxglove's decoder reads; the raw channels, nothing lost
    with open(out, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        summary_section = reader.get_summary()
        channels = {c.topic: c for c in summary_section.channels.values()}
        counts = {c.topic: summary_section.statistics.channel_message_counts[c.id] for c in channels.values()}
        assert counts[f"evopose/{fleet.fleet}/uav-1/pose"] == N and counts[f"evopose/{fleet.fleet}/uav-1/features"] == N
        assert counts["/rec_test/uav_1/target_pose"] == N and counts["/rec_test/uav_1/camera_info"] == N
        assert channels["/rec_test/uav_1/target_pose"].message_encoding == "cdr"
        assert summary_section.schemas[channels["/tf"].schema_id].encoding == "ros2msg"
        recorded = {}
        for _, channel, message in reader.iter_messages(topics=[f"evopose/{fleet.fleet}/uav-1/pose"]):
            estimate = decode_sample(channel.topic, message.data)[1]
            recorded[estimate.seq] = estimate
            assert message.publish_time == estimate.stamp_ns
        ros_poses = {m.publish_time: d for _, _, m, d in reader.iter_decoded_messages(
            topics=["/rec_test/uav_1/target_pose"])}
    assert sorted(recorded) == list(range(N))
    for estimate in recorded.values():
        pose = ros_poses[estimate.stamp_ns].pose.pose
        assert (pose.position.x, pose.position.y, pose.position.z) == estimate.pose[:3]
        assert np.allclose([pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w],
                           estimate.quaternion)

    # replay into a fresh receiving agent (drops stale data: max age 1 s) and a raw subscriber
    agent = fleet.start("listen", "--fleet", fleet.fleet, "--vehicle", "fresh", "--topics", "pose,features")
    agent.next_record(20, lambda r: r.get("event") == "ready")
    replayed = {}

    def on_pose(sample: zenoh.Sample) -> None:
        estimate = decode_sample(str(sample.key_expr), sample.payload.to_bytes())[1]
        replayed[estimate.seq] = estimate

    with client_session(fleet.endpoint) as session, \
            session.declare_subscriber(f"evopose/{fleet.fleet}/**", lambda s: on_pose(s) if str(
                s.key_expr).endswith("/pose") else None):
        replay = fleet.start("replay", str(out), "--json", "--wait", "20")
        ready = replay.next_record(30, lambda r: r.get("event") == "ready")
        assert ready["matched"] is True
        assert replay.wait(60) == 0, replay.stderr_now()
        done = replay.all_records()[-1]
        assert done["sent"][f"evopose/{fleet.fleet}/uav-1/pose"] == N
    code, _ = agent.stop(signal.SIGTERM, timeout=20)
    counters = agent.next_record(10, lambda r: r.get("event") == "summary")
    assert counters["received"].get("pose") == N and counters["received"].get("features") == N, counters
    assert not counters["rejected"], counters["rejected"]

    assert sorted(replayed) == sorted(recorded)
    for seq, estimate in recorded.items():
        again = replayed[seq]
        assert again.model_dump(exclude={"stamp_ns"}) == estimate.model_dump(exclude={"stamp_ns"})
        assert again.stamp_ns - estimate.stamp_ns == ready["shift_ns"]


def test_scenario_run_records_every_run(tmp_path):
    """`evopose scenario run NAME --record DIR`: each run's traffic in DIR/<fleet>.mcap, every pose the agents
    published (checked against their own summaries), as raw channels and as ROS 2 messages."""
    frames = 8
    runner = Proc([sys.executable, "-m", "agents.cli", "scenario", "run", "exp2a-features", "--frames", str(frames),
                   "--runs", "2", "--listen", f"tcp/127.0.0.1:{free_port()}", "--record", str(tmp_path / "runs"),
                   "--json"])
    try:
        result = runner.next_record(120, lambda r: "runs" in r)
        assert runner.wait(20) == 0
    finally:
        runner.kill()
    assert len(result["runs"]) == 2 and len({run["fleet"] for run in result["runs"]}) == 2
    for run in result["runs"]:
        check_recording(run, tmp_path / "runs" / f"{run['fleet']}.mcap", frames)


def check_recording(run: dict, path, frames: int) -> None:
    assert run["recording"] == str(path) and path.is_file()
    with open(path, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for vehicle in ("H1", "H2"):
            poses = {}
            for _, channel, message in reader.iter_messages(topics=[f"evopose/{run['fleet']}/{vehicle}/pose"]):
                estimate = decode_sample(channel.topic, message.data)[1]
                poses[estimate.stamp_ns] = estimate.pose
            published = run["agents"][vehicle]["poses"]  # [frame, x, y, z, roll, pitch, yaw, good] per frame
            assert len(poses) == len(published) == frames
            recorded = sorted(poses.items())
            for row, (_, pose) in zip(published, recorded):
                assert np.allclose(row[1:7], pose, atol=1e-9)
        ros_topics = {c.topic for c in reader.get_summary().channels.values()}
        expected = {"/tf", *(topic_name(run["fleet"], v, "target_pose") for v in ("H1", "H2"))}
        assert expected <= ros_topics, ros_topics
