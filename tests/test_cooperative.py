"""CooperativeEstimator without Zenoh: views from two vehicles (eq. 4), IMU knowledge (eq. 3), hints, tracking,
between-frame generations; and the pairing of team-mates' frames by stamp."""

from __future__ import annotations

import numpy as np
import pytest

from agents.vehicle.frames import FrameClock, SimulatedCamera
from agents.vehicle.team_views import MateView, TeamViews, build_views, camera_from_info, camera_info, own_view
from evopose import PoseObjective, View
from evopose.cooperative import CooperativeEstimator, Knowledge
from geometry import wrap_angle
from scenarios.world import load_scenario


@pytest.fixture(scope="module")
def exp2():
    scenario = load_scenario("exp2")
    frames = {v: SimulatedCamera(scenario, v).acquire(0, 0) for v in ("H1", "H2")}
    return scenario, frames


def _views(frames, vehicles):
    return build_views([own_view(v, 0, frames[v].camera, frames[v].points) for v in vehicles])


def _estimator(scenario, seed=0):
    return CooperativeEstimator(scenario.model.evopose_model(), scenario.bounds(), seed=seed)


def _position_error(pose, truth):
    return float(np.linalg.norm(np.asarray(pose)[:3] - truth[:3]))


def test_two_views_in_either_order_give_one_pose(exp2):
    scenario, frames = exp2
    views_a, names_a = _views(frames, ("H1", "H2"))
    views_b, names_b = _views(frames, ("H2", "H1"))
    assert names_a == names_b == ["H1", "H2"] and [v.weight for v in views_a] == [0.5, 0.5]
    a = _estimator(scenario).estimate(views_a, frame=3)
    b = _estimator(scenario).estimate(views_b, frame=3)
    assert a.converged and a.solved and np.array_equal(a.pose, b.pose)
    assert _position_error(a.pose, frames["H1"].truth) < 0.02


def test_tracking_follows_and_reports_mismatch(exp2):
    scenario, frames = exp2
    estimator = _estimator(scenario)
    views, _ = _views(frames, ("H1",))
    first = estimator.estimate(views, frame=0)
    second = estimator.estimate(views, frame=1)
    assert first.solved and not second.solved and second.solution.stop_reason == "tracked"
    assert 0.0 <= second.mismatch < 0.5 and 0.0 <= first.mismatch < 0.5   # 0 best, as on the wire
    assert _position_error(second.pose, frames["H1"].truth) < 0.05


def test_knowledge_holds_the_attitude_within_its_tolerance(exp2):
    """Eq. (3): with roll, pitch and yaw known within 0.5 degrees the pose stays in that box."""
    scenario, frames = exp2
    truth = frames["H1"].truth
    offset = np.deg2rad(0.4)
    knowledge = [Knowledge(n, float(truth[3 + i] + offset), np.deg2rad(0.5)) for i, n in enumerate(("roll", "pitch",
                                                                                                     "yaw"))]
    views, _ = _views(frames, ("H1",))
    estimate = _estimator(scenario).estimate(views, knowledge=knowledge)
    delta = wrap_angle(estimate.pose[3:] - (truth[3:] + offset))
    assert np.all(np.abs(delta) <= np.deg2rad(0.5) + 1e-9)
    with pytest.raises(ValueError, match="knowledge of .heading.: expected one of"):
        Knowledge("heading", 0.0)


def test_a_bad_hint_is_discarded_and_a_good_one_kept(exp2):
    """From the same unfinished search (one generation from scratch): a hint 1.8 m and 115 deg off is discarded
    and the search goes on; the true pose as a hint is kept (the best comes from it), judged good, and ends the
    search. A tracked pose is not pulled away by the bad hint either."""
    scenario, frames = exp2
    views, _ = _views(frames, ("H2",))
    truth = frames["H2"].truth
    bad = truth + np.array([1.5, -1.0, 0.3, 0.0, 0.0, 2.0])
    outcomes = {}
    for name, hint in (("bad", bad), ("good", truth)):
        estimator = _estimator(scenario)
        first = estimator.estimate(views, frame=0, generations=1)
        assert estimator.searching and not first.converged  # one generation does not finish a search
        estimate = estimator.generation(hint[None])
        outcomes[name] = (estimate.solution.from_hint, estimate.converged, estimator.searching)
        assert _position_error(estimate.pose, truth) < 0.05, name
    assert outcomes == {"bad": (False, False, True), "good": (True, True, False)}
    tracking = _estimator(scenario)
    tracking.estimate(views, frame=0)
    for _ in range(5):
        estimate = tracking.generation(bad[None])
    assert _position_error(estimate.pose, truth) < 0.05 and not estimate.solution.from_hint


