"""The wire format: keys, codec round trips, size limits, malformed inputs, the 24-byte hint, golden files."""

from __future__ import annotations

import re
from pathlib import Path

import msgpack
import numpy as np
import pytest

import protocol as p
from tests.golden.make import CAMERA, STAMP_NS, golden_messages, golden_path

ROOT = Path(__file__).resolve().parents[1]
HEADER = dict(sender="uav1", seq=1, stamp_ns=STAMP_NS)


# -- keys ---------------------------------------------------------------------------------------

def test_keys_build_and_parse():
    key = p.topic_key("alpha", "uav-1", "hint")
    assert key == "evopose/alpha/uav-1/hint"
    assert p.parse_key(key) == p.TopicKey("alpha", "uav-1", p.Topic.HINT)
    assert str(p.parse_key(key)) == key
    assert p.alive_key("alpha", "uav-1") == "evopose/alpha/@alive/uav-1"
    assert p.parse_alive_key("evopose/alpha/@alive/uav-1") == ("alpha", "uav-1")
    assert p.fleet_selector("alpha") == "evopose/alpha/*/*"
    assert p.fleet_selector() == "evopose/*/*/*"
    assert p.topic_selector("alpha", p.Topic.FEATURES) == "evopose/alpha/*/features"
    assert p.alive_selector("alpha") == "evopose/alpha/@alive/*"


@pytest.mark.parametrize("name", ["", "a/b", "a*", "$x", "a#", "q?", "@alive", "sp ace", "-x", ".x", "x" * 65, "é"])
def test_bad_names_are_rejected(name):
    with pytest.raises(p.InvalidName, match="vehicle"):
        p.topic_key("fleet", name, "hint")


@pytest.mark.parametrize("key", ["evopose/f/v", "evopose/f/v/hint/x", "other/f/v/hint", "evopose/f/v/video",
                                 "evopose/f/*/hint", "evopose/f/@alive/v"])
def test_parse_rejects_non_data_keys(key):
    with pytest.raises(p.InvalidName):
        p.parse_key(key)


# -- round trips and the hint ------------------------------------------------------------------

def test_every_message_round_trips():
    for name, message in golden_messages().items():
        assert p.decode(message.TOPIC, p.encode(message)) == message, name


def test_hint_is_exactly_24_little_endian_float32():
    pose = np.array([1.5, -2.0, 10.25, 0.125, -0.25, 3.0])
    payload = p.encode_hint(pose)
    assert len(payload) == p.HINT_SIZE == 24
    assert payload == np.array(pose, dtype="<f4").tobytes()
    assert payload[:4] == bytes.fromhex("0000c03f")  # 1.5
    np.testing.assert_array_equal(p.decode_hint(payload), pose)
    assert p.encode(p.Hint(pose=tuple(pose))) == payload


@pytest.mark.parametrize("payload, error", [(b"\x00" * 23, p.MalformedPayload), (b"", p.MalformedPayload),
                                            (b"\x00" * 25, p.OversizedPayload),
                                            (np.array([0, 0, np.nan, 0, 0, 0], "<f4").tobytes(), p.InvalidMessage),
                                            (np.array([np.inf, 0, 0, 0, 0, 0], "<f4").tobytes(), p.InvalidMessage)])
def test_bad_hints(payload, error):
    with pytest.raises(error):
        p.decode("hint", payload)


def test_hint_encoder_rejects_wrong_shape_and_float32_overflow():
    with pytest.raises(p.InvalidMessage, match="6 values"):
        p.encode_hint([1, 2, 3])
    with pytest.raises(p.InvalidMessage, match="finite"):
        p.encode_hint([1e39, 0, 0, 0, 0, 0])


def test_feature_points_pack_as_float32_pairs():
    uv = np.random.default_rng(0).uniform(0, 640, (30, 2))
    fs = p.FeatureSet.from_array(uv, CAMERA, **HEADER)
    assert len(fs.points) == 30 * 8
    np.testing.assert_array_equal(fs.points_uv, uv.astype(np.float32))
    assert 300 < len(p.encode(fs)) < 800  # "a few hundred bytes"


