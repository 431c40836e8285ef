"""The ROS 2 mirror in the rmw_zenoh format (docs/ros2.md): the format against rmw_zenoh's own documentation and
zenoh's serializer, golden CDR bytes, and a real fleet mirrored by `evopose ros2` and received by a pure-Python
subscriber that finds the publishers through their liveliness tokens.

No live ROS 2 install was available: the format is checked against the sources named in docs/ros2.md.
Rewrite the golden file (only on purpose) with ``python -m tests.test_ros2``.
"""

from __future__ import annotations

import math
import struct
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import zenoh
import zenoh.ext

from agents.bridges import names, ros_msgs
from agents.bridges.listener import Ros2Listener
from agents.bridges.rmw_zenoh import (DEFAULT_QOS, LEGACY_DURABILITY, SENSOR_QOS, TF_QOS, Attachment, Durability,
                                      EntityKind, Node, QoS, Reliability, decode_attachment, dds_type_name,
                                      encode_attachment, endpoint_token, gid, node_token, parse_token, ros_type_name,
                                      topic_key)
from agents.bridges.ros2_node import Ros2Node
from agents.bridges.translate import estimate_messages
from protocol.codec import decode_sample
from protocol.messages import PoseEstimate
from tests.fleet_procs import Fleet, client_session, fleet_with_router, free_port, peer_session

GOLDEN = Path(__file__).resolve().parent / "golden" / "ros2_pose.cdr"
STAMP_NS = 1_700_000_000_123_456_789
#: rmw_zenoh docs/design.md's examples (demo_nodes_cpp).
STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
#: Independently published hashes of the types the mirror uses (Jazzy = Kilted = Rolling for these).
KNOWN_HASHES = {
    "std_msgs/msg/String": STRING_HASH,
    "geometry_msgs/msg/PoseWithCovarianceStamped":
        "RIHS01_26432f9803e43727d3c8f668d1fdb3c630f548af631e2f4e31382371bfea3b6e",
    "tf2_msgs/msg/TFMessage": "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
}


# -- the format, against rmw_zenoh's documentation ----------------------------------------------------

def test_data_keys_are_those_of_the_design_document():
    assert topic_key(0, "/chatter", "std_msgs/msg/String", STRING_HASH) == \
        f"0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"
    assert topic_key(0, "/robot1/chatter", "std_msgs/msg/String", STRING_HASH) == \
        f"0/robot1/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"
    assert dds_type_name("geometry_msgs/msg/PoseWithCovarianceStamped") == \
        "geometry_msgs::msg::dds_::PoseWithCovarianceStamped_"
    assert ros_type_name("tf2_msgs::msg::dds_::TFMessage_") == "tf2_msgs/msg/TFMessage"


def test_liveliness_tokens_are_those_of_the_design_document():
    zid = "8b20917502ee955ac4476e0266340d5c"
    talker = Node("talker")
    assert node_token(2, zid, 0, talker) == f"@ros2_lv/2/{zid}/0/0/NN/%/%/talker"
    token = endpoint_token(EntityKind.PUBLISHER, 2, zid, 0, 10, talker, "/chatter", "std_msgs/msg/String",
                           STRING_HASH, QoS(depth=7))
    assert token == (f"@ros2_lv/2/{zid}/0/10/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/{STRING_HASH}/"
                     "::,7:,:,:,,")
    entity = parse_token(token)
    assert (entity.kind, entity.domain, entity.node, entity.topic, entity.msgtype, entity.qos) == (
        EntityKind.PUBLISHER, 2, talker, "/chatter", "std_msgs/msg/String", QoS(depth=7))
    assert entity.data_key == f"2/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"
    namespaced = node_token(0, zid, 3, Node("evopose_mirror", "/exp2a_features"))
    assert namespaced == f"@ros2_lv/0/{zid}/3/3/NN/%/%exp2a_features/evopose_mirror"
    assert parse_token(namespaced).node == Node("evopose_mirror", "/exp2a_features")


def test_qos_strings_leave_rmw_zenoh_defaults_empty():
    assert DEFAULT_QOS.keyexpr() == "::,10:,:,:,,"
    assert TF_QOS.keyexpr() == "::,100:,:,:,,"
    assert QoS(depth=42).keyexpr() == "::,:,:,:,,"
    assert QoS(depth=5, reliability=Reliability.BEST_EFFORT).keyexpr() == "2::,5:,:,:,,"
    for qos in (DEFAULT_QOS, TF_QOS, QoS(depth=5, reliability=Reliability.BEST_EFFORT)):
        assert QoS.parse(qos.keyexpr()) == qos