def test_a_generation_reports_the_eq4_fitness_of_its_pose_and_needs_an_estimate_first(exp2):
    """What a generation reports is eq. (4) at the pose it reports, on the frame's views (the fitness is never
    worse than the last one by construction: ``tell`` keeps the better)."""
    scenario, frames = exp2
    estimator = _estimator(scenario)
    assert estimator.generation() is None  # nothing to improve before the first estimate
    views, _ = _views(frames, ("H1",))
    estimator.estimate(views)
    objective = PoseObjective(estimator.problem(views), estimator.options.fitness, estimator.options.tau)
    history = []
    for _ in range(20):
        estimate = estimator.generation()
        assert objective(estimate.pose[None])[0] == pytest.approx(estimate.solution.fitness, rel=1e-9)
        history.append(estimate.solution.fitness)
    assert all(b <= a for a, b in zip(history, history[1:]))  # kept too: a regression of tell would show here


def test_camera_round_trip_and_pairing_by_stamp(exp2):
    scenario, frames = exp2
    cam = frames["H1"].camera
    back = camera_from_info(camera_info(cam))
    assert np.allclose(back.world_from_camera, cam.world_from_camera, atol=1e-12)
    clock = FrameClock(10.0, epoch_ns=1_000)
    assert clock.stamp_ns(25) == 1_000 + 2_500_000_000 and clock.index_of(clock.stamp_ns(25)) == 25
    assert clock.index_of(clock.stamp_ns(25) + 5_000_000) is None
    team = TeamViews()
    info = camera_info(cam)
    for n in range(12):  # keeps the last 8
        team.add(MateView("H2", clock.stamp_ns(n), info, np.zeros((4, 2), np.float32)))
    now = clock.stamp_ns(11)
    assert team.sharing({"H2"}, now, 1.0) == {"H2"} and team.sharing(set(), now, 1.0) == set()
    assert set(team.at(clock.stamp_ns(9), {"H2"})) == {"H2"} and team.at(clock.stamp_ns(2), {"H2"}) == {}
    assert team.newest({"H2"}, now + 5 * 10**9, 1.0) == {}


def test_only_team_mates_on_the_fleet_clock_are_waited_for(exp2):
    """Issue 12: a member whose newest feature set is stamped between the clock's ticks (a flood at arbitrary
    instants, a wrong --fps) is not waited for at a frame; it is again once its data come on the clock."""
    _, frames = exp2
    info = camera_info(frames["H1"].camera)
    clock = FrameClock(10.0, epoch_ns=1_000)
    on_clock = lambda stamp: clock.index_of(stamp) is not None  # noqa: E731
    team = TeamViews()
    points = np.zeros((4, 2), np.float32)
    for n in range(3):
        team.add(MateView("H2", clock.stamp_ns(n), info, points))
        team.add(MateView("H3", clock.stamp_ns(n), info, points))
    team.add(MateView("H3", clock.stamp_ns(2) + 37_000_000, info, points))  # the flood's: 37 ms off the tick
    assert team.on_clock({"H2", "H3", "H4"}, on_clock) == {"H2"}  # H4 sent nothing: nothing to wait for
    team.add(MateView("H3", clock.stamp_ns(3), info, points))
    assert team.on_clock({"H2", "H3"}, on_clock) == {"H2", "H3"}


