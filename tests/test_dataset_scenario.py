"""`evopose scenario run NAME --dataset DIR`: a fleet scenario's camera vehicles play a rendered dataset (each its
camera's folder, on the dataset's world and frames, on the fleet clock), with the usual tables and JSON; a vehicle
without a camera folder, a malformed dataset or conflicting options: one line and exit 2."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from agents.cli.main import main
from agents.runs import pose_rows
from tests.fleet_procs import ROOT, free_port
from tests.test_dataset import write_dataset

FRAMES = 10


@pytest.fixture(scope="module")
def datasets(tmp_path_factory):
    """exp2's first frames seen by H1 and H2 (`evopose render --engine opencv`: the renderer, then the default
    camera model, JPEG 4:2:0), and by H1 only (the DatasetWriter on the renderer's frames)."""
    folder = tmp_path_factory.mktemp("dataset_scenario")
    done = subprocess.run([sys.executable, "-m", "agents.cli", "render", "exp2", "--out", str(folder / "both"),
                           "--engine", "opencv", "--frames", str(FRAMES)], cwd=ROOT, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    return folder / "both", write_dataset(folder / "h1", frames=3, cameras=["H1"])


def test_a_fleet_scenario_runs_on_a_dataset(datasets):
    both, _ = datasets
    # the hue bands, which these drawings were made for: the pair then ends each search on the same generation and
    # publishes bit-equal poses (with auto's contrast front-end the time-sliced searches stop apart: the Cycles pair
    # test below asks for the same pose within 1 cm and 0.5 deg there)
    done = subprocess.run([sys.executable, "-m", "agents.cli", "scenario", "run", "exp2a-features", "--dataset",
                           str(both), "--features", "marks", "--listen", f"tcp/127.0.0.1:{free_port()}", "--json"],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    result = json.loads(done.stdout.splitlines()[-1])
    assert result["scenario"] == "exp2a-features" and result["dataset"] == str(both)
    (run,) = result["runs"]
    assert run["dataset"] == str(both) and run["world"] == "exp2" and not run["slow"]
    for vehicle in ("H1", "H2"):
        summary = run["agents"][vehicle]
        assert summary["dataset_camera"] == vehicle and summary["dataset"] == str(both)
        assert summary["frames"] == FRAMES and summary["good"] > 0 and summary["target_visible"]
        assert math.isfinite(summary["error_position"])  # the dataset's truth
    assert "dataset" not in run["agents"]["pioneer"]  # the target publishes its true pose from the world
    rows = {r["vehicle"]: r for r in result["rows"]}
    assert set(rows) == {"H1", "H2"} and all(math.isfinite(r["x"]) and r["good_fraction"] > 0 for r in rows.values())
    # features: both search both images, so both publish the same pose on the frames they pair
    h1 = {row.frame: row.pose for row in pose_rows(run["agents"]["H1"])}
    h2 = {row.frame: row.pose for row in pose_rows(run["agents"]["H2"])}
    assert sum(h1[k] == h2[k] for k in h1.keys() & h2.keys()) >= FRAMES // 2


def run_error(capfd, *args: str) -> str:
    code = main(["scenario", "run", *args, "--listen", f"tcp/127.0.0.1:{free_port()}"])
    err = capfd.readouterr().err
    lines = err.splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in err, err
    return lines[0]


def test_a_vehicle_without_its_camera_or_a_bad_dataset_is_one_line_and_exit_2(capfd, datasets, tmp_path):
    both, h1 = datasets
    line = run_error(capfd, "exp2a-features", "--dataset", str(h1))
    assert "vehicle H2 of exp2a-features (variant H1+H2) has no camera folder in the dataset (cameras: H1)" in line
    assert "the dataset has 10 frames, not 11" in run_error(capfd, "exp2a-features", "--dataset", str(both),
                                                            "--frames", "11")
    assert "a dataset has its own world" in run_error(capfd, "exp2a-features", "--dataset", str(both), "--world",
                                                      "exp2-paper-scale")
    assert "not a dataset directory (no manifest.yaml)" in run_error(capfd, "exp2-solo", "--dataset", str(tmp_path))
    manifest = yaml.safe_load((h1 / "manifest.yaml").read_text())
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "manifest.yaml").write_text(yaml.safe_dump({**manifest, "fps": "fast"}))
    assert "manifest.yaml: fps: expected a number" in run_error(capfd, "exp2-solo", "--dataset", str(broken))
    assert Path(h1 / "world.yaml").is_file()


@pytest.mark.parametrize("scale", ["paper", "telephoto", "telephoto-agx", "telephoto-flat-cool", "rover-telephoto"])
def test_two_helicopters_on_the_committed_cycles_frames_stay_within_a_right_poses_accuracy_and_no_good_pose_is_wrong(
        scale):
    # Blender Cycles frames (tests/data/photoreal, docs/datasets.md), the contrast front-end, feature sets shared
    # (eq. 4): on every frame the two publish poses within the accuracy of a right pose at that scale of each other
    # (not the same pose: see below), and a pose either calls good is within the bar (0.5 m, 5 deg). That
    # they publish the same pose (1 cm and 0.1 deg, agents.experiments.results.frame_agreement) is a measurement,
    # not this test's claim: benchmarks/bench_photoreal_fleet.py's "same pose" column and the report's agreement
    # table. Why not here: a dataset source plays one frame per frame processed, so a vehicle that ran late takes a
    # frame at a later tick than its team-mate; the views are paired by instant, but the best pose each sends with
    # its feature set is its own at the tick it sent it, so while a search from scratch is in progress the two
    # weigh different candidates and stop their slices at different bests
    from geometry import pose_error
    from scenarios.dataset import open_dataset

    # at the paper's scale the 16-frame sequence: a search from scratch takes ~22 generations there, 4 a frame, and
    # may end in a wrong basin, unsure (3 of 10 seeds on its first frame, whose features mislead it), so the pair
    # needs a second search before it is good (frame 7 in process); 4 frames only showed whether the first won
    # telephoto-agx and telephoto-flat-cool: the g2 world (not the one the telephoto rules were chosen on) through
    # AgX and a cold, flat, dark JPEG-50 camera (scenarios/looks.py; BENCHMARKS.md says which looks were seen),
    # with the agents' default front-end (--features auto: the contrast front-end on a dataset's camera images)
    # rover-telephoto: a robot no rule was chosen on (examples/your-robot, written as a lab would), its 4 frames
    folder = ROOT / "tests" / "data" / "photoreal" / ("paper-sequence" if scale == "paper" else scale)
    chosen = ["--features", "contrast"] if scale in ("paper", "telephoto") else []
    done = subprocess.run([sys.executable, "-m", "agents.cli", "scenario", "run", "exp2a-features", "--dataset",
                           str(folder), *chosen, "--listen", f"tcp/127.0.0.1:{free_port()}",
                           "--json"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    (run,) = json.loads(done.stdout.splitlines()[-1])["runs"]
    data = open_dataset(folder)
    # a source plays its frames in order, one per frame processed: each vehicle publishes a pose of every frame of
    # the dataset, at the tick it got to it (a late vehicle at a later tick than its team-mate): pair by that frame
    rows = {v: {r.scene_frame: r for r in pose_rows(run["agents"][v])} for v in ("H1", "H2")}
    assert all(sorted(rows[v]) == list(range(data.frames)) for v in rows), rows
    # each searches both images (eq. 4), each frame paired with the team-mate's view of the same instant even when
    # one ran late: on every frame they publish the same pose up to where each one's search stopped in its own
    # time slices, i.e. within the accuracy a right pose has at that scale (measured on two loaded cores: telephoto
    # up to 0.5 mm and 0.2 deg apart, each 0.2 deg from the truth; paper scale up to 1.5 cm and 1.9 deg apart, each
    # up to 3.6 deg from the truth, which is the bar below for the last pose: 10 cm, 5 deg)
    same_m, same_deg = (0.01, 0.5) if "telephoto" in scale else (0.1, 5.0)
    for k in range(data.frames):
        apart = pose_error(np.array(rows["H1"][k].pose), np.array(rows["H2"][k].pose))
        assert apart["position"] <= same_m and max(apart[a] for a in ("roll", "pitch", "yaw")) <= same_deg, (k, apart)
    for vehicle in ("H1", "H2"):
        published = [rows[vehicle][k] for k in range(data.frames)]
        good = [(i, r) for i, r in enumerate(published) if r.good]
        for i, r in good:
            error = pose_error(np.array(r.pose), data.truth(i).target_pose)
            assert error["position"] <= 0.5 and max(error[a] for a in ("roll", "pitch", "yaw")) <= 5.0, (i, error)
        # at ~150 px the pair confirms a pose within the dataset's 4 frames; at the paper's scale within its 16
        # (9 of 16 good, from frame 7, measured)
        assert good, vehicle
        # the last published pose, good or not, is right: within 10 cm and 5 deg (the paper's scale: 1.5 cm, 1.6 deg,
        # and good, when the search has finished)
        last = pose_error(np.array(published[-1].pose), data.truth(len(published) - 1).target_pose)
        assert last["position"] <= 0.1 and max(last[a] for a in ("roll", "pitch", "yaw")) <= 5.0, (vehicle, last)
