"""Scenario and model files, trajectories, camera rigs and sensors of the simulated world."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from evopose.trust import ConfidenceRules
from geometry import rotation_from_euler
from scenarios.errors import FrameError, ModelFileError, ScenarioError, WorldError
from scenarios.sensors import GpsModel, ImuModel
from scenarios.target import MODELS_DIR, load_model
from scenarios.trajectory import Trajectory, look_at_rotation
from scenarios.world import SCENARIOS_DIR, load_scenario


def test_shipped_models_have_the_papers_dimensions():
    pioneer, airship = load_model("pioneer"), load_model(MODELS_DIR / "airship.yaml")
    extent = np.ptp(pioneer.body.vertices, axis=0)
    np.testing.assert_allclose(extent, [0.44, 0.38, 0.22], atol=1e-9)
    x = airship.body.vertices[:, 0]
    assert x.max() == pytest.approx(0.925) and x.min() == pytest.approx(-0.98)  # 1.85 m hull, fins behind it
    for model in (pioneer, airship):
        assert len(model.mark_points) >= 15
        np.testing.assert_allclose(np.linalg.norm(model.mark_normals, axis=1), 1.0)
        assert set(model.mark_colours) <= set(model.palette)
        assert model.evopose_model().points.shape == model.mark_points.shape


def test_airship_marks_lie_along_the_long_axis():
    """Roll is hard to see: the marks spread far more along x (the roll axis) than around it."""
    marks = load_model("airship").mark_points
    assert np.ptp(marks[:, 0]) > 3 * np.ptp(marks[:, 2])


def test_pioneer_marks_have_no_symmetry():
    """No half turn about z maps the mark layout onto itself (the pose is unique)."""
    m = load_model("pioneer").mark_points
    for yaw in (np.pi / 2, np.pi, -np.pi / 2):
        R = rotation_from_euler(np.array([0, 0, yaw]))
        moved = m @ R.T
        d = np.linalg.norm(moved[:, None] - m[None], axis=2).min(axis=1)
        assert d.max() > 0.05


def test_shipped_scenarios_have_the_papers_geometry():
    exp1, exp2 = load_scenario("exp1-airship"), load_scenario(SCENARIOS_DIR / "exp2.yaml")
    cam = exp1.camera(None, 0)
    assert 4.5 < np.linalg.norm(exp1.target_pose(0)[:3] - cam.center_world) < 5.5
    assert exp1.target_imu is not None and exp1.vehicles[0].role == "ground-station"
    ranges = {v.name: np.linalg.norm(exp2.camera(v.name, 0).center_world - exp2.target_pose(0)[:3])
              for v in exp2.vehicles}
    assert abs(ranges["H1"] - 30) < 1.5 and abs(ranges["H2"] - 20) < 1.5
    heights = [exp2.camera(v.name, 0).center_world[2] for v in exp2.vehicles]
    assert abs(heights[0] - heights[1]) > 1  # varied altitudes


def test_look_at_puts_the_target_in_the_image_centre():
    exp2 = load_scenario("exp2")
    for v in exp2.vehicles:
        cam = exp2.camera(v.name, 3)
        uv, front = cam.project_world(np.array(v.camera.look_at)[None])
        assert front[0] and np.allclose(uv[0], [cam.cx, cam.cy], atol=1e-6)
    R = look_at_rotation(np.zeros(3), np.array([1.0, 0, 0]))
    np.testing.assert_allclose(R, [[0, 0, 1], [-1, 0, 0], [0, -1, 0]], atol=1e-12)  # x right, y down


def test_trajectories_move_and_sway():
    static = Trajectory(np.array([1.0, 2, 3, 0, 0, 0.5]))
    assert static.is_static and np.array_equal(static.pose(7.0), static.pose(0.0))
    moving = Trajectory(np.zeros(6), rate=np.array([0.5, 0, 0, 0, 0, 0.1]))
    np.testing.assert_allclose(moving.pose(2.0), [1.0, 0, 0, 0, 0, 0.2])
    hover = Trajectory(np.zeros(6), sway=np.array([0.3, 0, 0, 0, 0, 0]), period=4.0)
    xs = [hover.pose(t)[0] for t in np.linspace(0, 4, 81)]
    assert max(xs) == pytest.approx(0.3, abs=1e-3) and min(xs) == pytest.approx(-0.3, abs=1e-3)
    exp2 = load_scenario("exp2")
    assert not np.allclose(exp2.camera("H1", 0).center_world, exp2.camera("H1", 20).center_world)


def test_imu_bias_and_noise_have_the_mt9_magnitudes():
    imu = ImuModel(np.deg2rad(0.7), np.deg2rad(0.1))
    truth = np.array([0.1, -0.2, 1.0])
    biases = np.array([imu.bias(seed, 1) for seed in range(400)])
    assert np.rad2deg(biases.std()) == pytest.approx(0.7, rel=0.15)
    readings = np.array([imu.read(truth, 3, 1, frame) for frame in range(400)])
    errors = readings - truth
    np.testing.assert_allclose(errors.mean(axis=0), imu.bias(3, 1), atol=np.deg2rad(0.03))  # constant per run
    assert np.rad2deg(errors.std(axis=0)) == pytest.approx([0.1] * 3, rel=0.15)
    np.testing.assert_array_equal(imu.read(truth, 3, 1, 17), imu.read(truth, 3, 1, 17))
    assert not np.array_equal(imu.read(truth, 3, 1, 17), imu.read(truth, 4, 1, 17))


def test_gps_outage_and_degradation():
    gps = GpsModel(1.5, degraded=((10.0, 20.0, 5.0),), outages=((30.0, 35.0),))
    truth = np.array([5.0, 6.0, 7.0])
    assert gps.read(truth, 31.0, 0, 2, 310) is None
    assert gps.read(truth, 35.0, 0, 2, 350) is not None
    normal = np.array([gps.read(truth, 1.0, 0, 2, f) - truth for f in range(300)])
    degraded = np.array([gps.read(truth, 15.0, 0, 2, f) - truth for f in range(300)])
    assert normal.std() == pytest.approx(1.5, rel=0.15)
    assert degraded.std() == pytest.approx(7.5, rel=0.15)


def test_scenario_sensors_in_truth_match_the_file():
    exp1 = load_scenario("exp1-airship")
    from scenarios.render import render_frame
    truth = render_frame(exp1, 4, clean=True).truth
    err = np.rad2deg(np.abs(truth.sensors["imu_rpy"] - exp1.target_pose(4)[3:]))
    assert 0 < err.max() < 4


def _write(tmp_path: Path, document: dict) -> Path:
    path = tmp_path / "scenario.yaml"
    path.write_text(yaml.safe_dump(document), encoding="utf-8")
    return path


def _exp2() -> dict:
    document = yaml.safe_load((SCENARIOS_DIR / "exp2.yaml").read_text(encoding="utf-8"))
    document["target"]["model"] = str(MODELS_DIR / "pioneer.yaml")
    return document


@pytest.mark.parametrize("edit, expected", [
    (lambda d: d.update(extra_option=1), "extra_option: unknown key"),
    (lambda d: d["vehicles"][1].update(share="raw"), "vehicles[1].share: unknown key"),
    (lambda d: d["vehicles"][0]["camera"]["intrinsics"].update(fx=-5), "vehicles[0].camera.intrinsics.fx"),
    (lambda d: d["vehicles"][0].update(role="submarine"), "vehicles[0].role"),
    (lambda d: d["vehicles"][1].update(name="H1"), "repeated: ['H1']"),
    (lambda d: d["target"].update(model="no/such/model.yaml"), "target.model"),
    (lambda d: d.pop("vehicles"), "vehicles: required field missing"),
    (lambda d: d["render"].update(noise_sigma="loud"), "render.noise_sigma"),
    (lambda d: d["search"].update(z=[1, -1]), "z: lo 1"),
])
def test_malformed_scenarios_name_the_field(tmp_path, edit, expected):
    document = _exp2()
    edit(document)
    with pytest.raises(ScenarioError) as info:
        load_scenario(_write(tmp_path, document))
    message = str(info.value)
    assert expected in message and "\n" not in message and "scenario.yaml" in message


def test_malformed_model_file(tmp_path):
    path = tmp_path / "model.yaml"
    path.write_text("name: x\nmark_radius: 0.02\ncolours: {red: [0, 0, 255]}\n"
                    "marks: [{position: [0, 0, 0], normal: [0, 0, 1], colour: blue}]\n", encoding="utf-8")
    with pytest.raises(ModelFileError, match="unknown colour 'blue'"):
        load_model(path)
    path.write_text("name: x\nname: y\n", encoding="utf-8")
    with pytest.raises(ModelFileError, match="duplicate key"):
        load_model(path)
    for line, field in (("motion: {speed: 0.5, climb: 0.05, tilt: -1, turn: 0.5}", "motion.tilt"),
                        ("good_within: {rotation_deg: 0}", "good_within.rotation_deg")):
        path.write_text("name: x\nmark_radius: 0.02\ncolours: {red: [0, 0, 255]}\n"
                        f"marks: [{{position: [0, 0, 0], normal: [0, 0, 1], colour: red}}]\n{line}\n", encoding="utf-8")
        with pytest.raises(ModelFileError) as info:
            load_model(path)
        assert field in str(info.value) and "\n" not in str(info.value)


def test_the_pioneers_motion_sets_the_tracking_gate_per_frame():
    """The model file's 1-sigma rates times the frame period: the Pioneer drives and turns, it does not tilt."""
    rules = load_model("pioneer").confidence_rules(0.1)
    np.testing.assert_allclose(rules.track_motion, [0.05, 0.05, 0.005, 0.005, 0.005, 0.05])
    np.testing.assert_allclose(load_model("pioneer").confidence_rules(0.5).track_motion[5], 0.25)
    assert load_model("airship").confidence_rules(0.1) == ConfidenceRules()  # no motion in its file: the defaults


def test_the_pioneers_file_says_a_good_pose_lies_within_five_degrees_at_two_sigmas():
    # its published track is good once it knows its rotation to 2.5 deg; the airship's file says nothing, so any
    # track a precise frame joined is good (its single frames know their pitch to ~4.5 deg, their error 0.1 deg)
    assert np.degrees(load_model("pioneer").confidence_rules(0.1).max_published_rotation_sigma) == pytest.approx(2.5)
    assert load_model("airship").confidence_rules(0.1).max_published_rotation_sigma == float("inf")


def test_frame_and_vehicle_out_of_range():
    exp2 = load_scenario("exp2")
    with pytest.raises(FrameError, match="frame 50 out of range"):
        exp2.camera("H1", 50)
    with pytest.raises(FrameError, match="no vehicle 'H3'"):
        exp2.camera("H3", 0)
    assert issubclass(FrameError, WorldError)