def test_a_narrow_attitude_box_still_lets_the_position_converge():
    """Eq. (3) with an accurate IMU: roll, pitch and yaw held within 0.2° of the truth. The refinement must
    keep moving the position while the angles sit at the edges of their narrow box (before the active-set
    step it was stuck there: 17 cm off, never good, and worse on eq. 1 than the truth).

    Stuck means an estimate that fits its own frame worse than the true pose does, so that is asserted on
    every frame. The distance to the truth is asserted on the median: a clutter mark near a model mark can
    move a frame's optimum itself (frame 0 here: 6 cm, 1.9 sigma of the estimate's own x, and it fits the
    frame better than the truth does)."""
    scenario = load_scenario("exp1-airship")
    camera = SimulatedCamera(scenario, "ground-station")
    errors = []
    for n in range(5):
        frame = camera.acquire(n, n)
        views, _ = build_views([own_view("station", 0, frame.camera, frame.points)])
        knowledge = [Knowledge(name, float(frame.truth[3 + i]), np.deg2rad(0.2))
                     for i, name in enumerate(("roll", "pitch", "yaw"))]
        estimator = _estimator(scenario)
        estimate = estimator.estimate(views, knowledge=knowledge)
        assert estimate.converged and estimate.close_at is not None
        objective = PoseObjective(estimator.problem(views, knowledge, None), estimator.options.fitness,
                                  estimator.options.tau)
        at_estimate, at_truth = objective(np.stack([estimate.pose, frame.truth]))
        assert at_estimate <= at_truth + 1e-6, n
        errors.append(_position_error(estimate.pose, frame.truth))
    assert np.median(errors) < 0.02, errors


def _copy(value):
    """A copy of an attribute's numbers: an array, or nested tuples of arrays (the label coordinates) as one flat
    array."""
    if isinstance(value, np.ndarray):
        return np.array(value)
    if isinstance(value, tuple) and value and all(isinstance(v, (tuple, np.ndarray)) for v in value):
        return np.concatenate([np.ravel(_copy(v)) for v in value])
    return value


def _snapshot(objective: PoseObjective) -> dict:
    """An objective's state: every attribute but its evaluation counter (a meter, mutable by design) and its
    packed arrays (a cached property the objective computes itself)."""
    return {k: _copy(v) for k, v in vars(objective).items() if k not in ("counter", "packed")}


def test_the_estimator_never_mutates_an_objective(exp2, monkeypatch):
    """Eq. (4)'s step rule drops a view without the target; the estimator solves, tracks and runs generations
    with hints. Every objective made on the way ends as it was made: new weights make a new objective."""
    made = []
    post_init, with_weights = PoseObjective.__post_init__, PoseObjective.with_weights

    def record(self):
        post_init(self)
        made.append((self, _snapshot(self)))

    def record_reweighted(self, weights):
        other = with_weights(self, weights)
        made.append((other, _snapshot(other)))
        return other

    monkeypatch.setattr(PoseObjective, "__post_init__", record)
    monkeypatch.setattr(PoseObjective, "with_weights", record_reweighted)
    scenario, frames = exp2
    views, _ = _views(frames, ("H1", "H2"))
    junk = np.random.default_rng(3).uniform([50, 50], [590, 430], (len(views[1].points), 2))
    views = [views[0], View(views[1].camera, junk, views[1].weight)]
    estimator = _estimator(scenario)
    first = estimator.estimate(views, frame=0)
    assert first.converged and list(first.solution.view_weights) == [0.5, 0.0]
    assert estimator.estimate(views[:1], frame=1).solution.stop_reason == "tracked"
    truth = frames["H1"].truth
    for _ in range(3):
        estimator.generation(truth[None])
    assert len(made) > 4 and any(list(o.weights) == [0.5, 0.0] for o, _ in made)
    for objective, before in made:
        after = _snapshot(objective)
        assert after.keys() == before.keys()
        for key, value in before.items():
            np.testing.assert_array_equal(after[key], value, err_msg=key)