def test_raw_image_round_trips_as_array():
    image = np.random.default_rng(1).integers(0, 255, (3, 4, 3), dtype=np.uint8)
    frame = p.ImageFrame.from_array(image, CAMERA, **HEADER)
    np.testing.assert_array_equal(p.decode("image", p.encode(frame)).to_array(), image)


def test_pose_carries_a_unit_quaternion_matching_scipy_convention():
    pose = golden_messages()["pose"]
    q = np.array(pose.quaternion)
    assert np.isclose(np.linalg.norm(q), 1) and q[3] >= 0
    from scipy.spatial.transform import Rotation
    expected = Rotation.from_euler("xyz", pose.pose[3:]).as_quat()
    assert np.allclose(q, expected * np.sign(expected[3]))


# -- malformed and oversized payloads -> precise errors ----------------------------------------

def _doc(name: str) -> dict:
    return msgpack.unpackb(golden_path(name).read_bytes())


def _pack(doc: dict) -> bytes:
    return msgpack.packb(doc, use_bin_type=True)


def test_oversized_is_rejected_before_decoding():
    for topic in p.Topic:
        limit = p.size_limit(topic)
        with pytest.raises(p.OversizedPayload, match=f"{limit}-byte limit") as err:
            p.decode(topic, b"\xc1" * (limit + 1))  # would be a FormatError if it were parsed
        assert err.value.reason == "oversized" and err.value.size == limit + 1


def test_encoder_refuses_what_receivers_would_reject():
    big = p.FeatureSet(**HEADER, camera=CAMERA, points=b"\x00" * 8 * p.MAX_FEATURE_POINTS)
    p.encode(big)  # the limit leaves room for a full set
    with pytest.raises(Exception, match="16385 points exceed"):
        p.FeatureSet(**HEADER, camera=CAMERA, points=b"\x00" * 8 * (p.MAX_FEATURE_POINTS + 1))


@pytest.mark.parametrize("payload, match", [
    (b"\xc1", "not valid msgpack"),
    (b"\x93\x01\x02\x03", "expected a msgpack map, got an array"),
    (b"\x2a", "got an integer"),
    (golden_path("stats").read_bytes()[:-5], "not valid msgpack"),
    (golden_path("stats").read_bytes() + b"\x00", "trailing bytes"),
    (b"\xd9\xff" + b"a" * 255, "got a string"),
    (b"\x81\xd9\xff" + b"a" * 255 + b"\x01", "missing field 'version'"),  # a map, but no message
    (b"\x81\xda\x01\x01" + b"a" * 257 + b"\x01", "not valid msgpack"),  # string over MAX_STR_LEN
    (b"\xdc\x00\x80" + b"\x00" * 128, "not valid msgpack"),  # array over MAX_ARRAY_LEN
    (b"\xd4\x01\x00", "not valid msgpack"),  # ext types are not allowed
])
def test_malformed_stats(payload, match):
    with pytest.raises(p.ProtocolError, match=match) as err:
        p.decode("stats", payload)
    assert err.value.reason in {"malformed", "invalid"}


