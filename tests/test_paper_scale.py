"""The paper's image scale (exp2-paper-scale: the Pioneer ~25 px wide, marks 2-4 px): the --world override,
a driving Pioneer tracked (eq. 2), hints that pull a team-mate out of a wrong basin, and two real agents
that publish the same pose."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from agents.experiments.results import frame_agreement
from agents.vehicle.frames import SimulatedCamera
from agents.vehicle.step import FrameInputs, VehicleState, share, share_policy, step
from agents.vehicle.team_views import build_views, mate_view, own_view
from evopose.cooperative import Cooperation, CooperativeEstimator
from geometry import angle_difference
from protocol import decode, encode
from scenarios.errors import ScenarioError
from scenarios.fleet import load_fleet_scenario
from scenarios.world import load_scenario
from tests.fleet_procs import free_port

ROOT = Path(__file__).resolve().parents[1]


def test_any_fleet_scenario_runs_on_another_world_with_the_same_vehicles():
    scenario = load_fleet_scenario("exp2a-features", "exp2-paper-scale")
    assert scenario.world.name == "exp2-paper-scale" and scenario.name == "exp2a-features"
    assert [v.camera.intrinsics.fx for v in scenario.world.spec.vehicles] == [1700, 1150]
    with pytest.raises(ScenarioError, match="--world: no world 'nowhere'"):
        load_fleet_scenario("exp2a-features", "nowhere")
    with pytest.raises(ScenarioError, match="not in world 'exp1-airship'"):
        load_fleet_scenario("exp2a-features", "exp1-airship")


def test_the_pioneer_spans_20_to_30_pixels_at_paper_scale():
    scenario = load_scenario("exp2-paper-scale")
    for vehicle in ("H1", "H2"):
        frame = SimulatedCamera(scenario, vehicle).acquire(0, 0)
        corners = np.array([[x, y, z] for x in (-0.22, 0.22) for y in (-0.19, 0.19) for z in (0.0, 0.22)])
        uv, _ = frame.camera.project_world(corners)  # the Pioneer's box at the origin, as at frame 0
        assert 18 <= np.ptp(uv[:, 0]) <= 32, (vehicle, np.ptp(uv[:, 0]))


@pytest.mark.parametrize("world", ["exp2-paper-scale-driving", "exp2-driving"])
def test_a_driving_pioneer_is_tracked_and_both_helicopters_agree(world):
    """Feature sets with their senders' best poses, in process: 20 frames of a Pioneer driving at 0.5 m/s."""
    scenario = load_scenario(world)
    cams = {v: SimulatedCamera(scenario, v) for v in ("H1", "H2")}
    states = {v: VehicleState(Cooperation(scenario.model.evopose_model(), scenario.bounds(), seed=i),
                              share_policy("features"), v, "pioneer") for i, v in enumerate(("H1", "H2"))}
    good = agreed = 0
    errors = []
    for n in range(20):
        frames = {v: cams[v].acquire(n, n * 100_000_000) for v in cams}
        own = {v: own_view(v, frames[v].stamp_ns, frames[v].camera, frames[v].points) for v in cams}
        sent = {v: decode("features", encode(share(states[v], frames[v], own[v]))) for v in cams}
        published, events = {}, {}
        for v, mate in (("H1", "H2"), ("H2", "H1")):
            states[v], messages, events[v] = step(states[v], FrameInputs(
                n, own[v], (mate_view(mate, sent[mate], None),), truth=frames[v].truth, budget_s=1.0))
            published[v] = messages[0].pose
        good += events["H1"].estimate.converged and events["H2"].estimate.converged
        agreed += published["H1"] == published["H2"]
        if events["H1"].estimate.converged:
            errors.append(events["H1"].error["position"])
    assert good >= 18 and agreed >= 19
    assert np.median(errors) < 0.02  # metres, while the robot drove 1 m


def test_a_team_mates_hint_pulls_a_vehicle_out_of_a_wrong_basin():
    """Exp. 2(b) at paper scale: H2 is put in a wrong basin (the Pioneer turned half a turn) and stays there; H1's
    own estimate from its own image, sent as a hint, fits H2's image about as well or better, so H2's estimate
    takes it."""
    scenario = load_scenario("exp2-paper-scale")
    frame = SimulatedCamera(scenario, "H2").acquire(0, 0)
    views, _ = build_views([own_view("H2", 0, frame.camera, frame.points)])
    mate = SimulatedCamera(scenario, "H1").acquire(0, 0)
    mate_views, _ = build_views([own_view("H1", 0, mate.camera, mate.points)])
    hint = CooperativeEstimator(scenario.model.evopose_model(), scenario.bounds(), seed=3).estimate(mate_views,
                                                                                                    frame=0).pose
    estimator = CooperativeEstimator(scenario.model.evopose_model(), scenario.bounds(), seed=3)
    wrong = frame.truth + np.array([0.0, 0.0, 0.0, 0.0, 0.0, np.pi])
    # in a vehicle's slices (a generation a frame): the wrong candidate is tracked, unsure, while the search that
    # would confirm or replace it runs (without slices it runs to its end in the first call and finds the robot)
    first = estimator.estimate(views, frame=0, candidates=wrong[None], candidate_margin=0.0, generations=1)
    hinted = estimator.estimate(views, frame=1, candidates=hint[None], candidate_margin=0.1, generations=1)
    assert first.converged and abs(angle_difference(first.pose[5], frame.truth[5])) > np.radians(90.0)  # wrong
    assert not np.array_equal(hint, frame.truth)  # the team-mate's estimate, not the truth
    yaw_error = abs(angle_difference(hinted.pose[5], frame.truth[5]))
    assert hinted.converged and yaw_error < np.radians(2.0)


