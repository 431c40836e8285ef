"""Two hosts (network namespaces joined by a veth pair), one `evopose router` each, the routers joined: H1 and the
target (pioneer) on host A, H2 on host B, sharing feature sets (exp2). Faults on the link between the hosts:
(a) 20 % of B's inbound packets dropped for the whole run; (b) a partition of 5 s, then the link back; (c) a
partition of 12 s, longer than the Zenoh lease: the team-mate leaves, then joins again.
Real processes, real Zenoh, real packets dropped by iptables (docs/scaling.md, "Faults")."""

from __future__ import annotations

import time

import numpy as np
import pytest

from tests.netns import FleetOnHosts, Hosts, frame_time_ns, unavailable

pytestmark = pytest.mark.skipif(unavailable() is not None, reason=f"netns fault tests: {unavailable()}")

BOTH = ["H1", "H2"]
#: Frames of the lossy run (10 frames/s).
LOSSY_FRAMES = 60
#: Partition length, s.
PARTITION_S = 5.0
#: Longest time from the link's return until both helicopters use both views again, s. TCP retransmits
#: the segments lost in the partition only when its backed-off retransmission timer fires (200 ms doubling:
#: ~1.6-3.2 s after a 5 s cut), and every later message waits behind them.
REJOIN_S = 5.0
#: Longest time between two frames a vehicle estimated alone while cut off, s.
MAX_GAP_S = 0.5


@pytest.fixture
def hosts():
    made = Hosts()
    try:
        yield made
    finally:
        made.close()


def both_views(record: dict) -> bool:
    return record.get("event") == "frame" and record["views"] == BOTH


def pose_of(record: dict) -> np.ndarray:
    return np.array([record["pose"][n] for n in ("x", "y", "z", "roll", "pitch", "yaw")])


#: --max-age on the lossy link: TCP's backed-off retransmissions stall a stream for 1-2 s now and then (head of
#: line), past the default 1 s, which left a helicopter alone for 6-7 frames in 2 of ~12 runs (docs/scaling.md,
#: "Faults"). On a lossy link a team-mate's newest view a few seconds old is still worth using.
LOSSY_MAX_AGE_S = 3.0


def start_team(fleet: FleetOnHosts, *h_args: str) -> None:
    fleet.start_router("A")
    fleet.start_router("B")
    fleet.start_agent("A", "pioneer")
    fleet.start_agent("A", "H1", "--share", "features", *h_args, wait_for="H2")
    fleet.start_agent("B", "H2", "--share", "features", *h_args, wait_for="H1")