def test_a_confirming_search_whose_track_was_replaced_confirms_nothing_of_the_new_one(exp2, monkeypatch):
    # A tracked pose that is not confident (it began at a team-mate's pose) is confirmed by a global search beside it,
    # whose answer is compared with the pose tracked when it began (its anchor) and otherwise moved on by the track's
    # motion since. Here the first track is a wrong basin (the Pioneer half a turn round) and a team-mate's pose (the
    # right one, judged unsure here as an ambiguous frame's would be) replaces it a frame later: no motion of the
    # target, so the search's answer must not be shifted by that jump onto the old wrong basin. Measured on the
    # looks-long flat-cool paper-scale sequence, two agents in process: a first track 1.1 m off, replaced at frame 3
    # by a wrong basin 118 deg off; the confirming search found the right pose at frame 11 and was moved by that
    # jump, so the pair stayed wrong (and unsure) for all 20 frames.
    from dataclasses import replace

    import evopose.cooperative as cooperative
    from evopose.estimator_state import EstimatorState

    scenario, frames = exp2
    views, _ = _views(frames, ("H1", "H2"))
    truth = frames["H1"].truth
    wrong = truth + np.array([0.0, 0.0, 0.0, 0.0, 0.0, np.pi])
    coop = cooperative.Cooperation(scenario.model.evopose_model(), scenario.bounds(), seed=0)
    st, first = coop.estimate(EstimatorState(), views, frame=0, candidates=wrong[None], generations=4)
    assert first.converged and not first.solution.confident and st.confirm is not None
    assert st.confirm.anchor is not None and _position_error(first.pose, truth) < 0.5
    assert abs(wrap_angle(first.pose[5] - truth[5])) > np.radians(90)
    real = cooperative.assess
    monkeypatch.setattr(cooperative, "assess", lambda *a, **k: replace(real(*a, **k), confident=False))
    st, replaced = coop.estimate(st, views, frame=1, candidates=truth[None], generations=4)
    monkeypatch.setattr(cooperative, "assess", real)
    estimate, frame = replaced, 1
    while True:   # never moved onto the wrong basin (the old rule did, as the search ended at frame 1)
        assert abs(wrap_angle(estimate.pose[5] - truth[5])) < np.radians(5), frame
        if st.confirm is None or frame >= 40:
            break
        assert st.confirm.anchor is None, frame   # the track it began beside was replaced
        frame += 1
        st, estimate = coop.estimate(st, views, frame=frame, generations=4)
    assert st.confirm is None and estimate.solution.confident, frame   # the search ended and found this pose


def test_a_team_mates_pose_within_the_tracks_covariance_keeps_the_confirming_search_anchored(exp2):
    # hint mode: a team-mate's pose that fits about as well (the hint margin) is taken as the track's start; where it
    # lies within the own track's covariance it refines that track, no jump, so the confirming search beside it
    # keeps its anchor (its answer is compared with the pose and moved by the target's motion); a pose elsewhere
    # (the right one, half a turn from this wrong track) drops it
    from evopose.cooperative import Cooperation
    from evopose.estimator_state import EstimatorState

    scenario, frames = exp2
    views, _ = _views(frames, ("H1", "H2"))
    truth = frames["H1"].truth
    coop = Cooperation(scenario.model.evopose_model(), scenario.bounds(), seed=0)
    wrong = truth + np.array([0.0, 0.0, 0.0, 0.0, 0.0, np.pi])
    st, first = coop.estimate(EstimatorState(), views, frame=0, candidates=wrong[None], generations=1)
    assert not first.solution.confident and st.confirm is not None and st.confirm.anchor is not None
    near = st.last.pose + np.array([0.001, 0.0, 0.0, 0.0, 0.0, 0.0005])   # 1 mm, 0.03 deg: well within its sigmas
    assert np.array_equal(coop.start(st, coop.problem(views), near[None], 0.1), near)   # the hint is the start
    kept, _ = coop.estimate(st, views, frame=1, candidates=near[None], candidate_margin=0.1, generations=1)
    assert kept.confirm is not None and kept.confirm.anchor is not None
    jumped, _ = coop.estimate(st, views, frame=1, candidates=truth[None], candidate_margin=0.1, generations=1)
    assert jumped.confirm is None or jumped.confirm.anchor is None