def durability_as_read_by(chunk: str, default: Durability) -> Durability:
    """rmw_zenoh_cpp ``keyexpr_to_qos``: the second ':'-field, or the release's default when empty."""
    field = chunk.split(":")[1]
    return default if field == "" else Durability(int(field))


def test_legacy_tokens_write_out_the_durability_jazzy_0_2_0_to_0_2_2_would_misread():
    """Before ros2/rmw_zenoh#521 (Jazzy 0.2.3) the default durability was transient local: an empty field told
    0.2.0-0.2.2 our volatile publishers keep a history. ``--legacy-attachment`` tokens write it out, which those,
    0.2.3 and today's all read as volatile; today's tokens keep leaving it empty."""
    assert DEFAULT_QOS.keyexpr(legacy=True) == ":2:,10:,:,:,,"
    assert SENSOR_QOS.keyexpr(legacy=True) == "2:2:,5:,:,:,,"
    for qos in (DEFAULT_QOS, TF_QOS, SENSOR_QOS):
        assert QoS.parse(qos.keyexpr(legacy=True)) == QoS.parse(qos.keyexpr()) == qos
        assert durability_as_read_by(qos.keyexpr(), LEGACY_DURABILITY) is Durability.TRANSIENT_LOCAL  # the bug
        for default in (LEGACY_DURABILITY, Durability.VOLATILE):
            assert durability_as_read_by(qos.keyexpr(legacy=True), default) is Durability.VOLATILE
    with peer_session(f"tcp/127.0.0.1:{free_port()}") as session:
        for legacy, chunk in ((True, ":2:,10:,:,:,,"), (False, "::,10:,:,:,,")):
            with Ros2Node(session, Node("n", "/legacy"), legacy_attachment=legacy) as node:
                publisher = node.publisher("/legacy/t", "std_msgs/msg/String", STRING_HASH)
                subscription = node.subscription("/legacy/u", "std_msgs/msg/String", STRING_HASH)
                declared = {str(reply.ok.key_expr) for reply in session.liveliness().get("@ros2_lv/0/**")}
                assert publisher.token_key.endswith("/" + chunk) and publisher.token_key in declared
                assert subscription.token_key.endswith("/" + chunk) and subscription.token_key in declared


def test_the_attachment_is_what_zenoh_cpps_serializer_writes():
    source_gid = bytes(range(16))
    attachment = Attachment(7, 1_700_000_000_000_000_001, source_gid)
    data = encode_attachment(attachment)
    # docs/design.md: 8 bytes sequence number, 8 bytes timestamp (little-endian), 1 byte length (16), 16 bytes
    assert data == struct.pack("<qqB", 7, 1_700_000_000_000_000_001, 16) + source_gid and len(data) == 33
    # zenoh's own serializer, as zenoh-cpp's ext::Serializer writes int64, int64, std::array<uint8_t, 16>
    assert data == zenoh.ext.z_serialize((zenoh.ext.Int64(7), zenoh.ext.Int64(1_700_000_000_000_000_001),
                                          [zenoh.ext.UInt8(b) for b in source_gid])).to_bytes()
    assert decode_attachment(data) == attachment
    legacy = encode_attachment(attachment, legacy=True)
    assert legacy == zenoh.ext.z_serialize(("sequence_number", zenoh.ext.Int64(7), "source_timestamp",
                                            zenoh.ext.Int64(1_700_000_000_000_000_001), "source_gid",
                                            source_gid)).to_bytes()
    assert decode_attachment(legacy) == attachment
    for bad in (data[:-1], data + b"\x00", b"", legacy[:20]):
        with pytest.raises(ValueError):
            decode_attachment(bad)


def test_gid_is_xxh3_128_of_the_token_low_half_first():
    import xxhash

    token = "@ros2_lv/0/abc/0/1/MP/%/%/n/%t/std_msgs::msg::dds_::String_/" + STRING_HASH + "/::,10:,:,:,,"
    digest = xxhash.xxh3_128_intdigest(token.encode())
    assert gid(token) == (digest & (2**64 - 1)).to_bytes(8, "little") + (digest >> 64).to_bytes(8, "little")


def test_type_hashes_match_the_published_ones():
    for msgtype, expected in KNOWN_HASHES.items():
        assert ros_msgs.type_hash(msgtype) == expected