def test_a_lossy_link_between_the_hosts_keeps_both_views_and_agreement(hosts):
    # Linux's default TCP: a lost segment is sent again after >= 200 ms, doubling when lost again; the feature sets
    # behind it wait (head-of-line blocking). Stalls past the default --max-age (1 s) left the receiver alone for
    # 6-7 frames in 2 of ~12 runs (once under 95 %: docs/scaling.md, "Faults"), so this link runs with
    # LOSSY_MAX_AGE_S, the setting docs/scaling.md recommends for lossy links.
    fleet = FleetOnHosts(hosts, "lossy")
    hosts.drop_inbound("B", 0.2)
    start_team(fleet, "--frames", str(LOSSY_FRAMES), "--max-age", f"{LOSSY_MAX_AGE_S:g}")
    summaries = {v: fleet.summary(v, 90) for v in BOTH}
    h1, h2 = fleet.frames("H1"), fleet.frames("H2")
    # --frames counts the frames a vehicle ran: one that skipped frames (CPU contention: late frames) runs on after
    # the other stopped. Both views are expected while both ran.
    together = range(max(min(h1), min(h2)), min(max(h1), max(h2)) + 1)
    multi, first_both = {}, {}
    for vehicle, frames in (("H1", h1), ("H2", h2)):
        s = summaries[vehicle]
        # every frame it ran was estimated (frames skipped because the CPU was busy are counted as late)
        assert s["frames"] == s["estimates"] == len(frames) == LOSSY_FRAMES, s
        # Until the team-mate's first feature set arrives there is no older one to fall back on: a loss among the
        # first segments (TCP resends after >= 200 ms, doubling) leaves the first frames alone. Measured: H2's first
        # frame with both views was 0-1 frames after the start in 6 runs, 4 and 8 in two others (then 56 of 56 and
        # 52 of 52). So the start is bounded (three resends of one segment, 0.2 + 0.4 + 0.8 s, and some margin:
        # 2 s), and "keeps" is counted from the first frame with both views.
        first_both[vehicle] = min(n for n, r in frames.items() if r["views"] == BOTH)
        assert first_both[vehicle] <= together.start + 20, (vehicle, first_both[vehicle], together)
        ran = [r for n, r in frames.items() if n in together and n >= first_both[vehicle]]
        multi[vehicle] = (sum(r["views"] == BOTH for r in ran), len(ran))
        alone = [n for n, r in frames.items() if n in together and r["views"] != BOTH]
        assert multi[vehicle][0] >= 0.95 * len(ran), (vehicle, multi[vehicle], alone, s["traffic"])
    same = [n for n in h1 if n in h2 and h1[n]["views"] == h2[n]["views"] == BOTH
            and h1[n]["views_of_this_instant"] and h2[n]["views_of_this_instant"]]
    print(f"lossy link: first frame with both views {first_both} (both ran from {together.start}); frames with "
          f"both views after it (of those run while both ran) {multi}; {len(same)} frames with "
          f"both views of the same instant on both; late frames {summaries['H1']['late_frames']}, "
          f"{summaries['H2']['late_frames']}")
    assert len(same) >= LOSSY_FRAMES // 4  # loss delays some feature sets past the sync wait, not most
    for n in same:
        d = pose_of(h1[n]) - pose_of(h2[n])
        assert np.linalg.norm(d[:3]) <= 0.01 and np.degrees(np.abs(d[3:])).max() <= 0.1, (n, d)


def cut_and_heal(hosts, name: str, cut_s: float, rejoin_s: float):
    """A team on both hosts, both views in use; every packet between the hosts dropped for ``cut_s``, then the
    link back; both views again (waited up to ``rejoin_s`` + 5 s), then stopped. The agents, the cut's, the
    link's return's and the stop's times (ns) and per vehicle the seconds from the return to both views."""
    fleet = FleetOnHosts(hosts, name)
    start_team(fleet)
    h1, h2 = fleet.agents["H1"], fleet.agents["H2"]
    for agent in (h1, h2):
        agent.next_record(60, both_views)
    hosts.partition()
    cut_ns = time.time_ns()
    time.sleep(cut_s)
    hosts.heal()
    healed_ns = time.time_ns()
    rejoined = {}
    for vehicle, agent in (("H1", h1), ("H2", h2)):
        back = agent.next_record(rejoin_s + 5, lambda r: both_views(r) and r["stamp_ns"] >= healed_ns)
        rejoined[vehicle] = (back["stamp_ns"] - healed_ns) / 1e9
    time.sleep(0.5)
    stopped_ns = time.time_ns()
    for agent in (h1, h2):
        agent.stop()
    return h1, h2, cut_ns, healed_ns, stopped_ns, rejoined


