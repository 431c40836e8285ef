"""Service functions behind the fleet commands (router, meter, publish, listen); each returns plain data.

Each opens the process's single Zenoh session, runs until ``stop`` is set (SIGINT/SIGTERM, see
:mod:`agents.cli.signals`) or its duration/count is reached, and always closes what it declared.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from protocol import (SIZE_LIMITS, Attitude, CameraInfo, FeatureSet, Hint, ImageFrame, Payload, PoseEstimate,
                      Topic, check_name, encode)

from agents.transport.bus import FleetBus
from agents.tools.meter import Meter
from agents.transport.session import SessionOptions, open_session



# -- router ------------------------------------------------------------------------------------

def run_router(options: SessionOptions, stop: threading.Event, on_ready: Callable[[dict], None]) -> dict:
    """Run a Zenoh router (a session in mode ``router``) until ``stop``; returns its id and uptime."""
    session = open_session(SessionOptions(**{**options.__dict__, "mode": "router"}))
    started = time.monotonic()
    try:
        info = {"zid": str(session.zid()), "listen": list(options.listen)}
        on_ready(info)
        while not stop.wait(0.2):
            pass
        info["peers"] = len(session.info.peers_zid())
    finally:
        session.close()
    return {**info, "seconds": time.monotonic() - started}


# -- meter -------------------------------------------------------------------------------------

def run_meter(options: SessionOptions, stop: threading.Event, emit: Callable[[list[dict]], None], *,
              fleet: str | None = None, window: int = 100, duration: float | None = None,
              period_s: float = 1.0) -> dict:
    """Meter the fleet, calling ``emit`` with the per-key records every ``period_s``; returns the summary."""
    if fleet is not None:
        check_name(fleet, "fleet")
    session = open_session(options)
    try:
        meter = Meter(session, fleet, window)
        deadline = None if duration is None else time.monotonic() + duration
        try:
            next_report = time.monotonic() + period_s
            while not stop.is_set():
                timeout = next_report - time.monotonic()
                if deadline is not None:
                    timeout = min(timeout, deadline - time.monotonic())
                if stop.wait(max(timeout, 0)):
                    break
                if time.monotonic() >= next_report:
                    emit(meter.report())
                    next_report += period_s
                if deadline is not None and time.monotonic() >= deadline:
                    break
            time.sleep(0.05)  # last stats from agents still in flight
        finally:
            meter.close()
        return {"keys": meter.report(), "agents": meter.agents}
    finally:
        session.close()


# -- publisher (test and demo tool) ---------------------------------------------------------------

@dataclass(frozen=True)
class PublishSpec:
    """What ``evopose publish`` sends: ``count`` messages of ``topic`` at ``rate_hz`` (0: as fast as possible)."""

    topic: Topic
    rate_hz: float = 10.0
    count: int | None = None
    duration: float | None = None
    payload: str = "valid"  #: valid, garbage, oversized or truncated
    points: int = 30
    width: int = 640
    height: int = 480
    seed: int = 0


def sample_message(spec: PublishSpec, header: dict, rng: np.random.Generator) -> Payload:
    """A well-formed message of ``spec.topic``, random but plausible."""
    camera = CameraInfo(fx=800.0, fy=800.0, cx=spec.width / 2, cy=spec.height / 2, width=spec.width,
                        height=spec.height)
    pose = (rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(8, 20), *rng.uniform(-0.3, 0.3, 3))
    if spec.topic is Topic.HINT:
        return Hint(pose=pose)
    if spec.topic is Topic.FEATURES:
        uv = rng.uniform((0, 0), (spec.width, spec.height), (spec.points, 2))
        return FeatureSet.from_array(uv, camera, **header)
    if spec.topic is Topic.IMAGE:
        image = rng.integers(0, 256, (spec.height, spec.width, 3), dtype=np.uint8)
        return ImageFrame.from_array(image, camera, **header)
    if spec.topic is Topic.ATTITUDE:
        return Attitude(**header, body=header["sender"], roll=pose[3], pitch=pose[4], yaw=pose[5],
                        sigma=(0.002, 0.002, 0.01))
    if spec.topic is Topic.POSE:
        return PoseEstimate(**header, pose=pose, fitness=0.5, mismatch=0.1, converged=True, generations=10,
                            seconds=0.1)
    raise ValueError(f"publish cannot make {spec.topic.value!r} messages; Stats are sent by agents themselves")


def bad_payload(spec: PublishSpec, valid: bytes, rng: np.random.Generator) -> bytes:
    """A payload the receivers must reject: random bytes, one byte over the limit, or the valid one truncated."""
    if spec.payload == "garbage":
        return bytes(rng.integers(0, 256, max(len(valid), 1), dtype=np.uint8)) + b"\xc1"
    if spec.payload == "oversized":
        return b"\x00" * (SIZE_LIMITS[spec.topic] + 1)
    return valid[: len(valid) // 2]


def run_publisher(options: SessionOptions, stop: threading.Event, fleet: str, vehicle: str,
                  spec: PublishSpec, *, wait_s: float = 0.0, stay: bool = False) -> dict:
    """Publish per ``spec`` as ``vehicle``; with ``stay``, keep the session (and presence) until ``stop``.

    With ``wait_s`` > 0, first wait up to that long for a subscriber of the topic; ``matched`` in the
    result says whether one came (None: not waited for). With BLOCK topics that subscriber then gets
    every message; others that subscribe later miss the first ones. ``stats_sent`` counts this
    vehicle's Stats messages, the final one (sent at close) included.
    """
    rng = np.random.default_rng(spec.seed)
    matched = None
    with FleetBus.open(options, fleet, vehicle, stats_period_s=1.0) as bus:
        if wait_s > 0:
            matched = bus.wait_for_subscribers(spec.topic, wait_s)
        sent, total_bytes, sizes = 0, 0, set()
        started = next_time = time.monotonic()
        while not stop.is_set() and (spec.count is None or sent < spec.count) and (
                spec.duration is None or time.monotonic() - started < spec.duration):
            message = sample_message(spec, bus.header(spec.topic), rng)
            payload = encode(message)
            if spec.payload != "valid":
                payload = bad_payload(spec, payload, rng)
            size = bus.put_raw(spec.topic, payload)
            sent, total_bytes = sent + 1, total_bytes + size
            sizes.add(size)
            if spec.rate_hz > 0:
                next_time += 1.0 / spec.rate_hz
                stop.wait(max(0.0, next_time - time.monotonic()))
        seconds = time.monotonic() - started
        while stay and not stop.wait(0.2):
            pass
    stats_sent = bus.counters.snapshot()["sent"].get(Topic.STATS.value, 0)  # after close: the final one too
    return {"vehicle": vehicle, "topic": spec.topic.value, "payload": spec.payload, "matched": matched, "sent": sent,
            "bytes": total_bytes, "size_min": min(sizes, default=0), "size_max": max(sizes, default=0),
            "seconds": seconds, "rate_hz": (sent - 1) / seconds if sent > 1 and seconds > 0 else 0.0,
            "stats_sent": stats_sent}


# -- listener (a receiving agent without the per-frame loop) --------------------------------------

def run_listener(options: SessionOptions, stop: threading.Event, fleet: str, vehicle: str,
                 topics: tuple[Topic, ...], *, duration: float | None = None, max_age_s: float | None = 1.0,
                 emit: Callable[[dict], None], period_s: float = 1.0) -> dict:
    """Receive ``topics`` from the team-mates as ``vehicle``; returns the counters (after close: complete).

    Emits ``ready`` once subscribed; ``join`` and ``leave`` of team-mates; ``data`` for the first
    message of a team-mate per topic since it (re)joined, i.e. when it is used (again); and the
    counters (``counters``) every ``period_s``.
    """
    started = time.monotonic()
    lock = threading.Lock()
    used: set[tuple[str, str]] = set()  # (vehicle, topic) received since the vehicle last joined; worker thread

    def say(record: dict) -> None:  # from the main and the bus's worker thread
        with lock:
            emit({**record, "t_s": time.monotonic() - started})

    def on_join(mate: str) -> None:
        used.difference_update({key for key in used if key[0] == mate})
        say({"event": "join", "vehicle": mate})

    def on_message(rx) -> None:
        if (rx.vehicle, rx.topic.value) not in used:
            used.add((rx.vehicle, rx.topic.value))
            say({"event": "data", "vehicle": rx.vehicle, "topic": rx.topic.value,
                 "teammates": sorted(bus.teammates())})

    with FleetBus.open(options, fleet, vehicle, max_age_s=max_age_s, stats_period_s=1.0, on_join=on_join,
                       on_leave=lambda mate: say({"event": "leave", "vehicle": mate})) as bus:
        for topic in topics:
            bus.subscribe(topic, on_message)
        say({"event": "ready", "vehicle": vehicle})
        next_counters = time.monotonic() + period_s
        while not stop.wait(0.1):
            for topic in topics:  # drain, as an agent loop would
                while bus.recv(topic, timeout=0) is not None:
                    pass
            if time.monotonic() >= next_counters:
                next_counters += period_s
                say({"event": "counters", "vehicle": vehicle, **bus.counters.snapshot()})
            if duration is not None and time.monotonic() - started >= duration:
                break
    # after close: what reached this process before it stopped is counted
    return {"event": "summary", "vehicle": vehicle, "teammates": sorted(bus.teammates()), **bus.counters.snapshot()}
