"""The report's team-size table (issue 13) from run records shaped like `evopose scenario run`'s: per UAV the
costs (CPU per frame, bytes/s sent and received) worked out by hand, H1's error, and agreement with H1."""

from __future__ import annotations

from agents.experiments.report import TEAM_SIZE, _team_size_lines
from agents.experiments.results import rows


def summary(vehicle: str, share: str, *, position: float, poses: list[list], sent: int, received: int) -> dict:
    """An agent summary of 10 frames at 2 fps that ran 4 s (late start): 2 s of process CPU, 0.5 s of it rendering."""
    return {"role": "uav", "share": share, "vehicle": vehicle, "frames": 10, "estimates": 10, "good": 10, "fps": 2.0,
            "run_s": 4.0, "cpu_s": 2.0, "render_cpu_s": 0.5, "error_position": position, "error_yaw": 0.5,
            "poses": poses, "traffic": {"sent": {"pose": 10}, "bytes_sent": {"pose": sent},
                                        "received": {"features": 10}, "bytes_received": {"features": received}}}


def test_team_size_table_from_run_records():
    pose = [0.0, 1.0, 2.0, 0.1, 0.0, 0.0]
    same = [[n, *pose, True] for n in range(10)]
    moved = [[n, pose[0] + (0.05 if n < 5 else 0.0), *pose[1:], True] for n in range(10)]  # 5 cm off on 5 frames
    records = [
        {"scenario": TEAM_SIZE, "variant": "1-alone", "run": 0, "agents": {
            "H1": summary("H1", "none", position=0.09, poses=same, sent=3000, received=0)}},
        {"scenario": TEAM_SIZE, "variant": "2-features", "run": 0, "agents": {
            "H1": summary("H1", "features", position=0.003, poses=same, sent=5000, received=2000),
            "H2": summary("H2", "features", position=0.005, poses=moved, sent=6000, received=4000),
            "pioneer": {"role": "target", "share": "none"}}},
    ]
    header, rule, alone, pair = _team_size_lines(records, rows(records))
    assert header.startswith("| share | UAVs |") and rule.count("|") == header.count("|")
    cells = [c.strip() for c in pair.strip("|").split("|")]
    # 2 s of CPU over 10 frames: 200 ms a frame, 50 of it rendering; bytes over the 4 s run, mean of the two UAVs
    assert cells == ["features", "2", "100%", "0.3 (0.0)", "0.4 (0.5)", "0.50 (0.50)", "50% (worst pair)",
                     "200 (50)", "1,375", "750"], cells
    assert [c.strip() for c in alone.strip("|").split("|")][:7] == ["none", "1", "100%", "9.0 (0.0)", "9.0 (9.0)",
                                                                    "0.50 (0.50)", "-"]


def test_above_paper_names_each_cell_over_the_papers_table_ii_and_a_row_without_a_good_pose():
    from agents.experiments.paper_tables import PAPER_TABLE_II, above_paper

    def row(scenario: str, vehicle: str, **errors: float) -> dict:
        base = {"roll": 0.01, "pitch": 0.01, "yaw": 0.01, "x": 0.001, "y": 0.001, "z": 0.001}
        return {"scenario": scenario, "vehicle": vehicle, "world": "w", **base, **errors}

    result_rows = [row("exp2-solo", "H1"), row("exp2-solo", "H2", pitch=4.05),
                   row("exp2a-features", "H1", z=PAPER_TABLE_II["H1 + H2"][5][0] + 0.06),
                   row("exp2b-hints", "H1", roll=float("nan")), row("exp2b-hints", "H2"),
                   row("exp2-solo", "H2", pitch=99.0) | {"world": "other"}]
    assert above_paper(result_rows, "w") == ["H2 pitch 4.05 > 1 deg", "H1 + H2 z 0.96 > 0.9 m",
                                             "H1 + hint roll: no good pose"]
    assert above_paper(result_rows[:1], "w") == []
