"""`evopose view` (docs/ros2.md, "Live view"): a real fleet, the foxglove-sdk WebSocket server behind the view's relay,
and clients that subscribe to every advertised channel and receive them all: one with the `websockets` package
offering both subprotocols, and the official `@foxglove/ws-protocol` client from npm offering only its default,
foxglove.websocket.v1, which decodes a message of every channel with the channel's own schema (skipped, with the
reason, without node and npm). Also the shipped layout and the pure drawing helpers."""

from __future__ import annotations

import asyncio
import hashlib
import json
import math
import os
import shutil
import struct
import subprocess
import tempfile
import time
import zlib
from pathlib import Path

import numpy as np
import pytest
import websockets

from agents.bridges.view_scene import blank_png, frustum_lines, pose_errors, project
from protocol.messages import CameraInfo
from tests.fleet_procs import ROOT, Fleet, Proc, free_port

UNKNOWN_CHANNEL = "Unknown channel ID: "
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
EXPECTED = {"/tf", "/scene", "/metrics", "/uav_1/camera_calibration", "/uav_1/image", "/uav_1/features"}


def test_projection_frustum_errors_and_canvas():
    camera = CameraInfo(fx=800.0, fy=800.0, cx=320.0, cy=240.0, width=640, height=480,
                        world_from_camera=(0.0, 0.0, 10.0, math.pi, 0.0, 0.0))  # looking straight down
    uv = project(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]), (0.0, 0.0, 0.0, 0.0, 0.0, 0.0), camera)
    assert np.allclose(uv, [[320.0, 240.0], [400.0, 240.0]])
    lines = frustum_lines(camera, 2.0)
    assert lines.shape == (16, 3) and np.allclose(lines[1], (-0.8, -0.6, 2.0))
    position, rotation = pose_errors((1.0, 0.0, 0.0, 0.0, 0.0, 0.1), (0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    assert math.isclose(position, 1.0) and math.isclose(rotation, math.degrees(0.1))
    png = blank_png(4, 3)
    assert png.startswith(b"\x89PNG\r\n\x1a\n") and struct.unpack(">II", png[16:24]) == (4, 3)
    idat = png[png.index(b"IDAT") + 4:png.index(b"IEND") - 8]
    assert zlib.decompress(idat) == (b"\x00" + bytes([48]) * 4) * 3


async def receive_every_channel(url: str, wanted: set[str], timeout: float,
                                until=lambda payloads: True) -> tuple[dict, dict]:
    """Subscribe to every channel as it is advertised; return (channels by topic, payloads by topic) once every
    wanted topic has sent something and ``until(payloads)`` holds, or at the timeout."""
    channels, payloads, subscriptions = {}, {}, {}
    deadline = time.monotonic() + timeout
    # foxglove-sdk 0.30 accepts only "foxglove.sdk.v1", the renamed foxglove.websocket.v1 (same messages); a client
    # offers both, as the Foxglove app does
    async with websockets.connect(url, subprotocols=SUBPROTOCOLS, max_size=None) as ws:
        assert ws.subprotocol in SUBPROTOCOLS
        while not (wanted <= set(payloads) and until(payloads)) and time.monotonic() < deadline:
            try:
                frame = await asyncio.wait_for(ws.recv(), max(0.01, deadline - time.monotonic()))
            except asyncio.TimeoutError:
                break
            if isinstance(frame, str):
                message = json.loads(frame)
                if message["op"] == "advertise":
                    new = []
                    for channel in message["channels"]:
                        channels[channel["topic"]] = channel
                        subscriptions[len(subscriptions) + 1] = channel["topic"]
                        new.append({"id": len(subscriptions), "channelId": channel["id"]})
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
                elif message["op"] == "status" and message["message"].startswith(UNKNOWN_CHANNEL):
                    # foxglove-sdk 0.30 advertises a new channel a moment before it accepts subscriptions to it:
                    # subscribe again, with a new id, as a client would
                    channel_id = int(message["message"][len(UNKNOWN_CHANNEL):])
                    topic = next(t for t, c in channels.items() if c["id"] == channel_id)
                    subscriptions[len(subscriptions) + 1] = topic
                    await asyncio.sleep(0.05)
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                        {"id": len(subscriptions), "channelId": channel_id}]}))
            elif frame[0] == 0x01:  # Message Data: opcode, uint32 subscription id, uint64 timestamp, payload
                subscription, _ = struct.unpack_from("<IQ", frame, 1)
                payloads.setdefault(subscriptions[subscription], []).append(bytes(frame[13:]))
    return channels, payloads


