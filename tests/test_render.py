"""The renderer: deterministic frames, exact ground truth, visibility, nuisances."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from vision.features import colour_ranges, detect_colour_marks, match_to_truth
from geometry import matrix_from_pose
from scenarios.render import render_frame
from scenarios.world import OccluderSpec, load_scenario


@pytest.fixture(scope="module")
def exp1():
    return load_scenario("exp1-airship")


@pytest.fixture(scope="module")
def exp2():
    return load_scenario("exp2")


def test_rendering_is_deterministic_for_a_seed_in_any_order(exp2):
    later = render_frame(exp2, 9, "H2").image
    first = render_frame(exp2, 3, "H2").image
    again = [render_frame(exp2, k, "H2").image for k in (9, 3)]
    assert np.array_equal(later, again[0]) and np.array_equal(first, again[1])
    assert not np.array_equal(first, later)
    reseeded = dataclasses.replace(exp2, spec=exp2.spec.model_copy(update={"seed": exp2.seed + 1}))
    assert not np.array_equal(render_frame(reseeded, 3, "H2").image, first)


def test_image_has_the_camera_resolution(exp1, exp2):
    for scenario, vehicle in ((exp1, None), (exp2, "H1")):
        frame = render_frame(scenario, 0, vehicle)
        k = frame.camera
        assert frame.image.shape == (k.height, k.width, 3) and frame.image.dtype == np.uint8


def test_truth_is_the_projection_of_the_visible_marks(exp2):
    frame = render_frame(exp2, 6, "H1", clean=True)
    truth = frame.truth
    T = matrix_from_pose(exp2.target_pose(6))
    pts = exp2.model.mark_points @ T[:3, :3].T + T[:3, 3]
    uv, _ = frame.camera.project_world(pts[truth.mark_index])
    np.testing.assert_allclose(truth.mark_uv, uv, atol=1e-9)
    normals = exp2.model.mark_normals @ T[:3, :3].T
    towards = frame.camera.center_world - pts
    facing = np.sum(normals * towards, axis=1) > 0
    assert set(truth.mark_index) <= set(np.nonzero(facing)[0])   # back-facing marks are never in the truth
    assert 6 <= len(truth.mark_index) < len(pts)
    np.testing.assert_array_equal(truth.target_pose, exp2.target_pose(6))
    d = truth.to_dict()
    assert d["marks"][0]["index"] == truth.mark_index[0] and d["vehicle"] == "H1"


@pytest.mark.parametrize("scenario_name, vehicle", [("exp1-airship", None), ("exp2", "H1"), ("exp2", "H2")])
def test_clean_frames_detected_within_1px_with_full_recall(scenario_name, vehicle):
    scenario = load_scenario(scenario_name)
    ranges = colour_ranges(scenario.model.palette)
    for frame_index in (0, 13, 27):
        frame = render_frame(scenario, frame_index, vehicle, clean=True)
        truth = frame.truth
        whole = truth.mark_uv[truth.fully_visible]
        det = detect_colour_marks(frame.image, ranges)
        pairs, dist = match_to_truth(det.points, whole, max_distance=1.0)
        assert len(pairs) == len(whole) >= 6, (frame_index, len(pairs), len(whole))
        assert len(det) == len(truth.mark_uv)  # and nothing else
        # the detected colour is the mark's colour
        colours = det.colours()
        expected = np.array(truth.mark_colour)[truth.fully_visible]
        assert all(colours[i] == expected[j] for i, j in pairs)


def test_an_occluder_hides_marks_in_the_truth_and_in_the_image(exp2):
    frame = render_frame(exp2, 0, "H1", clean=True)
    cam = frame.camera
    # a box on the line of sight, half way to the target
    centre = 0.5 * (cam.center_world + exp2.target_pose(0)[:3]) + [0, 0, 0.1]
    blocker = OccluderSpec(centre=centre.tolist(), size=[0.5, 0.5, 0.5], colour=[100, 100, 100])
    spec = exp2.spec.model_copy(update={"render": exp2.spec.render.model_copy(
        update={"occluders": [blocker], "distractors": exp2.spec.render.distractors.model_copy(update={"count": 0}),
                "noise_sigma": 0.0, "blur_sigma": 0.0})})
    hidden = render_frame(dataclasses.replace(exp2, spec=spec), 0, "H1")
    assert len(hidden.truth.mark_index) < len(frame.truth.mark_index)
    det = detect_colour_marks(hidden.image, colour_ranges(exp2.model.palette))
    assert len(det) <= len(hidden.truth.mark_index)


def test_self_occlusion_by_the_wheels_and_fins():
    """Partly hidden marks are flagged; their visible centre is still in the truth."""
    exp1 = load_scenario("exp1-airship")
    counts = [render_frame(exp1, k, clean=True).truth for k in range(0, 100, 10)]
    assert all(len(t.mark_index) >= 6 for t in counts)


def test_nuisances_add_distractors_noise_and_lighting(exp2):
    clean = render_frame(exp2, 5, "H2", clean=True)
    noisy = render_frame(exp2, 5, "H2")
    assert len(noisy.truth.distractor_uv) == exp2.render.distractors.count
    assert len(clean.truth.distractor_uv) == 0
    diff = noisy.image.astype(float) - clean.image.astype(float)
    assert diff.std() > 2
    det = detect_colour_marks(noisy.image, colour_ranges(exp2.model.palette))
    found, _ = match_to_truth(det.points, noisy.truth.distractor_uv, max_distance=3)
    assert len(found) >= 1  # distractors look like marks to the detector
    gains = [render_frame(exp2, k, "H2").image.mean() for k in (0, 15, 30)]
    assert np.ptp(gains) > 3  # the lighting changes over time
