"""`evopose record` and `evopose replay` (docs/ros2.md): a real fleet recorded into two MCAP files (a ROS 2 profile
file read whole by readers that are not ours, and the raw channels beside it), then replayed into a fresh receiving
agent, which gets the same messages (same senders, sequence numbers and poses; stamps moved by one offset).

The ROS 2 file is checked against the rules of rosbag2's MCAP storage plugin (ros2/rosbag2
``rosbag2_storage_mcap/src/mcap_storage.cpp`` ``read_metadata`` and ``rosbag2_storage/src/rosbag2_storage/qos.cpp``,
:func:`check_rosbag2_rules`), read over every channel by the ``rosbags`` rosbag2 reader and decoded message by
message, with no topic filter, by the ``mcap`` reader with ``mcap-ros2-support`` (:func:`check_ros2_file`)."""

from __future__ import annotations

import signal
import sys

import msgpack
import numpy as np
import pytest
import zenoh
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

import re
import threading

import yaml
from mcap.writer import Writer
from rosbags.rosbag2 import Reader as Rosbag2Reader
from rosbags.typesys import Stores, get_typestore, get_types_from_msg

from agents.bridges.names import topic_name
from agents.bridges.recording import (Recorder, RecordingError, offered_qos_profiles, raw_messages, raw_path,
                                      raw_recording, restamp, run_record)
from agents.bridges.rmw_zenoh import DEFAULT_QOS, SENSOR_QOS, TF_QOS
from agents.bridges.tap import RawSample
from agents.runs import pose_rows
from agents.tools.runners import PublishSpec, sample_message
from agents.transport.session import SessionOptions
from protocol.codec import decode_sample, encode
from protocol.keys import Topic, topic_key
from protocol.messages import PoseEstimate
from tests.fleet_procs import Proc, client_session, fleet_with_router, free_port

N = 20


@pytest.fixture
def fleet():
    with fleet_with_router("rec-test") as fleet:
        yield fleet


# -- the rules of rosbag2's MCAP storage plugin, and readers that are not ours -------------------------------

#: rosbag2_storage qos.cpp ``convert<rclcpp::QoS>::decode``: the keys of a profile, read with ``as<...>``.
QOS_KEYS = {"history", "depth", "reliability", "durability", "deadline", "lifespan", "liveliness",
            "liveliness_lease_duration", "avoid_ros_namespace_conventions"}
#: rmw/qos_string_conversions.c names, the version-9 form of the policies (version 8: their integers).
POLICY_NAMES = {"history": {"system_default", "keep_last", "keep_all"},
                "reliability": {"system_default", "reliable", "best_effort", "best_available"},
                "durability": {"system_default", "transient_local", "volatile", "best_available"},
                "liveliness": {"system_default", "automatic", "manual_by_topic", "best_available"}}


def check_rosbag2_rules(path) -> dict:
    """What ``MCAPStorage::read_metadata`` needs of a file: the Statistics record; every channel's schema present
    ("Could not find schema for topic ..." otherwise), named ``pkg/msg/Type``, ``ros2msg`` or ``ros2idl``; the
    channel's message encoding the serialization format (``cdr``); ``offered_qos_profiles`` a YAML list of
    profiles that ``to_rclcpp_qos_vector`` decodes (all keys; the policies all integers or all names;
    durations ``{sec, nsec}``); ``topic_type_hash`` the type's RIHS01 hash. Returns the channels by topic."""
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
    assert summary is not None and summary.statistics is not None
    channels = {c.topic: c for c in summary.channels.values()}
    for channel in channels.values():
        schema = summary.schemas.get(channel.schema_id)
        assert channel.schema_id != 0 and schema is not None, f"Could not find schema for topic {channel.topic}"
        assert re.fullmatch(r"\w+/msg/\w+", schema.name) and schema.encoding in ("ros2msg", "ros2idl"), schema
        assert channel.message_encoding == "cdr", channel
        assert re.fullmatch(r"RIHS01_[0-9a-f]{64}", channel.metadata["topic_type_hash"]), channel
        profiles = yaml.safe_load(channel.metadata["offered_qos_profiles"])
        assert isinstance(profiles, list) and profiles, channel
        for profile in profiles:
            assert set(profile) == QOS_KEYS, profile
            integers = isinstance(profile["history"], int)
            for policy, names in POLICY_NAMES.items():
                assert profile[policy] in (range(0, 5) if integers else names), (policy, profile)
            assert isinstance(profile["depth"], int) and isinstance(profile["avoid_ros_namespace_conventions"], bool)
            for duration in ("deadline", "lifespan", "liveliness_lease_duration"):
                assert set(profile[duration]) == {"sec", "nsec"}, profile
    return channels