@pytest.fixture
def fleet():
    port = free_port()
    fleet = Fleet(port, "view-test")
    router = fleet.start("router", "--listen", fleet.endpoint, "--json", "--no-multicast", connect=False)
    router.next_record(10, lambda r: r.get("event") == "ready")
    yield fleet
    fleet.close()


@pytest.mark.untimed("waits for every channel's first messages")
def test_a_websocket_client_receives_every_channel_of_a_live_fleet(fleet):
    view = fleet.start("view", "--fleet", fleet.fleet, "--port", "0", "--json")
    ready = view.next_record(60, lambda r: r.get("event") == "ready")
    for vehicle, topic in (("uav-1", "pose"), ("uav-1", "features"), ("target", "pose")):
        fleet.start("publish", "--fleet", fleet.fleet, "--vehicle", vehicle, "--topic", topic, "--rate", "20",
                    "--count", "1200", "--wait", "10")
    channels, payloads = asyncio.run(receive_every_channel(ready["url"], EXPECTED, 90))
    assert EXPECTED <= set(payloads), (sorted(channels), sorted(payloads))
    assert channels["/scene"]["schemaName"] == "foxglove.SceneUpdate"
    assert channels["/uav_1/features"]["schemaName"] == "foxglove.ImageAnnotations"
    assert channels["/metrics"]["encoding"] == "json"
    metrics = [json.loads(p) for p in payloads["/metrics"]]
    assert all(m["vehicle"] == "uav_1" and 0 <= m["mismatch"] <= 1 for m in metrics)


# -- what Lichtblick's and Foxglove's parsers accept ----------------------------------------------------------

JS_SAFE_INTEGER = 2**53 - 1


def check_viewer_schema(schema: dict, where: str = "") -> None:
    """A JSON schema every viewer's parser reads: one plain type per field (Lichtblick: "Unsupported type
    [...]" for a list), no integer that can exceed 2^53 (JavaScript numbers round it), times as ``{sec, nsec}``."""
    kind = schema.get("type")
    assert isinstance(kind, str), f"{where or 'schema'}: type {kind!r} is not one plain type"
    assert not ({"anyOf", "oneOf", "allOf"} & set(schema)), f"{where}: a union ({sorted(schema)})"
    if kind == "integer":
        assert schema.get("maximum", math.inf) <= JS_SAFE_INTEGER, f"{where}: an integer with no maximum <= 2^53"
        assert schema.get("minimum", -math.inf) >= -JS_SAFE_INTEGER, f"{where}: an integer with no minimum"
    for name, field in schema.get("properties", {}).items():
        check_viewer_schema(field, f"{where}.{name}")
    if "items" in schema:
        check_viewer_schema(schema["items"], f"{where}[]")


@pytest.mark.untimed("waits for every channel's first messages")
def test_every_advertised_schema_parses_in_the_viewers_and_every_message_validates(fleet):
    """Every channel `evopose view` advertises for a live fleet (pose with and without a truth, features): the JSON
    ones have schemas :func:`check_viewer_schema` accepts and every message sent on them validates against the
    advertised schema (jsonschema); the others are Foxglove's own protobuf schemas. /metrics' time is Foxglove's
    ``{sec, nsec}``; its errors appear once the truth is known, and are numbers."""
    import jsonschema

    view = fleet.start("view", "--fleet", fleet.fleet, "--port", "0", "--json")
    ready = view.next_record(60, lambda r: r.get("event") == "ready")
    fleet.start("publish", "--fleet", fleet.fleet, "--vehicle", "uav-1", "--topic", "pose", "--rate", "20",
                "--count", "1200", "--wait", "10")
    fleet.start("publish", "--fleet", fleet.fleet, "--vehicle", "uav-1", "--topic", "features", "--rate", "20",
                "--count", "1200", "--wait", "10")
    channels, before = asyncio.run(receive_every_channel(ready["url"], EXPECTED, 90))  # no truth yet
    assert EXPECTED <= set(before), (sorted(channels), sorted(before))
    fleet.start("publish", "--fleet", fleet.fleet, "--vehicle", "target", "--topic", "pose", "--rate", "20",
                "--count", "1200", "--wait", "10")
    channels, after = asyncio.run(receive_every_channel(  # until an estimate is measured against the truth
        ready["url"], EXPECTED, 30, until=lambda got: any(json.loads(p)["has_truth"] for p in got.get("/metrics", []))))
    payloads = {topic: before.get(topic, []) + after.get(topic, []) for topic in channels}
    for topic, channel in channels.items():
        if channel["schemaEncoding"] == "jsonschema":
            schema = json.loads(channel["schema"])
            check_viewer_schema(schema, topic)
            jsonschema.Draft202012Validator.check_schema(schema)
            for payload in payloads.get(topic, []):
                jsonschema.validate(json.loads(payload), schema)
        else:
            assert channel["schemaEncoding"] == "protobuf" and channel["schemaName"].startswith("foxglove."), channel
    metrics = [json.loads(p) for p in payloads["/metrics"]]
    assert {m["has_truth"] for m in metrics} == {False, True}, "estimates with and without a truth"
    for m in metrics:
        assert set(m["timestamp"]) == {"sec", "nsec"} and m["timestamp"]["sec"] > 1_600_000_000
        assert ("error_position_m" in m) == ("error_rotation_deg" in m) == m["has_truth"], m