def test_fleet_names_map_to_valid_ros_names():
    assert names.ros_name("exp2a-features") == "exp2a_features"
    assert names.ros_name("uav.1") == "uav_1"
    assert names.ros_name("a--b__c") == "a_b_c"
    assert names.ros_name("2nd") == "_2nd"
    assert names.topic_name("exp2a-features", "H1", "target_pose") == "/exp2a_features/H1/target_pose"
    seen = names.NameMap()
    assert seen.collision("a-b") is None and seen.collision("a-b") is None
    assert seen.collision("a_b") == "a-b" and seen.collision("a_b") is None


# -- golden CDR -----------------------------------------------------------------------------------------

COVARIANCE = np.diag([0.01, 0.02, 0.04, 0.001, 0.002, 0.003])
COVARIANCE[0, 1] = COVARIANCE[1, 0] = 0.005


def golden_estimate():
    """The estimate behind the golden file, with a covariance (the real field when protocol has it)."""
    fields = dict(sender="H1", seq=3, stamp_ns=STAMP_NS, target="pioneer", pose=(1.0, 2.0, 15.0, 0.1, -0.05, 1.0))
    if "covariance" in PoseEstimate.model_fields:
        return PoseEstimate(**fields, fitness=0.75, mismatch=0.1, converged=True, generations=17, seconds=0.4,
                            covariance=tuple(COVARIANCE.reshape(36)))
    return SimpleNamespace(**fields, covariance=tuple(COVARIANCE.reshape(36)))


def golden_cdr() -> bytes:
    pose = estimate_messages("exp2a-features", "H1", golden_estimate())[0]
    assert pose.topic == "/exp2a_features/H1/target_pose"
    return pose.cdr()


def test_pose_with_covariance_cdr_is_the_golden_file():
    data = golden_cdr()
    assert data == GOLDEN.read_bytes(), "CDR of PoseWithCovarianceStamped changed; see the module docstring"
    # and the layout by hand: encapsulation CDR_LE, Time, "map", Pose (8-aligned), 36 doubles
    assert data[:4] == b"\x00\x01\x00\x00"
    sec, nanosec, length = struct.unpack_from("<iII", data, 4)
    assert (sec * 10**9 + nanosec, length, data[16:20]) == (STAMP_NS, 4, b"map\x00")
    values = struct.unpack_from("<43d", data, 20)
    assert values[:3] == (1.0, 2.0, 15.0)
    q = values[3:7]
    assert math.isclose(sum(c * c for c in q), 1.0) and q[3] > 0
    assert np.array_equal(np.array(values[7:]).reshape(6, 6), COVARIANCE)
    assert len(data) == 20 + 43 * 8
    message = ros_msgs.deserialize(data, ros_msgs.POSE_WITH_COVARIANCE_STAMPED)
    expected_q = ros_msgs.quaternion_from_rpy(0.1, -0.05, 1.0)
    assert np.allclose([message.pose.pose.orientation.x, message.pose.pose.orientation.y,
                        message.pose.pose.orientation.z, message.pose.pose.orientation.w], expected_q)


def test_quaternion_follows_the_projects_euler_convention():
    from protocol.messages import quaternion_from_euler

    rng = np.random.default_rng(0)
    for roll, pitch, yaw in rng.uniform(-3, 3, (50, 3)):
        assert np.allclose(ros_msgs.quaternion_from_rpy(roll, pitch, yaw), quaternion_from_euler(roll, pitch, yaw))


def test_camera_rig_recomposes_the_camera_pose():
    rng = np.random.default_rng(1)
    for pose in rng.uniform(-2, 2, (20, 6)):
        position, r_world_base, r_base_camera = ros_msgs.camera_rig(tuple(pose))
        assert np.allclose(r_world_base @ r_base_camera, ros_msgs.matrix_from_rpy(*pose[3:]))
        assert np.allclose(r_world_base[:, 2], (0, 0, 1)) and np.allclose(position, pose[:3])


# -- a real fleet, mirrored -----------------------------------------------------------------------------

@pytest.fixture
def fleet():
    with fleet_with_router("ros2-test") as fleet:
        yield fleet