def check_ros2_file(path) -> dict[str, int]:
    """Read every channel of ``path`` with the rosbags rosbag2 reader (types from the file's own schemas) and
    decode every message with the ``mcap`` reader and Foxglove's ROS 2 decoder, no topic filter; both must see
    the same messages. Returns the message count per topic."""
    channels = check_rosbag2_rules(path)
    by_rosbags: dict[str, int] = {}
    with Rosbag2Reader(path) as bag:
        assert {c.topic for c in bag.connections} == set(channels)
        typestore = get_typestore(Stores.EMPTY)
        for connection in bag.connections:
            assert connection.msgdef.data, connection
            typestore.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
            assert connection.ext.serialization_format == "cdr" and connection.ext.offered_qos_profiles
        for connection, _, data in bag.messages():
            typestore.deserialize_cdr(data, connection.msgtype)
            by_rosbags[connection.topic] = by_rosbags.get(connection.topic, 0) + 1
    by_mcap: dict[str, int] = {}
    with open(path, "rb") as stream:
        for _, channel, _, decoded in make_reader(stream, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            assert decoded is not None
            by_mcap[channel.topic] = by_mcap.get(channel.topic, 0) + 1
    assert by_rosbags == by_mcap and set(by_mcap) == set(channels)
    return by_mcap


def test_offered_qos_profiles_are_what_rosbag2_writes():
    """The integer form rosbag2 wrote before metadata version 9 (rosbag2 test_qos.cpp's fixture): Humble reads only
    that, Jazzy and later detect it."""
    assert yaml.safe_load(offered_qos_profiles(DEFAULT_QOS)) == [{
        "history": 1, "depth": 10, "reliability": 1, "durability": 2, "deadline": {"sec": 0, "nsec": 0},
        "lifespan": {"sec": 0, "nsec": 0}, "liveliness": 1, "liveliness_lease_duration": {"sec": 0, "nsec": 0},
        "avoid_ros_namespace_conventions": False}]
    assert yaml.safe_load(offered_qos_profiles(SENSOR_QOS))[0]["reliability"] == 2
    assert yaml.safe_load(offered_qos_profiles(TF_QOS))[0]["depth"] == 100


def test_every_mirrored_message_kind_in_a_ros2_file_and_the_rest_beside_it(tmp_path):
    """All five fleet topics a vehicle sends, recorded: the ROS 2 file holds only ROS 2 channels that rosbag2's
    rules, rosbags and Foxglove's decoder all accept; the raw file holds every sample, replay finds it from either."""
    out = tmp_path / "all.mcap"
    rng = np.random.default_rng(1)
    samples = []
    for seq in range(3):
        for topic in (Topic.POSE, Topic.FEATURES, Topic.IMAGE, Topic.ATTITUDE, Topic.HINT):
            header = {"sender": "uav-1", "seq": seq, "stamp_ns": 1_700_000_000_000_000_000 + seq * 100_000_000}
            message = sample_message(PublishSpec(topic, width=64, height=48), header, rng)
            samples.append(RawSample(topic_key("rec-x", "uav-1", topic.value), encode(message),
                                     header["stamp_ns"] + 5_000_000))
    with open(out, "wb") as ros_stream, open(raw_path(out), "wb") as raw_stream:
        ros, raw = Writer(ros_stream), Writer(raw_stream)
        ros.start(profile="ros2", library="test")
        raw.start(profile="", library="test")
        recorder = Recorder(ros, raw)
        for sample in samples:
            recorder.handle(sample)
        ros.finish()
        raw.finish()
    counts = check_ros2_file(out)
    assert counts == {"/rec_x/uav_1/target_pose": 3, "/rec_x/uav_1/camera_info": 6, "/rec_x/uav_1/image_raw": 3,
                      "/rec_x/uav_1/imu": 3, "/rec_x/uav_1/hint": 3, "/tf": 9}
    recorded = [(key, payload) for key, _, payload in raw_messages(raw_path(out))]
    assert recorded == [(s.key, s.payload) for s in samples]
    assert not list(raw_messages(out))
    assert raw_recording(out) == raw_recording(raw_path(out)) == raw_path(out)


def test_record_refuses_nothing_to_record_and_a_raw_name(tmp_path):
    with pytest.raises(RecordingError, match="nothing to record"):
        run_record(SessionOptions(), threading.Event(), "f", tmp_path / "x.mcap", ros=False, raw=False)
    with pytest.raises(RecordingError, match=r"\*\.raw\.mcap"):
        run_record(SessionOptions(), threading.Event(), "f", tmp_path / "x.raw.mcap")
    assert not list(tmp_path.iterdir())


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

    # the ROS 2 file: every channel read by rosbags and decoded by Foxglove's decoder; the raw file: nothing lost
    assert summary["out"] == str(out) and summary["raw"] == str(raw_path(out))
    counts = check_ros2_file(out)
    assert counts["/rec_test/uav_1/target_pose"] == N and counts["/rec_test/uav_1/camera_info"] == N
    with open(raw_path(out), "rb") as stream:
        raw_summary = make_reader(stream).get_summary()
    raw_counts = {c.topic: raw_summary.statistics.channel_message_counts[c.id] for c in raw_summary.channels.values()}
    assert raw_counts[f"evopose/{fleet.fleet}/uav-1/pose"] == N
    assert raw_counts[f"evopose/{fleet.fleet}/uav-1/features"] == N
    with open(out, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        ros_poses = {m.publish_time: d for _, _, m, d in reader.iter_decoded_messages(
            topics=["/rec_test/uav_1/target_pose"])}
    with open(raw_path(out), "rb") as stream:
        recorded = {}
        for _, channel, message in make_reader(stream).iter_messages(topics=[f"evopose/{fleet.fleet}/uav-1/pose"]):
            estimate = decode_sample(channel.topic, message.data)[1]
            recorded[estimate.seq] = estimate
            assert message.publish_time == estimate.stamp_ns
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
        check_recording(run, tmp_path / "runs" / run["fleet"], frames)


def check_bag_directory(bag) -> dict[str, int]:
    """A rosbag2 bag directory as ``ros2 bag info DIR`` opens it: metadata.yaml (version 8, storage mcap) naming
    its one MCAP file, whose topics, types and counts it states; ``rosbags.rosbag2.Reader(DIR)`` reads every
    message back and decodes it with the types the file carries. Returns the message count per topic."""
    metadata = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert metadata["version"] == 8 and metadata["storage_identifier"] == "mcap"
    assert metadata["relative_file_paths"] == [f"{bag.name}.mcap"] and (bag / f"{bag.name}.mcap").is_file()
    by_file = check_ros2_file(bag / f"{bag.name}.mcap")
    stated = {t["topic_metadata"]["name"]: t["message_count"] for t in metadata["topics_with_message_count"]}
    assert stated == by_file and metadata["message_count"] == sum(by_file.values())
    read: dict[str, int] = {}
    with Rosbag2Reader(bag) as reader:
        typestore = get_typestore(Stores.EMPTY)
        for connection in reader.connections:
            assert connection.msgdef.data, connection  # the definitions come from the MCAP file's schemas
            typestore.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
        assert reader.message_count == sum(by_file.values())
        for connection, timestamp, data in reader.messages():
            assert reader.start_time <= timestamp < reader.end_time
            typestore.deserialize_cdr(data, connection.msgtype)
            read[connection.topic] = read.get(connection.topic, 0) + 1
    assert read == by_file
    return read


def test_record_into_a_bag_directory(tmp_path):
    """``evopose record --out DIR``: a rosbag2 bag directory (DIR/DIR.mcap and the metadata.yaml rosbag2 writes)
    that rosbags' Reader(DIR) opens and reads every message of; a non-empty directory is refused."""
    from agents.bridges.recording import bag_file, bag_metadata

    bag = tmp_path / "bag"
    bag.mkdir()
    out = bag_file(bag)
    rng = np.random.default_rng(2)
    with open(out, "wb") as stream:
        writer = Writer(stream)
        writer.start(profile="ros2", library="test")
        recorder = Recorder(writer, None)
        for seq in range(3):
            for topic in (Topic.POSE, Topic.FEATURES, Topic.IMAGE, Topic.ATTITUDE, Topic.HINT):
                header = {"sender": "uav-1", "seq": seq, "stamp_ns": 1_700_000_000_000_000_000 + seq * 100_000_000}
                message = sample_message(PublishSpec(topic, width=64, height=48), header, rng)
                recorder.handle(RawSample(topic_key("rec-x", "uav-1", topic.value), encode(message),
                                          header["stamp_ns"] + 5_000_000))
        writer.finish()
    (bag / "metadata.yaml").write_text(yaml.safe_dump(bag_metadata(recorder, out.name), sort_keys=False))
    assert check_bag_directory(bag) == {"/rec_x/uav_1/target_pose": 3, "/rec_x/uav_1/camera_info": 6,
                                        "/rec_x/uav_1/image_raw": 3, "/rec_x/uav_1/imu": 3, "/rec_x/uav_1/hint": 3,
                                        "/tf": 9}
    with pytest.raises(RecordingError, match="not an empty directory"):
        run_record(SessionOptions(), threading.Event(), "f", bag)


def check_recording(run: dict, bag, frames: int) -> None:
    path = bag / f"{bag.name}.mcap"
    assert run["recording"] == str(bag) and path.is_file() and raw_path(path).is_file()
    assert set(check_bag_directory(bag)) == set(check_ros2_file(path))
    assert raw_recording(bag) == raw_path(path)
    ros_topics = set(check_ros2_file(path))
    expected = {"/tf", *(topic_name(run["fleet"], v, "target_pose") for v in ("H1", "H2"))}
    assert expected <= ros_topics, ros_topics
    with open(raw_path(path), "rb") as stream:
        reader = make_reader(stream)
        for vehicle in ("H1", "H2"):
            poses = {}
            for _, channel, message in reader.iter_messages(topics=[f"evopose/{run['fleet']}/{vehicle}/pose"]):
                estimate = decode_sample(channel.topic, message.data)[1]
                poses[estimate.stamp_ns] = estimate.pose
            published = pose_rows(run["agents"][vehicle])
            assert len(poses) == len(published) == frames
            recorded = sorted(poses.items())
            for row, (_, pose) in zip(published, recorded):
                assert np.allclose(row.pose, pose, atol=1e-9)
