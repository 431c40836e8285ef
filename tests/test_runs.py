"""Typed run records: a published pose row is written by the agent and read back by name (agents/runs.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from agents.experiments.results import frame_agreement
from agents.runs import POSE_COLUMNS, PoseRow, pose_rows, pose_table
from agents.vehicle.records import RunRecord


def test_an_agent_summary_carries_its_columns_and_its_rows_read_back_by_name():
    record = RunRecord()
    record.poses.append(PoseRow(7, (1.0, 2.0, 3.0, 0.1, -0.2, 0.3), True, 5))
    record.poses.append(PoseRow(8, (1.5, 2.0, 3.0, 0.1, -0.2, 0.3), False, 6))
    summary = json.loads(json.dumps(record.summary()))  # what goes to disk
    assert summary["pose_columns"] == list(POSE_COLUMNS) == ["frame", "x", "y", "z", "roll", "pitch", "yaw", "good",
                                                             "scene_frame"]
    assert summary["poses"][0] == [7, 1.0, 2.0, 3.0, 0.1, -0.2, 0.3, True, 5]  # readable: one row, named columns
    rows = pose_rows(summary)
    assert rows == list(record.poses)
    frames, poses, good = pose_table(rows)
    assert list(frames) == [7, 8] and poses.shape == (2, 6) and poses[1, 0] == 1.5 and list(good) == [True, False]


def test_a_summary_written_before_the_column_header_reads_the_same():
    old = {"poses": [[3, 0, 0, 1, 0, 0, 0.5, 1], [4, 0, 0, 1, 0, 0, 0.5, 0]]}
    expected = [PoseRow(3, (0.0, 0.0, 1.0, 0.0, 0.0, 0.5), True), PoseRow(4, (0.0, 0.0, 1.0, 0.0, 0.0, 0.5), False)]
    assert pose_rows(old) == expected and expected[0].scene_frame is None
    # written with the header but before scene_frame was kept
    assert pose_rows({**old, "pose_columns": ["frame", "x", "y", "z", "roll", "pitch", "yaw", "good"]}) == expected
    assert pose_rows({}) == []


@pytest.mark.parametrize("summary, message", [
    ({"pose_columns": ["frame", "x"], "poses": []}, "not readable here"),
    ({"poses": [[1, 2, 3]]}, "a pose row is [frame, x, y, z, roll, pitch, yaw, good, scene_frame]"),
    ({"poses": [{"frame": 1}]}, "a pose row is"),
])
def test_a_row_of_another_shape_is_one_precise_error(summary, message):
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace("]", r"\]")):
        pose_rows(summary)


def test_frame_agreement_pairs_rows_by_frame_and_wraps_angles():
    a = [PoseRow(k, (0.0, 0.0, 1.0, 0.0, 0.0, np.pi - 0.0005), True).to_json() for k in range(5)]
    b = [PoseRow(k, (0.0, 0.0, 1.0, 0.0, 0.0, -np.pi + 0.0005), k != 2).to_json() for k in range(1, 6)]
    out = frame_agreement([{"agents": {"H1": {"poses": a}, "H2": {"poses": b}}}], "H1", "H2")
    assert out["frames"] == 4 and out["agreed"] == 4 and out["both_good"] == 3


def test_frame_agreement_pairs_a_datasets_poses_by_its_frame_not_by_the_tick():
    # a vehicle plays a dataset one frame per frame processed: H2, late once, shows frame 3 at tick 5, H1 at tick 4
    pose = (0.0, 0.0, 1.0, 0.0, 0.0, 0.5)
    h1 = [PoseRow(t, pose, True, s).to_json() for t, s in ((0, 0), (1, 1), (2, 2), (4, 3))]
    h2 = [PoseRow(t, pose, True, s).to_json() for t, s in ((0, 0), (1, 1), (3, 2), (5, 3))]
    played = frame_agreement([{"agents": {"H1": {"poses": h1, "dataset": "d"}, "H2": {"poses": h2, "dataset": "d"}}}],
                             "H1", "H2")
    assert played["frames"] == 4 and played["agreed"] == 4
    rendered = frame_agreement([{"agents": {"H1": {"poses": h1}, "H2": {"poses": h2}}}], "H1", "H2")
    assert rendered["frames"] == 2  # a rendered world's instant is the tick: only ticks 0 and 1 are both there


def test_errors_are_over_the_right_basin_and_good_counts_only_precise_frames():
    from types import SimpleNamespace

    from agents.vehicle.events import FrameEvent
    from evopose.trust import Trust

    record = RunRecord()
    estimate = SimpleNamespace(solved=False, close_at=None, solution=SimpleNamespace(history=[]))
    for verdict, error in ((Trust(True, True, False), 0.8),    # one camera: right basin, range unknown
                           (Trust(True, True, True), 0.02),    # two cameras: good
                           (Trust(True, False, False), 5.0)):  # not sure of the basin: no error counted
        event = FrameEvent("H1", 0, 12, pose=(0.0,) * 6, trust=verdict, error={"position": error},
                           estimate=estimate)
        record.add_frame(event, image_ready_s=0.0)
    summary = record.summary()
    assert summary["good"] == 1 and summary["estimates"] == 3
    assert summary["error_position"] == (0.8 + 0.02) / 2 and summary["error_position_max"] == 0.8
    line = FrameEvent("H1", 0, 12, pose=(0.0,) * 6, trust=Trust(True, True, False), estimate=estimate).to_json()
    assert (line["good"], line["converged"], line["confident"], line["precise"]) == (False, True, True, False)