@pytest.mark.parametrize("name, change, error, match", [
    ("features", lambda d: d.pop("camera"), p.InvalidMessage, "field 'camera': Field required"),
    ("features", lambda d: d["camera"].update(fx=-1.0), p.InvalidMessage, "field 'camera.fx'"),
    ("features", lambda d: d.update(points=b"\x00" * 12), p.InvalidMessage, "multiple of 8"),
    ("features", lambda d: d.update(points=np.array([np.nan, 1], "<f4").tobytes()), p.InvalidMessage, "finite"),
    ("features", lambda d: d.update(points="text"), p.InvalidMessage, "field 'points'"),
    ("features", lambda d: d.update(seq=-1), p.InvalidMessage, "field 'seq'"),
    ("features", lambda d: d.update(seq=7.0), p.InvalidMessage, "field 'seq'"),
    ("features", lambda d: d.update(sender="a/b"), p.InvalidMessage, "field 'sender'"),
    ("features", lambda d: d.update(version=1), p.SchemaMismatch, "schema version 1"),
    ("features", lambda d: d.update(version="2"), p.SchemaMismatch, "schema version '2'"),
    ("features", lambda d: d.pop("version"), p.InvalidMessage, "missing field 'version'"),
    ("image_raw", lambda d: d.update(data=d["data"][:-1]), p.InvalidMessage, "needs 36 bytes"),
    ("image_raw", lambda d: d.update(width=5), p.InvalidMessage, "camera is 4x3"),
    ("image_raw", lambda d: d.update(encoding="bmp"), p.InvalidMessage, "field 'encoding'"),
    ("image_png", lambda d: d.update(data=b"GIF89a"), p.InvalidMessage, "PNG signature"),
    ("image_png", lambda d: d.update(encoding="jpeg"), p.InvalidMessage, "JPEG marker"),
    ("attitude", lambda d: d.update(sigma=(-1.0, 0.0, 0.0)), p.InvalidMessage, "field 'sigma.0'"),
    ("attitude", lambda d: d.update(roll=float("nan")), p.InvalidMessage, "finite"),
    ("pose", lambda d: d.update(mismatch=1.5), p.InvalidMessage, "field 'mismatch'"),
    ("pose", lambda d: d.update(pose=(1.0, 2.0)), p.InvalidMessage, "field 'pose."),
    ("pose", lambda d: d.update(converged=1), p.InvalidMessage, "field 'converged'"),
    ("stats", lambda d: d["sent"].update(video=1), p.InvalidMessage, "unknown topic names"),
])
def test_invalid_fields_are_named(name, change, error, match):
    doc = _doc(name)
    change(doc)
    with pytest.raises(error, match=re.escape(match)):
        p.decode(golden_messages()[name].TOPIC, _pack(doc))


def test_unknown_fields_are_ignored_for_forward_compatibility():
    doc = _doc("attitude")
    doc["added_in_a_later_minor_revision"] = [1, 2]
    assert p.decode("attitude", _pack(doc)) == golden_messages()["attitude"]


def test_error_hierarchy_and_reasons():
    for cls, reason in [(p.OversizedPayload, "oversized"), (p.MalformedPayload, "malformed"),
                        (p.SchemaMismatch, "schema"), (p.InvalidMessage, "invalid"), (p.InvalidName, "bad_key")]:
        assert issubclass(cls, p.ProtocolError) and cls.reason == reason


def test_protocol_imports_no_zenoh():
    import subprocess
    import sys
    code = "import sys, protocol; assert not any(m.split('.')[0] in ('zenoh', 'agents', 'evopose') for m in sys.modules)"
    subprocess.run([sys.executable, "-c", code], cwd=ROOT, check=True)


def test_decode_sample_checks_the_sender_against_the_key():
    payload = golden_path("features").read_bytes()
    key, message = p.decode_sample("evopose/f/uav1/features", payload)
    assert key.vehicle == "uav1" and message == golden_messages()["features"]
    with pytest.raises(p.InvalidMessage, match="differs from the key"):
        p.decode_sample("evopose/f/uav2/features", payload)
    with pytest.raises(p.InvalidName):
        p.decode_sample("evopose/f/uav1/video", payload)
    assert p.decode_sample("evopose/f/anyone/hint", golden_path("hint").read_bytes())[0].vehicle == "anyone"


def test_feature_labels_round_trip_and_must_be_one_per_point():
    points = np.array([[1.0, 2.0], [3.0, 4.0]])
    message = p.FeatureSet.from_array(points, CAMERA, sender="uav1", seq=1, stamp_ns=STAMP_NS, labels=np.array([2, 0]))
    decoded = p.decode("features", p.encode(message))
    np.testing.assert_array_equal(decoded.labels_array, [2, 0])
    assert p.FeatureSet.from_array(points, CAMERA, sender="uav1", seq=1, stamp_ns=STAMP_NS).labels_array is None
    wire = msgpack.unpackb(p.encode(message), raw=False)
    wire["labels"] = b"\x01"  # one label for two points
    with pytest.raises(p.ProtocolError, match="labels: 1 bytes for 2 points"):
        p.decode("features", msgpack.packb(wire, use_bin_type=True))
