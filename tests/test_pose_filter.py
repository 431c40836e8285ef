"""The published track (evopose/pose_filter.py): good frames fused by their covariances, a jump set aside, a loss
only ageing the track. Poses and covariances are made by hand so that each rule is seen by its effect."""

from __future__ import annotations

import numpy as np

from evopose.pose_filter import PoseFilter
from geometry import pose_error
from scenarios.target import load_model, resolve_model_path

#: A frame at the paper's scale: position known to 2 cm, rotation to 3 deg (1 sigma, every axis).
FRAME_COV = np.diag([0.02 ** 2] * 3 + [np.deg2rad(3.0) ** 2] * 3)
LEVEL = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 2.4])


def _pioneer() -> PoseFilter:
    """The filter an agent at 10 fps has for the Pioneer (its model file's motion: it drives, it does not tilt)."""
    return PoseFilter.of_rules(load_model(resolve_model_path("pioneer")).confidence_rules(0.1))


def _tilted(pitch_deg: float, base: np.ndarray = LEVEL) -> np.ndarray:
    pose = base.copy()
    pose[4] += np.deg2rad(pitch_deg)
    return pose


def _run(filt: PoseFilter, poses, first: int = 0, good: bool = True):
    outs = []
    for k, pose in enumerate(poses, start=first):
        filt, out = filt.step(k, pose, FRAME_COV, good)
        outs.append(out)
    return filt, outs


def test_a_frame_that_lands_nine_degrees_off_within_its_own_sigma_is_published_near_the_track():
    # five right frames (each 1-2 deg off), then one that lands in its basin 9 deg off: 3 sigma under its own
    # covariance, so the per-frame verdict is good; the target cannot tilt 9 deg in 0.1 s
    right = [_tilted(d) for d in (1.5, -1.0, 2.0, -0.5, 1.0)]
    filt, outs = _run(_pioneer(), right)
    assert all(o.on_track for o in outs) and outs[-1].track_frames == 5
    filt, out = filt.step(5, _tilted(9.0), FRAME_COV, True)
    assert out.on_track and 2.0 < out.jump_sigmas < 4.0  # within the gate: fused, not set aside
    assert pose_error(out.pose, LEVEL)["pitch"] < 3.0  # the frame alone is 9 deg off
    # the fused track knows the tilt far better than one frame, and says so
    assert np.sqrt(out.covariance[4, 4]) < 0.6 * np.sqrt(FRAME_COV[4, 4])


def test_the_track_follows_a_driving_target_in_position_and_heading():
    # the Pioneer drives 4 cm and turns 2 deg per frame; its frames know position to 2 cm
    poses = [LEVEL + np.array([0.04 * k, 0.0, 0.0, 0.0, 0.0, np.deg2rad(2.0) * k]) for k in range(10)]
    _, outs = _run(_pioneer(), poses)
    assert all(o.on_track for o in outs)
    last = pose_error(outs[-1].pose, poses[-1])
    assert last["position"] < 0.03 and last["yaw"] < 2.0


def test_a_jump_is_set_aside_the_track_stands_and_the_fourth_in_a_row_restarts_it():
    filt, _ = _run(_pioneer(), [_tilted(0.0)] * 4)
    far = _tilted(40.0)
    filt, out = filt.step(4, far, FRAME_COV, True)
    assert not out.on_track and out.jump_sigmas > 4.0
    assert np.array_equal(out.pose, far)  # published as it is, not good
    filt, back = filt.step(5, _tilted(0.5), FRAME_COV, True)
    assert back.on_track and back.track_frames == 5  # the track stood: the right frame joins it
    for k in range(6, 9):  # three jumps in a row are set aside...
        filt, out = filt.step(k, far, FRAME_COV, True)
        assert not out.on_track and filt.track.frames == 5
    filt, out = filt.step(9, far, FRAME_COV, True)  # ...the fourth restarts the track from it, not yet good
    assert not out.on_track and filt.track.frames == 1 and np.allclose(filt.track.pose, far)
    filt, out = filt.step(10, _tilted(40.2), FRAME_COV, True)
    assert out.on_track and out.track_frames == 2


