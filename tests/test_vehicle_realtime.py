"""The vehicle runtime in this process, on a real Zenoh session on a free loopback port: the camera rate while the
frame loop improves between frames, hints kept and counted, pairing by stamp and staleness with a team-mate the test
plays itself (docs/architecture.md, "A frame's path"). Waits are on the agents' own events and returns, not sleeps.
"""

from __future__ import annotations

import queue
import sys
import threading

import numpy as np

from agents.transport.session import SessionOptions
from agents.vehicle.agent import run_agent
from agents.vehicle.config import AgentConfig
from agents.vehicle.frames import FrameClock, SimulatedCamera
from agents.vehicle.team_views import camera_info
from protocol import FeatureSet, alive_key, encode, topic_key
from scenarios.world import load_scenario
from tests.fleet_procs import Proc, free_port, peer_session

FPS = 10.0


def _agent(vehicle: str, fleet: str, share: str, frames: int | None, options: SessionOptions, events: queue.Queue,
           stop: threading.Event, **extra) -> tuple[threading.Thread, dict]:
    config = AgentConfig(fleet=fleet, vehicle=vehicle, scenario="exp2", share=share, frames=frames, fps=FPS, **extra)
    out: dict = {}

    def run() -> None:
        out["summary"] = run_agent(options, config, stop, events.put)

    thread = threading.Thread(target=run, name=vehicle, daemon=True)
    thread.start()
    return thread, out


def _next(events: queue.Queue, predicate, timeout: float = 60.0) -> dict:
    while True:
        record = events.get(timeout=timeout)
        if predicate(record):
            return record


def test_two_vehicles_keep_the_camera_rate_while_hints_flow_between_frames():
    """Hint mode: both frame loops run generations until each tick and send their good bests as hints; no frame
    is late for it (the frame has priority), and each vehicle uses the other's hints. H1 runs in this process, its
    team-mate H2 as an agent process of its own: two vehicles in one interpreter would share one lock and starve each
    other's generations between frames, which no fleet does."""
    endpoint, stop = f"tcp/127.0.0.1:{free_port()}", threading.Event()
    events: queue.Queue = queue.Queue()
    frames = 20
    h2 = Proc([sys.executable, "-m", "agents.cli", "agent", "--fleet", "rt-hints", "--vehicle", "H2", "--scenario",
               "exp2", "--share", "hint", "--frames", str(frames), "--fps", f"{FPS:g}", "--wait-for", "H1",
               "--connect", endpoint, "--no-multicast", "--json"])
    try:
        h1 = _agent("H1", "rt-hints", "hint", frames, SessionOptions(listen=(endpoint,)), events, stop,
                    wait_for=("H2",))
        h1[0].join(120)
        assert not h1[0].is_alive()
        summaries = {"H1": h1[1]["summary"], "H2": h2.next_record(60, lambda r: r.get("event") == "summary")}
    finally:
        h2.kill()
    for vehicle, s in summaries.items():
        assert s["frames"] == s["estimates"] == frames, s
        assert s["late_frames"] <= 1, (vehicle, s["late_frames"])  # one tick of slack for the machine, no more
        assert s["hints_published"] > 10 * s["run_s"] and s["traffic"]["sent"]["hint"] == s["hints_published"]
        assert s["hints_used"] > 0 and s["good"] >= frames - 3


def test_pairing_is_by_stamp_and_a_silent_teammate_is_reported_stale_once_then_fresh():
    """A team-mate played by the test: present (its liveliness token), sending feature sets of H2's camera stamped
    on the fleet clock; H1 pairs them with its own frames of the same instant. Then it falls silent while still
    present: H1 says once that it went stale and stops waiting; when it sends again, H1 says it is fresh."""
    endpoint, stop = f"tcp/127.0.0.1:{free_port()}", threading.Event()
    events: queue.Queue = queue.Queue()
    thread, out = _agent("H1", "rt-pairs", "features", None, SessionOptions(listen=(endpoint,)), events, stop,
                         max_age_s=0.3)
    scenario = load_scenario("exp2")
    camera, clock = SimulatedCamera(scenario, "H2"), FrameClock(FPS)
    paired = threading.Event()
    try:
        _next(events, lambda r: r.get("event") == "ready")
        with peer_session(endpoint) as session:
            token = session.liveliness().declare_token(alive_key("rt-pairs", "H2"))
            publisher = session.declare_publisher(topic_key("rt-pairs", "H2", "features"))
            sending, seq = threading.Event(), [0]
            sending.set()

            def mate() -> None:  # one feature set per tick of the fleet clock while ``sending``
                n = None
                while not stop.is_set():
                    n = clock.wait_next(n, stop)
                    if n is None:
                        return
                    if sending.is_set():
                        frame = camera.acquire(n, clock.stamp_ns(n))
                        message = FeatureSet.from_array(frame.points, camera_info(frame.camera), sender="H2",
                                                        seq=seq[0], stamp_ns=frame.stamp_ns, labels=frame.labels)
                        publisher.put(encode(message))
                        seq[0] += 1

            player = threading.Thread(target=mate, daemon=True)
            player.start()
            record = _next(events, lambda r: r.get("event") == "frame" and r["views"] == ["H1", "H2"]
                           and r["views_of_this_instant"])
            paired.set()
            assert clock.index_of(record["stamp_ns"]) == record["frame"]
            sending.clear()
            stale = _next(events, lambda r: r.get("event") in ("stale", "fresh"))
            assert stale["event"] == "stale" and stale["vehicle"] == "H2" and stale["age_s"] > 0.3
            alone = _next(events, lambda r: r.get("event") == "frame")
            assert alone["views"] == ["H1"]  # not waited for
            sending.set()
            again = _next(events, lambda r: r.get("event") in ("stale", "fresh"))
            assert again == {"event": "fresh", "vehicle": "H2", "by": "H1"}
            stop.set()
            player.join(5)
            publisher.undeclare()
            token.undeclare()
    finally:
        stop.set()
        thread.join(30)
    s = out["summary"]
    assert paired.is_set() and s["stale_events"] == 1 and s["multi_view_frames"] >= 1
    assert np.isfinite(s["error_position"])


def test_a_frame_whose_estimate_raises_is_reported_and_the_vehicle_goes_on(monkeypatch):
    """A bug in one frame's estimate (injected: the step raises on the third frame) does not ground the vehicle: the
    frame is reported (``frame-error``, counted in the summary), the estimator starts afresh, and the later frames are
    estimated and good again."""
    import agents.vehicle.roles as roles

    real_step, calls, raised_at = roles.step, [0], []

    def faulty(state, inputs):
        calls[0] += 1
        if calls[0] == 3:
            raised_at.append(inputs.index)
            raise FloatingPointError("injected")
        return real_step(state, inputs)

    monkeypatch.setattr(roles, "step", faulty)
    events: queue.Queue = queue.Queue()
    thread, out = _agent("H1", "rt-fault", "none", 8, SessionOptions(listen=(f"tcp/127.0.0.1:{free_port()}",)),
                         events, threading.Event())
    thread.join(120)
    assert not thread.is_alive()
    records = []
    while not events.empty():
        records.append(events.get())
    errors = [r for r in records if r.get("event") == "frame-error"]
    assert errors == [{"event": "frame-error", "vehicle": "H1", "frame": raised_at[0],
                       "error": "FloatingPointError: injected"}]
    s = out["summary"]
    assert s["frame_errors"] == 1 and s["frames"] == 8 and s["estimates"] == 7
    frames = [r for r in records if r.get("event") == "frame"]
    assert frames[-1]["frame"] > raised_at[0] and frames[-1]["good"]