def test_two_agents_at_paper_scale_publish_the_same_pose():
    """Real processes over Zenoh on loopback: exp2a-features on exp2-paper-scale."""
    out = subprocess.run([sys.executable, "-m", "agents.cli", "scenario", "run", "exp2a-features", "--world",
                          "exp2-paper-scale", "--frames", "20", "--json", "--listen", f"tcp/127.0.0.1:{free_port()}"],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    result = json.loads(out.stdout.strip().splitlines()[-1])
    agreement = frame_agreement(result["runs"], "H1", "H2")
    assert agreement["frames"] >= 15 and agreement["fraction"] >= 0.9, agreement


def test_a_hint_that_fits_about_as_well_wins_only_with_the_margin():
    """The rule itself: a team-mate's pose whose mismatch on the own views is a little higher than the own best's
    is taken with the hint margin (> 0) and left with margin 0 (feature sets: the fittest wins)."""
    scenario = load_scenario("exp2-paper-scale")
    frame = SimulatedCamera(scenario, "H2").acquire(0, 0)
    views, _ = build_views([own_view("H2", 0, frame.camera, frame.points)])
    estimator = CooperativeEstimator(scenario.model.evopose_model(), scenario.bounds(), seed=3)
    assert estimator.estimate(views, frame=0).converged
    problem = estimator.problem(views)
    own = estimator.current_best
    nearby = own + np.array([0.02, 0.0, 0.0, 0.0, 0.0, 0.0])  # a slightly worse fit (mismatch 0.166 -> 0.181)
    assert np.array_equal(estimator._start(problem, nearby[None], 0.0), own)
    np.testing.assert_allclose(estimator._start(problem, nearby[None], 0.1), nearby, atol=1e-12)
    far = own + np.array([2.0, 2.0, 0.0, 0.0, 0.0, 1.0])  # fits much worse: never taken
    assert np.array_equal(estimator._start(problem, far[None], 0.1), own)


def _after_a_wrong_best(typed: bool) -> float:
    """H1's yaw error (deg) on the 8th frame of exp2-paper-scale, in process, after H2's first feature set carried as
    its best the truth turned half round (a mistaken or hostile team-mate); ``typed``: the points carry their colours."""
    from protocol import FeatureSet

    scenario = load_scenario("exp2-paper-scale")
    cams = {v: SimulatedCamera(scenario, v) for v in ("H1", "H2")}
    state = VehicleState(Cooperation(scenario.model.evopose_model(), scenario.bounds(), seed=0),
                         share_policy("features"), "H1", "pioneer")
    for n in range(8):
        frames = {v: cams[v].acquire(n, n * 100_000_000) for v in cams}
        views = {v: own_view(v, frames[v].stamp_ns, frames[v].camera, frames[v].points,
                             frames[v].labels if typed else None) for v in cams}
        mate = views["H2"]
        best = tuple(float(x) for x in frames["H2"].truth + np.array([0, 0, 0, 0, 0, np.pi])) if n == 0 else None
        sent = FeatureSet(sender="H2", seq=n, stamp_ns=mate.stamp_ns, target="pioneer", camera=mate.camera,
                          points=mate.points.astype("<f4").tobytes(), best=best,
                          labels=None if mate.labels is None else mate.labels.astype(np.uint8).tobytes())
        state, _, event = step(state, FrameInputs(n, views["H1"], (mate_view("H2", sent, None),),
                                                  truth=frames["H1"].truth))
        assert not (event.trust.good and abs(angle_difference(event.pose[5], frames["H1"].truth[5])) > 0.1)
    return float(np.degrees(abs(angle_difference(event.pose[5], frames["H1"].truth[5]))))


def test_a_team_mates_wrong_best_pose_is_searched_past_with_the_marks_colours():
    assert _after_a_wrong_best(typed=True) < 5.0   # measured: right from frame 1, good from frame 2


def test_a_team_mates_wrong_best_pose_is_searched_past_without_them():
    # untyped, the wrong twin fits the points about as well as the truth: judged against no rival it was taken as
    # sure and held the vehicle 178-180 deg off on all 8 frames; against its half-turned twins it is unsure, and the
    # confirming search finds the robot (measured: right and good from frame 1)
    assert _after_a_wrong_best(typed=False) < 5.0