def test_b_a_partition_leaves_each_alone_and_both_rejoin_when_the_link_returns(hosts):
    h1, h2, cut_ns, healed_ns, stopped_ns, rejoined = cut_and_heal(hosts, "partition", PARTITION_S, REJOIN_S)
    report = {}
    for vehicle, mate, agent in (("H1", "H2", h1), ("H2", "H1", h2)):
        records = agent.all_records()
        stale = [r for r in records if r.get("event") == "stale" and r["vehicle"] == mate]
        fresh = [r for r in records if r.get("event") == "fresh" and r["vehicle"] == mate]
        assert len(stale) == 1 and len(fresh) == 1, (vehicle, stale, fresh)
        stale_ns, fresh_ns = frame_time_ns(agent, stale[0]), frame_time_ns(agent, fresh[0])
        assert cut_ns < stale_ns < healed_ns < fresh_ns
        # alone while cut off: it kept estimating, on its own view, from the stale event to the link's return (the
        # frame loop never stalled: no gap over MAX_GAP_S; single skipped frames are CPU contention, counted as late)
        stamps = sorted(r["stamp_ns"] for r in records if r.get("event") == "frame"
                        and stale_ns <= r["stamp_ns"] < healed_ns and r["views"] == [vehicle] and r["pose"])
        edges = [stale_ns, *stamps, healed_ns]
        gaps = [(b - a) / 1e9 for a, b in zip(edges, edges[1:])]
        assert stamps and max(gaps) <= MAX_GAP_S, (vehicle, gaps)
        # 5 s < the Zenoh lease (10 s): no one left (until the end, when the other was stopped)
        assert not [r for r in records if r.get("event") == "leave" and r["_rx_ns"] < stopped_ns]
        report[vehicle] = {"stale_after_s": (stale_ns - cut_ns) / 1e9, "rejoined_after_s": rejoined[vehicle]}
    print(f"partition of {PARTITION_S:g} s: {report}")
    assert max(rejoined.values()) <= REJOIN_S, report


#: A partition longer than the Zenoh lease (10 s): the sessions between the hosts close.
LONG_PARTITION_S = 12.0
#: Zenoh's default lease, s (transport/link/tx/lease, 10000 ms).
LEASE_S = 10.0
#: Longest time from the link's return until both helicopters use both views again after a long cut, s: B's router
#: connects to A's again (retry every 0.25-1 s, agents/transport/session.py) and the agents see each other join.
REJOIN_LONG_S = 15.0


def test_c_a_partition_longer_than_the_lease_ends_in_leave_then_join_and_both_views_again(hosts):
    h1, h2, cut_ns, healed_ns, stopped_ns, rejoined = cut_and_heal(hosts, "longcut", LONG_PARTITION_S,
                                                                   REJOIN_LONG_S)
    report = {}
    for vehicle, mate, agent in (("H1", "H2", h1), ("H2", "H1", h2)):
        records = [r for r in agent.all_records() if r.get("_rx_ns", 0) < stopped_ns]
        events = {kind: [r for r in records if r.get("event") == kind and r.get("vehicle") == mate]
                  for kind in ("stale", "leave", "join")}
        # past the lease the session between the hosts closed: the team-mate left during the cut, and joined
        # again after the link returned (its first join, at start, came before the cut)
        left = [r for r in events["leave"] if cut_ns < r["_rx_ns"] < healed_ns]
        joined = [r for r in events["join"] if r["_rx_ns"] > healed_ns]
        assert len(left) == 1 and len(joined) == 1, (vehicle, events)
        assert [r for r in events["stale"] if cut_ns < frame_time_ns(agent, r) < left[0]["_rx_ns"]], (vehicle, events)
        # alone but estimating all the while: frames on its own view between the leave and the link's return
        alone = [r for r in records if r.get("event") == "frame" and left[0]["_rx_ns"] <= r["stamp_ns"] < healed_ns
                 and r["views"] == [vehicle] and r["pose"]]
        assert alone, vehicle
        report[vehicle] = {"left_after_s": round((left[0]["_rx_ns"] - cut_ns) / 1e9, 2),
                           "joined_after_heal_s": round((joined[0]["_rx_ns"] - healed_ns) / 1e9, 2),
                           "both_views_after_heal_s": round(rejoined[vehicle], 2), "frames_alone": len(alone)}
        assert LEASE_S - 1 <= report[vehicle]["left_after_s"] <= LONG_PARTITION_S, report
    print(f"partition of {LONG_PARTITION_S:g} s: {report}")
    assert max(rejoined.values()) <= REJOIN_LONG_S, report