def test_a_real_fleet_is_received_by_an_rmw_zenoh_subscriber(fleet):
    mirror = fleet.start("ros2", "--fleet", fleet.fleet, "--json")
    ready = mirror.next_record(20, lambda r: r.get("event") == "ready")
    fleet_poses: dict[int, PoseEstimate] = {}

    def on_fleet_pose(sample: zenoh.Sample) -> None:
        _, message = decode_sample(str(sample.key_expr), sample.payload.to_bytes())
        fleet_poses[message.stamp_ns] = message

    pose_topic = "/ros2_test/uav_1/target_pose"
    with client_session(fleet.endpoint) as session, \
            session.declare_subscriber(f"evopose/{fleet.fleet}/uav-1/pose", on_fleet_pose), \
            Ros2Listener(session) as ros:
        assert ros.wait_for(lambda r: any(e.key == ready["node"] for e in r.entities(EntityKind.NODE)), 20)
        fleet.start("publish", "--fleet", fleet.fleet, "--vehicle", "uav-1", "--topic", "pose", "--rate", "20",
                    "--count", "400", "--wait", "10")
        fleet.start("publish", "--fleet", fleet.fleet, "--vehicle", "uav-1", "--topic", "features", "--rate",
                    "20", "--count", "400", "--wait", "10")
        wanted = {pose_topic, "/tf", "/ros2_test/uav_1/camera_info"}
        def stamp_ns(sample) -> int:
            return sample.message.header.stamp.sec * 10**9 + sample.message.header.stamp.nanosec

        # wait for 5 ROS poses whose fleet original this test's own subscriber has too: that subscriber is declared
        # just before the publishers start, so the first fleet poses may reach the mirror but not it
        assert ros.wait_for(lambda r: wanted <= {s.topic for s in r.samples()} and
                            sum(stamp_ns(s) in fleet_poses for s in r.samples(pose_topic)) >= 5, 60), (
            ros.errors, ros.topics())
        assert not ros.errors
        publishers = {e.topic: e for e in ros.entities(EntityKind.PUBLISHER)}
        samples = ros.samples(pose_topic)
        transforms = [t for s in ros.samples("/tf") for t in s.message.transforms]
        camera = ros.samples("/ros2_test/uav_1/camera_info")[0].message

    # the graph: the node's and each publisher's tokens, the namespace, type and hash
    node = parse_token(ready["node"])
    assert node.node == Node("evopose_mirror", "/ros2_test") and node.zid == ready["zid"]
    entity = publishers[pose_topic]
    assert (entity.node, entity.zid, entity.node_id) == (node.node, node.zid, node.node_id)
    assert entity.msgtype == ros_msgs.POSE_WITH_COVARIANCE_STAMPED and entity.qos == DEFAULT_QOS
    assert entity.type_hash == KNOWN_HASHES[ros_msgs.POSE_WITH_COVARIANCE_STAMPED]
    assert publishers["/tf"].qos == TF_QOS
    # every sample: the attachment (consecutive sequence numbers, the publisher's GID), the pose of the fleet's
    sequence = [s.attachment.sequence_number for s in samples]
    assert sequence == list(range(sequence[0], sequence[0] + len(sequence)))
    assert all(s.attachment.source_gid == entity.gid for s in samples)
    matched = 0
    for sample in samples:
        header = sample.message.header
        original = fleet_poses.get(stamp_ns(sample))
        if original is None:
            continue
        matched += 1
        pose = sample.message.pose.pose
        assert header.frame_id == "map"
        assert (pose.position.x, pose.position.y, pose.position.z) == original.pose[:3]
        assert np.allclose([pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w],
                           original.quaternion)
        assert np.array_equal(sample.message.pose.covariance,
                              np.asarray(getattr(original, "covariance", None) or np.zeros(36)))
    assert matched >= 5
    # /tf: map -> uav_1/base_link -> uav_1/camera_optical; the camera's intrinsics in its optical frame
    edges = {(t.header.frame_id, t.child_frame_id) for t in transforms}
    assert {("map", "uav_1/base_link"), ("uav_1/base_link", "uav_1/camera_optical"),
            ("map", "uav_1/target_estimate")} <= edges
    assert camera.header.frame_id == "uav_1/camera_optical" and camera.distortion_model == "plumb_bob"
    assert (camera.width, camera.height, camera.k[0], camera.k[2], camera.k[4]) == (640, 480, 800.0, 320.0, 800.0)


def test_scenario_run_with_ros2_mirrors_every_camera_vehicle_and_the_truth():
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    fleet = Fleet(port, "exp2a-features-H1-H2-0")
    try:
        run = fleet.start("scenario", "run", "exp2a-features", "--frames", "20", "--ros2", "--listen", endpoint,
                          "--json", connect=False)
        with zenoh.open(peer_config(endpoint)) as session, Ros2Listener(session) as ros:
            prefix = "/exp2a_features_H1_H2_0"
            wanted = {f"{prefix}/H1/target_pose", f"{prefix}/H2/target_pose", f"{prefix}/pioneer/true_pose"}
            transforms = {("map", "H1/base_link"), ("H1/base_link", "H1/camera_optical"), ("map", "H2/base_link"),
                          ("map", "pioneer/truth")}

            def frames(r) -> set[tuple[str, str]]:
                return {(t.header.frame_id, t.child_frame_id) for s in r.samples("/tf") for t in s.message.transforms}

            # a pose and its /tf are two messages of the mirror: either may come first, so wait for both
            assert ros.wait_for(lambda r: wanted <= {s.topic for s in r.samples()} and transforms <= frames(r), 120), \
                (ros.topics(), sorted(frames(ros)), ros.errors)
            assert not ros.errors
        result = run.next_record(120, lambda r: "runs" in r)
        assert result["runs"][0]["fleet"] == "exp2a-features-H1-H2-0"
    finally:
        fleet.close()


