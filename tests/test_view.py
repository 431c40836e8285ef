"""`evopose view` (docs/ros2.md, "Live view"): a real fleet, the foxglove-sdk WebSocket server, and a client speaking
foxglove.websocket.v1 (the `websockets` package; the SDK names it foxglove.sdk.v1) that subscribes to every advertised
channel and receives them all. Also the pure drawing helpers."""

from __future__ import annotations

import asyncio
import json
import math
import struct
import time
import zlib

import numpy as np
import pytest
import websockets

from agents.bridges.view_scene import blank_png, frustum_lines, pose_errors, project
from protocol.messages import CameraInfo
from tests.fleet_procs import Fleet, free_port

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


async def receive_every_channel(url: str, wanted: set[str], timeout: float) -> tuple[dict, dict]:
    """Subscribe to every channel as it is advertised; return (channels by topic, payloads by topic) once every
    wanted topic has sent something, or at the timeout."""
    channels, payloads, subscriptions = {}, {}, {}
    deadline = time.monotonic() + timeout
    # foxglove-sdk 0.30 accepts only "foxglove.sdk.v1", the renamed foxglove.websocket.v1 (same messages); a client
    # offers both, as the Foxglove app does
    async with websockets.connect(url, subprotocols=SUBPROTOCOLS, max_size=None) as ws:
        assert ws.subprotocol in SUBPROTOCOLS
        while not wanted <= set(payloads) and time.monotonic() < deadline:
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
