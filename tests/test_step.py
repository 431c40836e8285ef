"""A camera vehicle's per-frame decision without Zenoh: agents.vehicle.step, and the estimator's time slices
and candidate exchange at the paper's image scale (exp2-paper-scale: the Pioneer ~25 px wide)."""

from __future__ import annotations

import numpy as np
import pytest

from agents.vehicle.frames import SimulatedCamera
from agents.vehicle.step import FrameInputs, share, step
from agents.vehicle.team_views import build_views, mate_view, own_view
from evopose.cooperative import CooperativeEstimator
from protocol import FeatureSet, decode, encode
from scenarios.world import load_scenario


@pytest.fixture(scope="module")
def paper_scale():
    scenario = load_scenario("exp2-paper-scale")
    frames = {v: [SimulatedCamera(scenario, v).acquire(n, n * 100_000_000) for n in range(4)] for v in ("H1", "H2")}
    return scenario, frames


def _estimator(scenario, seed=0):
    return CooperativeEstimator(scenario.model.evopose_model(), scenario.bounds(), seed=seed)


def _own(frames, vehicle, n):
    f = frames[vehicle][n]
    return own_view(vehicle, f.stamp_ns, f.camera, f.points)


def test_step_publishes_the_pose_and_in_hint_mode_a_hint(paper_scale):
    scenario, frames = paper_scale
    inputs = FrameInputs(0, _own(frames, "H1", 0), truth=frames["H1"][0].truth)
    result = step(_estimator(scenario), inputs, vehicle="H1", target="pioneer", share_mode="hint")
    topics = [out.topic for out in result.outbox]
    assert result.estimate is not None and result.estimate.good
    assert topics == ["pose", "hint"]
    pose = result.outbox[0].fields
    assert pose["converged"] and pose["target"] == "pioneer" and pose["inputs"] == ()
    assert result.event["error"]["position"] < 0.5
    alone = step(_estimator(scenario), inputs, vehicle="H1", target="pioneer", share_mode="none")
    assert [out.topic for out in alone.outbox] == ["pose"]


def test_too_few_points_is_a_no_estimate_event_and_publishes_nothing(paper_scale):
    scenario, frames = paper_scale
    own = _own(frames, "H1", 0)
    empty = own.__class__(own.vehicle, own.stamp_ns, own.camera, own.points[:2])
    result = step(_estimator(scenario), FrameInputs(0, empty), vehicle="H1", target="pioneer", share_mode="none")
    assert result.estimate is None and result.outbox == () and result.event["event"] == "no-estimate"


def test_a_search_in_slices_ends_where_the_whole_search_ends(paper_scale):
    """Time slices pause the search between generations only: the same seed gives the same pose."""
    scenario, frames = paper_scale
    views, _ = build_views([_own(frames, "H1", 0)])
    whole = _estimator(scenario).estimate(views, frame=0)
    sliced = _estimator(scenario)
    first = sliced.estimate(views, frame=0, budget_s=0.0)
    assert not first.good and sliced.searching  # one generation, then the best so far
    estimate = first
    for _ in range(10_000):
        if not sliced.searching:
            break
        estimate = sliced.generation(budget_s=0.0)
    assert not sliced.searching and estimate.good == whole.good
    np.testing.assert_array_equal(estimate.pose, whole.pose)


def test_feature_sets_carry_the_best_and_team_mates_agree(paper_scale):
    """Exp. 2(a) with our extension: each feature set carries the sender's best pose; both vehicles weigh the
    same candidates on the same eq. (4) views and publish the same pose, although their searches differ."""
    scenario, frames = paper_scale
    h1, h2 = _estimator(scenario, seed=1), _estimator(scenario, seed=2)
    agreed = 0
    for n in range(4):
        own1, own2 = _own(frames, "H1", n), _own(frames, "H2", n)
        sent = {}
        for name, est, own in (("H1", h1, own1), ("H2", h2, own2)):
            out = share("features", "raw", frames[name][n], own, est.current_best)
            message = FeatureSet(sender=name, seq=n, stamp_ns=own.stamp_ns, **out.fields)
            sent[name] = decode("features", encode(message))  # through the wire format
        mate_of = {"H1": mate_view("H2", sent["H2"], None), "H2": mate_view("H1", sent["H1"], None)}
        r1 = step(h1, FrameInputs(n, own1, (mate_of["H1"],)), vehicle="H1", target="pioneer", share_mode="features")
        r2 = step(h2, FrameInputs(n, own2, (mate_of["H2"],)), vehicle="H2", target="pioneer", share_mode="features")
        assert r1.inputs == r2.inputs == ("H1", "H2")
        if n >= 1:  # from the second frame on, each has the other's best
            agreed += bool(np.array_equal(r1.estimate.pose, r2.estimate.pose))
    assert agreed == 3


# -- the improver's slots (agents.vehicle.roles.SlotSchedule) ----------------------------------------------

def test_slot_schedule_keeps_the_rate_and_makes_up_at_most_a_burst():
    from agents.vehicle.roles import SlotSchedule
    schedule = SlotSchedule(200.0, burst=20)  # 5 ms slots, up to a 100 ms frame's worth made up
    assert schedule.due(0.0) and not schedule.due(0.001) and schedule.wait_s(0.001) == pytest.approx(0.004)
    # a 60 ms frame held the thread: the 12 slots it covered are made up at once, then the rate is 200 Hz again
    made_up = sum(schedule.due(0.065) for _ in range(30))
    assert made_up == 13 and schedule.wait_s(0.065) == pytest.approx(0.005)
    # a long stall is not made up beyond the burst: never more than 200 Hz over a burst's window
    assert sum(schedule.due(10.0) for _ in range(100)) == 20
    plain = SlotSchedule(200.0)  # burst 1: a late call does not lower the rate, and nothing is made up
    assert plain.due(0.0) and plain.due(0.007) and not plain.due(0.008) and plain.due(0.010)
