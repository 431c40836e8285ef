"""The fleet over real Zenoh: separate processes on loopback (multicast scouting off) around one
`evopose router`: the meter's numbers, fault tolerance, presence, clean shutdown, hint throughput."""

from __future__ import annotations

import json
import signal
import textwrap
import time

import pytest

from agents.cli.main import main
from tests.fleet_procs import Fleet, free_port

RAW_FRAME = 640 * 480 * 3


@pytest.fixture(scope="module")
def router():
    port = free_port()
    fleet = Fleet(port, "router")
    proc = fleet.start("router", "--listen", f"tcp/127.0.0.1:{port}", "--json", "--no-multicast", connect=False)
    proc.next_record(10, lambda r: r.get("event") == "ready")
    yield port
    code, seconds = proc.stop(signal.SIGTERM)
    fleet.close()
    assert code == 0 and seconds < 5, (code, seconds)


@pytest.fixture
def fleet(router, request):
    fleet = Fleet(router, request.node.name.replace("_", "-")[:40])
    yield fleet
    fleet.close()


def by_key(records: list[dict]) -> dict[str, dict]:
    return {r["key"]: r for r in records}


def wait_for_counts(meter, wanted: dict[str, int], timeout: float) -> dict[str, int]:
    """Read the meter's per-second records until every key of ``wanted`` has been seen that many times (or fail)."""
    counts: dict[str, int] = {}
    deadline = time.monotonic() + timeout
    while any(counts.get(key, 0) < n for key, n in wanted.items()):
        try:
            record = meter.next_record(max(deadline - time.monotonic(), 0.01), lambda r: r.get("type") == "rate")
        except AssertionError:
            raise AssertionError(f"the meter counted {counts}, not {wanted}, within {timeout} s") from None
        counts[record["key"]] = record["count"]
    return counts


def test_meter_matches_what_was_sent(fleet):
    meter = fleet.start("meter", "--fleet", fleet.fleet, "--json", "--window", "100")
    common = ["--fleet", fleet.fleet, "--wait", "30"]  # each publisher starts once the meter subscribes
    publishers = [
        fleet.start("publish", *common, "--vehicle", "uav1", "--topic", "hint", "--rate", "200", "--count", "400"),
        fleet.start("publish", *common, "--vehicle", "uav2", "--topic", "features", "--rate", "20", "--count", "40",
                    "--points", "30"),
        fleet.start("publish", *common, "--vehicle", "ugv1", "--topic", "image", "--rate", "10", "--count", "20"),
    ]
    sent = {}
    for proc in publishers:
        record = proc.next_record(60)
        assert record["matched"], record
        sent[f"evopose/{fleet.fleet}/{record['vehicle']}/{record['topic']}"] = record
        assert proc.wait(10) == 0
    # the publishers are gone, their last messages may still be on the way: stop the meter once it has counted
    # every message of the BLOCK topics and every Stats message (the last, from each publisher's exit, included)
    block = [f"evopose/{fleet.fleet}/uav1/hint", f"evopose/{fleet.fleet}/uav2/features"]
    wanted = {key: sent[key]["sent"] for key in block}
    wanted.update({f"evopose/{fleet.fleet}/{r['vehicle']}/stats": r["stats_sent"] for r in sent.values()})
    wait_for_counts(meter, wanted, 30)
    code, seconds = meter.stop(signal.SIGTERM)
    assert code == 0 and seconds < 5
    summary = meter.next_record(2, lambda r: r.get("type") == "summary")
    keys = by_key(summary["keys"])
    hint, features, image = (keys[f"evopose/{fleet.fleet}/{v}/{t}"] for v, t in
                             (("uav1", "hint"), ("uav2", "features"), ("ugv1", "image")))
    # sizes: 24 B, a few hundred bytes, ~921 KB
    assert hint["size_min"] == hint["size_max"] == 24
    assert 300 <= features["size_min"] <= features["size_max"] < 1000
    assert RAW_FRAME < image["size_min"] == image["size_max"] < RAW_FRAME + 1000
    assert image["size_mean"] / features["size_mean"] > 1000 and features["size_mean"] / hint["size_mean"] > 10
    # BLOCK topics: what the publishers counted arrives, message for message and byte for byte
    for key in block:
        assert (keys[key]["count"], keys[key]["total_bytes"]) == (sent[key]["sent"], sent[key]["bytes"]), key
    assert image["count"] >= 15  # DROP: a frame may be lost, not more
    # rates and bandwidth
    assert hint["rate_hz"] == pytest.approx(200, rel=0.15)
    assert features["rate_hz"] == pytest.approx(20, rel=0.15)
    assert image["rate_hz"] == pytest.approx(10, rel=0.2)
    for record in (hint, features, image):
        assert record["window"] == min(record["count"], 100)
        assert 0 <= record["period_min_s"] <= record["period_max_s"] and record["period_std_s"] >= 0
    # the meter's bandwidth against what the publishers sent: their rate times their own mean message size (each
    # publisher's count of bytes over messages), within the rate's tolerance above
    for (vehicle, topic), rate_hz, tolerance in ((("uav1", "hint"), 200, 0.15), (("uav2", "features"), 20, 0.15),
                                                 (("ugv1", "image"), 10, 0.2)):
        published = sent[f"evopose/{fleet.fleet}/{vehicle}/{topic}"]
        expected = rate_hz * published["bytes"] / published["sent"]
        measured = keys[f"evopose/{fleet.fleet}/{vehicle}/{topic}"]["bandwidth_Bps"]
        assert measured == pytest.approx(expected, rel=tolerance)
    assert hint["bandwidth_Bps"] == pytest.approx(4800, rel=0.15)
    # the agents' own counts, from their Stats
    agents = summary["agents"]
    assert agents[f"{fleet.fleet}/uav1"]["sent"]["hint"] == 400  # the final Stats, sent at exit
    assert agents[f"{fleet.fleet}/uav2"]["bytes_sent"]["features"] == sent[f"evopose/{fleet.fleet}/uav2/features"][
        "bytes"]