def test_a_schema_with_a_union_or_a_big_integer_is_refused():
    """The check itself: what Lichtblick refused (a list type) and a nanosecond stamp fail it."""
    from agents.bridges.view import METRICS_SCHEMA

    check_viewer_schema(METRICS_SCHEMA)
    with pytest.raises(AssertionError, match="plain type"):
        check_viewer_schema({"type": "object", "properties": {"confident": {"type": ["boolean", "null"]}}})
    with pytest.raises(AssertionError, match="2\\^53"):
        check_viewer_schema({"type": "object", "properties": {"stamp_ns": {"type": "integer"}}})


def test_tf_and_scene_stay_within_the_viewers_rates(fleet):
    """Three senders at 20 Hz each (a vehicle's pose and features, the truth: 60 /tf and 60 /scene samples a
    second before coalescing): /tf and /scene arrive at most VIEW_RATE_HZ a second, and still carry every frame."""
    from agents.bridges.view import VIEW_RATE_HZ

    view = fleet.start("view", "--fleet", fleet.fleet, "--port", "0", "--json")
    ready = view.next_record(60, lambda r: r.get("event") == "ready")
    for vehicle, topic in (("uav-1", "pose"), ("uav-1", "features"), ("target", "pose")):
        fleet.start("publish", "--fleet", fleet.fleet, "--vehicle", vehicle, "--topic", topic, "--rate", "20",
                    "--count", "1200", "--wait", "10")
    asyncio.run(receive_every_channel(ready["url"], EXPECTED, 90))  # everything flows
    window = 4.0
    channels, payloads = asyncio.run(receive_every_channel(ready["url"], EXPECTED | {"never"}, window))
    for topic in ("/tf", "/scene"):
        rate = len(payloads[topic]) / window
        assert rate <= VIEW_RATE_HZ * 1.15 + 1, (topic, rate)
        assert rate >= 10, (topic, rate)  # coalesced, not starved
    assert len(payloads["/metrics"]) / window <= 30


# -- the official client, and what Lichtblick reads -------------------------------------------------------------

NODE_DIR = ROOT / "tests" / "node"
LAYOUT = ROOT / "docs" / "foxglove-layout.json"


def ws_protocol_client() -> Path:
    """A directory with tests/node's client and its pinned npm packages (``npm ci``, once per lock file, in the
    temporary directory); skips the test, saying why, without node and npm or when npm cannot install them."""
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None or npm is None:
        pytest.skip("node and npm not found (Debian: apt-get install nodejs npm): the official @foxglove/ws-protocol "
                    "client cannot run")
    lock = (NODE_DIR / "package-lock.json").read_bytes()
    home = Path(os.environ.get("EVOPOSE_NODE_CACHE", tempfile.gettempdir())) / (
        "evopose-ws-protocol-" + hashlib.sha256(lock).hexdigest()[:12])
    if not (home / "node_modules" / "@foxglove" / "ws-protocol" / "package.json").is_file():
        home.mkdir(parents=True, exist_ok=True)
        for name in ("package.json", "package-lock.json"):
            shutil.copy(NODE_DIR / name, home / name)
        try:
            done = subprocess.run([npm, "ci", "--no-audit", "--no-fund", "--ignore-scripts"], cwd=home,
                                  capture_output=True, text=True, timeout=300)
        except subprocess.TimeoutExpired:
            pytest.skip("npm ci of @foxglove/ws-protocol took over 300 s (no registry?)")
        if done.returncode != 0:
            last = (done.stderr.strip().splitlines() or ["?"])[-1]
            pytest.skip(f"npm could not install @foxglove/ws-protocol: {last}")
    shutil.copy(NODE_DIR / "ws_protocol_client.cjs", home / "ws_protocol_client.cjs")
    return home