def test_frames_not_good_only_age_the_track_by_the_motion_of_each_elapsed_frame():
    pioneer = _pioneer()
    filt, _ = _run(pioneer, [LEVEL] * 3)
    before = filt.track.covariance.copy()
    wrong = _tilted(30.0)
    filt, out = filt.step(3, wrong, FRAME_COV, False)
    assert not out.on_track and np.array_equal(out.pose, wrong)  # a frame not good goes out as it is
    filt, out = filt.step(7, wrong, FRAME_COV, False)  # frames 4-6 never came (skipped)
    grown = np.diag(filt.track.covariance - before)
    assert np.allclose(grown, 5 * pioneer.motion ** 2)  # frames 3..7: five frames of motion
    assert filt.track.frames == 3  # nothing fused


def test_a_frame_without_a_finite_covariance_is_not_fused():
    filt, _ = _run(_pioneer(), [LEVEL] * 2)
    filt, out = filt.step(2, _tilted(1.0), np.full((6, 6), np.inf), True)
    assert not out.on_track and filt.track.frames == 2


def test_an_agent_counts_a_frame_set_aside_and_does_not_count_it_good():
    from agents.vehicle.events import FrameEvent
    from agents.vehicle.records import RunRecord
    from evopose import Solution
    from evopose.estimator_state import Estimate
    from evopose.trust import Trust

    solution = Solution(LEVEL, 0.1, np.zeros(2), np.ones(2), 0, 0, 0.0, True, "tracked", [])
    record = RunRecord()
    for verdict in (Trust(True, True, True, "set aside"), Trust(True, True, True),
                    Trust(True, True, False, "set aside")):  # the last is not good alone: not set aside
        record.add_frame(FrameEvent("H1", 0, 12, views=("H1", "H2"), pose=tuple(LEVEL), trust=verdict,
                                    estimate=Estimate(solution, 0.2, False)), 0.0)
    summary = record.summary()
    assert summary["good"] == 1 and summary["set_aside"] == 1
    assert FrameEvent("H1", 0, 12, pose=tuple(LEVEL), trust=Trust(True, True, True, "set aside"),
                      estimate=Estimate(solution, 0.2, False)).to_json()["standing"] == "set aside"


def test_a_track_is_published_good_only_once_it_knows_its_rotation_to_two_and_a_half_degrees():
    # one frame at the paper's scale (3 deg, 1 sigma) is fused but not yet publishable: a good pose must lie
    # within 5 deg at two sigmas; the second frame brings the fused sigma to ~2.1 deg
    filt, first = _pioneer().step(0, _tilted(5.2), FRAME_COV, True)
    assert first.on_track and not first.settled and first.track_frames == 1
    filt, second = filt.step(1, _tilted(0.5), FRAME_COV, True)
    assert second.on_track and second.settled
    assert np.degrees(np.sqrt(np.linalg.eigvalsh(second.covariance[3:, 3:]).max())) <= 2.5
    # a frame that is not good, and a frame set aside, are never settled
    _, lost = filt.step(2, _tilted(0.5), FRAME_COV, False)
    _, jumped = filt.step(2, _tilted(40.0), FRAME_COV, True)
    assert not lost.settled and not jumped.settled
    # without the rule (its rules' default sigma cap infinite) the first frame alone would have been good
    _, alone = PoseFilter(filt.motion).step(0, _tilted(5.2), FRAME_COV, True)
    assert alone.settled


def test_an_unsettled_track_makes_the_verdict_not_good_and_is_not_set_aside():
    from evopose.trust import Trust

    unsettled = Trust(True, True, True, "unsettled")
    assert not unsettled.good and not unsettled.set_aside and unsettled.in_right_basin
    assert Trust(True, True, True).good


def test_a_frame_record_says_whether_its_track_settled_and_why_it_is_unsure():
    from agents.vehicle.events import FrameEvent
    from evopose import Solution
    from evopose.estimator_state import Estimate
    from evopose.trust import Confidence, Trust, judge

    unsure = Solution(LEVEL, 0.1, np.zeros(2), np.ones(2), 0, 0, 0.0, True, "tracked", [])
    unsure = unsure.with_(confidence=Confidence(False, None, 9, 0.1, reason="ambiguous"))
    line = FrameEvent("H1", 0, 12, pose=tuple(LEVEL), trust=judge(unsure),
                      estimate=Estimate(unsure, 0.2, False)).to_json()
    assert line["reason"] == "ambiguous" and line["good"] is False and line["trust"] == "unsure"
    sure = unsure.with_(confidence=Confidence(True, None, 12, 0.0))
    line = FrameEvent("H1", 0, 12, pose=tuple(LEVEL), trust=Trust(True, True, True, "unsettled"),
                      estimate=Estimate(sure, 0.2, False)).to_json()
    assert line["reason"] == "track unsettled" and line["standing"] == "unsettled" and line["good"] is False