ATTACKER = """
import json, time, numpy as np, protocol as p, zenoh
from agents.transport.bus import FleetBus
from agents.transport.session import SessionOptions
rng = np.random.default_rng(0)
options = SessionOptions(mode="client", connect=({endpoint!r},), multicast=False)
with FleetBus.open(options, {fleet!r}, "evil") as bus:
    for topic in ("image", "features", "hint", "attitude", "pose"):
        assert bus.wait_for_subscribers(topic, 30)
        # an attacker picks its own QoS: BLOCK on every key (images too), so that all of it arrives to be counted
        evil = bus.session.declare_publisher(p.topic_key({fleet!r}, "evil", topic),
                                             congestion_control=zenoh.CongestionControl.BLOCK)
        for _ in range(3):
            evil.put(bytes(rng.integers(0, 256, 100, dtype=np.uint8)) + b"\\xc1")  # garbage
        evil.put(b"\\x00" * (p.size_limit(topic) + 1))                             # oversized
        evil.put(b"")                                                              # empty
        evil.undeclare()
    bus.put_raw("pose", p.encode(p.PoseEstimate(sender="other", seq=0, stamp_ns=time.time_ns(), pose=(0,) * 6,
                fitness=0, mismatch=0, converged=True, generations=1, seconds=0)))           # spoofed sender
    bus.put_raw("pose", p.encode(p.PoseEstimate(sender="evil", seq=0, stamp_ns=time.time_ns() - 10**10,
                pose=(0,) * 6, fitness=0, mismatch=0, converged=True, generations=1, seconds=0)))  # stale
    t0 = time.monotonic()
    for i in range(300):
        bus.publish_hint(np.array([i, 0, 10, 0, 0, 0.1]))
    print(json.dumps({{"hints": 300, "seconds": time.monotonic() - t0}}), flush=True)
"""