@pytest.mark.untimed("waits for every channel's first messages")
def test_the_official_ws_protocol_client_decodes_every_channel_with_its_default_subprotocol(fleet):
    """@foxglove/ws-protocol's FoxgloveClient over `ws`, offering only foxglove.websocket.v1 (as Lichtblick does):
    the relay accepts it, and it decodes a message of every channel (protobuf from the advertised descriptors,
    JSON for /metrics) into what was sent."""
    home = ws_protocol_client()
    view = fleet.start("view", "--fleet", fleet.fleet, "--port", "0", "--json")
    ready = view.next_record(60, lambda r: r.get("event") == "ready")
    for vehicle, topic in (("uav-1", "pose"), ("uav-1", "features"), ("target", "pose")):
        fleet.start("publish", "--fleet", fleet.fleet, "--vehicle", vehicle, "--topic", topic, "--rate", "20",
                    "--count", "1200", "--wait", "10")
    client = Proc(["node", str(home / "ws_protocol_client.cjs"), ready["url"], ",".join(sorted(EXPECTED)), "90"])
    fleet.procs.append(client)
    assert client.wait(120) == 0, (client.all_records()[-3:], client.stderr_now()[-2000:])
    records = client.all_records()
    assert records[0] == {"event": "open", "subprotocol": "foxglove.websocket.v1"}
    decoded = {r["topic"]: r for r in records if r["event"] == "decoded"}
    assert EXPECTED <= set(decoded)
    assert {t: decoded[t]["schemaName"] for t in ("/tf", "/scene", "/uav_1/features", "/uav_1/image")} == {
        "/tf": "foxglove.FrameTransforms", "/scene": "foxglove.SceneUpdate",
        "/uav_1/features": "foxglove.ImageAnnotations", "/uav_1/image": "foxglove.CompressedImage"}
    assert decoded["/metrics"]["schemaName"] == "evopose.Metrics" and decoded["/metrics"]["encoding"] == "json"
    metrics = decoded["/metrics"]["message"]
    assert metrics["vehicle"] == "uav_1" and 0 <= metrics["mismatch"] <= 1
    frames = {t["child_frame_id"]: t["parent_frame_id"] for t in decoded["/tf"]["message"]["transforms"]}
    assert set(frames.values()) <= {"map", "uav_1/base_link"} and frames
    calibration = decoded["/uav_1/camera_calibration"]["message"]
    assert (calibration["frame_id"], calibration["width"], calibration["height"]) == ("uav_1/camera_optical", 640, 480)
    assert decoded["/uav_1/image"]["message"]["format"] == "png"
    assert decoded["/scene"]["message"]["entities"][0]["frame_id"] in {"uav_1/target_estimate", "target/truth",
                                                                      "uav_1/camera_optical"}


def test_the_shipped_layout_names_its_panels_and_plots_only_what_the_view_sends():
    """docs/foxglove-layout.json: every panel's title in the keys Foxglove (``foxglovePanelTitle``) and Lichtblick
    (``lichtblickPanelTitle``) read, no ``title`` that neither does; every plotted /metrics field in the schema."""
    from agents.bridges.view import METRICS_SCHEMA, METRICS_SCHEMA_NAME

    layout = json.loads(LAYOUT.read_text(encoding="utf-8"))
    assert METRICS_SCHEMA["title"] == METRICS_SCHEMA_NAME
    for panel, config in layout["configById"].items():
        assert "title" not in config, panel
        assert config["foxglovePanelTitle"] == config["lichtblickPanelTitle"] and config["foxglovePanelTitle"], panel
        for path in config.get("paths", []):
            topic, _, field = path["value"].partition("}.")
            assert topic.startswith("/metrics{") and field in METRICS_SCHEMA["properties"], path