def rmw_zenohd_config(endpoint: str) -> zenoh.Config:
    """The router as ``ros2 run rmw_zenoh_cpp rmw_zenohd`` configures it (rmw_zenoh_cpp/config/
    DEFAULT_RMW_ZENOH_ROUTER_CONFIG.json5): router mode, multicast scouting off, gossip on (one hop, peers
    autoconnect), timestamps, and ``peers_failover_brokering: false`` (ros2/rmw_zenoh#341: it does not route
    between two peers, which it takes to be connected to each other); listening on ``endpoint`` instead of
    ``tcp/[::]:7447``. (Zenoh 1.9 and later ignore that key and warn; rmw_zenohd's own Zenoh read it.)"""
    config = zenoh.Config()
    config.insert_json5("mode", '"router"')
    config.insert_json5("listen/endpoints", f'["{endpoint}"]')
    config.insert_json5("scouting", '{multicast: {enabled: false}, gossip: {enabled: true, multihop: false, '
                                    'autoconnect: {router: [], peer: ["router", "peer"]}}}')
    config.insert_json5("timestamping", '{enabled: {router: true, peer: true, client: false}, '
                                        'drop_future_timestamp: false}')
    config.insert_json5("queries_default_timeout", "10000")
    config.insert_json5("routing", '{router: {peers_failover_brokering: false}, peer: {mode: "peer_to_peer"}}')
    return config


def test_the_mirror_as_a_client_of_a_router_configured_as_rmw_zenohd():
    """docs/ros2.md "Connecting ROS 2 nodes": behind rmw_zenohd the mirror runs as a Zenoh client of the router (a
    router always routes to and from its clients); a ROS 2 node there, a peer listening on loopback as rmw_zenoh
    nodes do, finds the mirror's publishers through their liveliness tokens and receives the fleet's poses."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    fleet = Fleet(port, "zenohd-test")  # every process it starts: --mode client --connect endpoint
    pose_topic = "/zenohd_test/uav_1/target_pose"
    try:
        with zenoh.open(rmw_zenohd_config(endpoint)):
            mirror = fleet.start("ros2", "--fleet", fleet.fleet, "--json")
            ready = mirror.next_record(20, lambda r: r.get("event") == "ready")
            with zenoh.open(peer_config(endpoint)) as session, Ros2Listener(session) as ros:
                assert ros.wait_for(lambda r: any(e.key == ready["node"] for e in r.entities(EntityKind.NODE)), 20)
                fleet.start("publish", "--fleet", fleet.fleet, "--vehicle", "uav-1", "--topic", "pose", "--rate",
                            "20", "--count", "400", "--wait", "10")
                assert ros.wait_for(lambda r: len(r.samples(pose_topic)) >= 5, 60), (ros.errors, ros.topics())
                assert not ros.errors
                publisher = {e.topic: e for e in ros.entities(EntityKind.PUBLISHER)}[pose_topic]
                samples = ros.samples(pose_topic)
        assert publisher.zid == ready["zid"] and publisher.qos == DEFAULT_QOS
        assert all(s.attachment.source_gid == publisher.gid for s in samples)
        assert all(s.message.header.frame_id == "map" for s in samples)
    finally:
        fleet.close()


def peer_config(endpoint: str) -> zenoh.Config:
    config = zenoh.Config()
    config.insert_json5("connect/endpoints", f'["{endpoint}"]')
    config.insert_json5("listen/endpoints", '["tcp/127.0.0.1:0"]')
    config.insert_json5("scouting/multicast/enabled", "false")
    # started before the fleet's first agent listens: retry often (Zenoh's default backs off to seconds)
    config.insert_json5("connect/retry", '{"period_init_ms": 100, "period_max_ms": 500, "period_increase_factor": 1.5}')
    return config


if __name__ == "__main__":
    GOLDEN.write_bytes(golden_cdr())
    print(f"wrote {GOLDEN} ({GOLDEN.stat().st_size} bytes)", file=sys.stderr)