def test_receiver_survives_garbage_and_hints_flow_fast(fleet):
    listener = fleet.start("listen", "--fleet", fleet.fleet, "--vehicle", "rx")
    listener.next_record(30, lambda r: r.get("event") == "ready")
    attacker = fleet.python(textwrap.dedent(ATTACKER.format(endpoint=fleet.endpoint, fleet=fleet.fleet)))
    timing = attacker.next_record(60)
    assert attacker.wait(30) == 0, attacker.popen.stderr.read()
    assert timing["hints"] / timing["seconds"] > 100  # hints flow > 100 Hz, and all 300 arrive (below)
    # the listener has handled all of it (its counters, printed every second) and seen the attacker leave
    last: dict = {}

    def handled(record: dict) -> bool:
        if record.get("event") != "counters":
            return False
        last.update(record)
        return record["received"].get("hint") == 300 and sum(record["rejected"].values()) == 27

    try:
        listener.next_record(30, handled)
    except AssertionError:
        raise AssertionError(f"the listener's counters did not reach 300 hints and 27 rejections: {last}") from None
    listener.first_record(10, lambda r: r.get("event") == "leave" and r["vehicle"] == "evil")
    assert listener.popen.poll() is None  # still running after all that
    code, _ = listener.stop(signal.SIGTERM)
    assert code == 0
    summary = listener.next_record(2, lambda r: r.get("event") == "summary")
    assert summary["received"] == {"hint": 300}, summary
    assert summary["lost"] == {}
    rejected = summary["rejected"]
    assert rejected["oversized"] == 5 + 3  # one per topic, plus the three 101-byte "hints"
    assert rejected["stale"] == 1
    # every topic saw 5 bad payloads (3 garbage, 1 oversized, 1 empty); pose also a spoofed and a stale one
    assert summary["rejected_by_topic"] == {"image": 5, "features": 5, "hint": 5, "attitude": 5, "pose": 7}
    assert sum(rejected.values()) == 27


def test_teammate_killed_is_seen_leaving_and_returning(fleet):
    listener = fleet.start("listen", "--fleet", fleet.fleet, "--vehicle", "rx", "--topics", "hint")
    listener.next_record(30, lambda r: r.get("event") == "ready")
    args = ("publish", "--fleet", fleet.fleet, "--vehicle", "mate", "--rate", "5", "--stay", "--wait", "0")
    mate = fleet.start(*args)
    joined = listener.next_record(30, lambda r: r.get("event") == "join")
    assert joined["vehicle"] == "mate"
    used = listener.next_record(30, lambda r: r.get("event") == "data")  # its hints are used
    assert used["vehicle"] == "mate" and used["topic"] == "hint" and used["teammates"] == ["mate"]
    mate.popen.send_signal(signal.SIGKILL)
    mate.wait(5)
    left = listener.next_record(30, lambda r: r.get("event") == "leave")
    assert left["vehicle"] == "mate"
    again = fleet.start(*args)
    assert listener.next_record(30, lambda r: r.get("event") == "join")["vehicle"] == "mate"
    # it is used again: a hint of the new process arrives and is handed on (not only counted), with the mate alive
    used_again = listener.next_record(30, lambda r: r.get("event") == "data")
    assert used_again["vehicle"] == "mate" and used_again["topic"] == "hint" and used_again["teammates"] == ["mate"]
    code, seconds = again.stop(signal.SIGTERM)
    assert code == 0 and seconds < 5
    assert json.dumps(again.next_record(2)["topic"]) == '"hint"'
    assert listener.next_record(30, lambda r: r.get("event") == "leave")["vehicle"] == "mate"
    code, seconds = listener.stop(signal.SIGTERM)
    assert code == 0 and seconds < 5
    summary = listener.next_record(2, lambda r: r.get("event") == "summary")
    assert summary["teammates"] == [] and summary["received"].get("hint", 0) > 0


@pytest.mark.parametrize("args, message", [
    (["meter", "--mode", "bogus"], "--mode must be one of peer, client, router, got 'bogus'"),
    (["meter", "--connect", "127.0.0.1:7447"], "--connect endpoint '127.0.0.1:7447' must look like"),
    (["router", "--listen", "tcp/no-port"], "cannot open the Zenoh session"),
    (["meter", "--config", "/nonexistent.json5"], "Zenoh config file '/nonexistent.json5' does not exist"),
    (["meter", "--fleet", "a/b"], "fleet 'a/b' must be"),
    (["publish", "--fleet", "f", "--vehicle", "v*"], "vehicle 'v*' must be"),
    (["publish", "--fleet", "f", "--vehicle", "v", "--payload", "evil"], "--payload must be one of"),
    (["listen", "--fleet", "f", "--vehicle", "v", "--topics", "hint,video"], "--topics must be names"),
])
def test_bad_arguments_are_one_line_and_exit_2(args, message, capsys):
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and message in err and err.count("\n") == 1 and "Traceback" not in err


def test_unreadable_zenoh_config_from_environment(tmp_path, monkeypatch, capsys):
    bad = tmp_path / "zenoh.json5"
    bad.write_text("{mode: 'bogus'}")
    monkeypatch.setenv("ZENOH_CONFIG", str(bad))
    assert main(["meter", "--duration", "0"]) == 2
    assert "unknown variant `bogus`" in capsys.readouterr().err
