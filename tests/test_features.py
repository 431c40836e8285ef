"""Feature extraction on synthetic images with known answers, and image -> features -> pose end to end."""

from __future__ import annotations

import time

import cv2
import numpy as np
import pytest

from benchmarks.problems import is_success, pose_errors
from evopose import PoseProblem, View, solve
from vision.features import (any_hue_ranges, colour_ranges, detect_colour_marks, detect_corners,
                              hue_of, match_to_truth, named_hue_ranges)
from geometry import angle_difference
from scenarios.render import render_frame
from scenarios.world import load_scenario

PALETTE = {"red": (30, 30, 220), "green": (40, 190, 40), "blue": (220, 90, 20), "yellow": (20, 220, 240),
           "pure-blue": (255, 0, 0)}
SHIFT = 4


def discs(centres, colours, radius=6.0, size=(480, 640), blur=0.0) -> np.ndarray:
    """Anti-aliased discs (1/16 px positions) of PALETTE colours on grey, optionally blurred (sigma, px)."""
    image = np.full((*size, 3), 110, np.uint8)
    for (u, v), name in zip(centres, colours):
        cv2.circle(image, (int(round(u * 16)), int(round(v * 16))), int(round(radius * 16)), PALETTE[name], -1,
                   cv2.LINE_AA, SHIFT)
    return cv2.GaussianBlur(image, (0, 0), blur) if blur else image


def test_subpixel_centroids_and_colour_labels():
    rng = np.random.default_rng(0)
    centres = np.column_stack([rng.uniform(30, 610, 12), rng.uniform(30, 450, 12)])
    centres[:, 0] = np.linspace(30, 610, 12) + rng.uniform(-0.5, 0.5, 12)  # well apart
    names = [list(PALETTE)[i % 4] for i in range(12)]
    det = detect_colour_marks(discs(centres, names), colour_ranges(PALETTE))
    pairs, dist = match_to_truth(det.points, centres, max_distance=1.0)
    assert len(det) == 12 and len(pairs) == 12
    assert dist.max() < 0.3  # binary moments of anti-aliased 6 px discs
    assert [det.colours()[i] for i, _ in pairs] == [names[j] for _, j in pairs]


def test_red_hue_band_wraps_through_zero():
    (red,) = colour_ranges({"red": PALETTE["red"]})
    assert hue_of(PALETTE["red"]) == 0 and red.hue_lo > red.hue_hi
    image = discs([(100.3, 200.7)], ["red"])
    image[300:310, 300:310] = (200, 30, 120)  # hue ~ 160 (magenta-ish): outside red's band
    det = detect_colour_marks(image, [red])
    assert len(det) == 1 and np.allclose(det.points[0], [100.3, 200.7], atol=0.1)


def test_filters_reject_specks_stripes_large_areas_and_border_blobs():
    image = discs([(320, 240)], ["green"])
    image[10:12, 100:102] = PALETTE["green"]              # speck: 4 px
    image[100:104, 200:260] = PALETTE["green"]            # stripe: 60 x 4
    image[300:460, 400:600] = PALETTE["green"]            # large surface
    cv2.circle(image, (0, 100), 6, PALETTE["green"], -1)  # cut by the border
    # min_area=6: the telephoto setting; by default (2) a 2 x 2 blob is a mark, as at the paper's image scale
    det = detect_colour_marks(image, colour_ranges(PALETTE), min_area=6, max_area=5000)
    assert len(det) == 1 and np.allclose(det.points[0], [320, 240], atol=0.05)
    assert len(detect_colour_marks(image, colour_ranges(PALETTE), min_area=6, max_area=5000, drop_border=False)) == 2
    assert [100.5, 10.5] in detect_colour_marks(image, colour_ranges(PALETTE), max_area=5000).points.tolist()


def test_dull_and_dark_pixels_are_not_marks():
    image = np.full((120, 160, 3), 100, np.uint8)
    cv2.circle(image, (50, 60), 6, (60, 80, 90), -1)       # dull brown: low saturation
    cv2.circle(image, (110, 60), 6, (0, 30, 35), -1)       # dark yellow: low value
    assert len(detect_colour_marks(image, colour_ranges(PALETTE))) == 0
    with pytest.raises(ValueError, match="BGR image"):
        detect_colour_marks(image[..., 0], colour_ranges(PALETTE))


def test_corners_of_a_chessboard():
    square, cols, rows = 40, 7, 5
    board = np.full(((rows + 1) * square + 80, (cols + 1) * square + 80), 255, np.uint8)
    for r in range(rows + 1):
        for c in range(cols + 1):
            if (r + c) % 2 == 0:
                board[40 + r * square:40 + (r + 1) * square, 40 + c * square:40 + (c + 1) * square] = 0
    board = cv2.GaussianBlur(board, (0, 0), 1.0)
    truth = np.array([(40 + c * square - 0.5, 40 + r * square - 0.5)
                      for r in range(1, rows + 1) for c in range(1, cols + 1)], float)
    corners = detect_corners(board, max_corners=100, quality=0.1, min_distance=10)
    pairs, dist = match_to_truth(corners, truth, max_distance=1.5)
    assert len(pairs) == len(truth) and np.median(dist) < 0.5


def test_extraction_speed_at_640x480():
    """>= 200 frames/s is measured by benchmarks/bench_features.py; here frames per CPU second, with a wide
    margin (the coverage-weighted centroids cost 2-3x the binary moments they replaced)."""
    scenario = load_scenario("exp2")
    image = render_frame(scenario, 2, "H1").image
    ranges = colour_ranges(scenario.model.palette)
    previous = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        detect_colour_marks(image, ranges)
        t0 = time.process_time()   # CPU time: other processes on the machine do not count
        for _ in range(100):
            detect_colour_marks(image, ranges)
        fps = 100 / (time.process_time() - t0)
    finally:
        cv2.setNumThreads(previous)
    assert fps > 50, fps


# -- the paper's image scale: marks 2-4 px across, 3-5 px apart ---------------------------------------

@pytest.mark.parametrize("blur", [0.0, 0.8])
def test_small_marks_subpixel_centroids(blur):
    """2.8 px discs: coverage-weighted centroids within a tenth of a pixel (binary moments: ~0.17 px median).

    Palette colours must differ in hue by more than their bands: (220, 90, 20) and (255, 0, 0), 11 hue units
    apart, would split one blurred disc between two colours."""
    rng = np.random.default_rng(3)
    centres = np.column_stack([np.linspace(20, 620, 40) + rng.uniform(-0.5, 0.5, 40), rng.uniform(20, 460, 40)])
    names = [["red", "green", "yellow", "pure-blue"][i % 4] for i in range(40)]   # hues over 2 bands apart
    det = detect_colour_marks(discs(centres, names, radius=1.4, blur=blur), colour_ranges(PALETTE))
    pairs, dist = match_to_truth(det.points, centres, max_distance=1.0)
    assert len(det) == len(pairs) == 40
    assert np.median(dist) < 0.1 and dist.max() < 0.3, (np.median(dist), dist.max())


@pytest.mark.parametrize("vehicle", ["H1", "H2"])
@pytest.mark.parametrize("clean", [True, False])
def test_paper_scale_frames_recall_and_centre_error(vehicle, clean):
    """exp2-paper-scale (the Pioneer ~25 px, marks 2-4 px): recall >= 90 % of the fully visible marks, median
    centre error <= 0.2 px on clean frames (0.07-0.10 measured), <= 0.35 px with noise, blur and distractors."""
    scenario = load_scenario("exp2-paper-scale")
    ranges = colour_ranges(scenario.model.palette)
    errors, found, total = [], 0, 0
    for frame_index in (0, 17, 34):
        frame = render_frame(scenario, frame_index, vehicle, clean=clean)
        truth = frame.truth
        whole = truth.mark_uv[truth.fully_visible]
        det = detect_colour_marks(frame.image, ranges)
        pairs, dist = match_to_truth(det.points, whole, max_distance=1.0)
        errors += dist.tolist()
        found, total = found + len(pairs), total + len(whole)
        expected = np.array(truth.mark_colour)[truth.fully_visible]
        assert all(det.colours()[i] == expected[j] for i, j in pairs)
    assert total >= 30 and found >= 0.9 * total, (found, total)
    assert np.median(errors) <= (0.2 if clean else 0.35), np.median(errors)


def test_pure_blue_marks_found_with_default_settings():
    """Without colours every saturated hue is searched: pure blue (hue 120) is outside a palette's blue band."""
    centres = [(100.3, 100.6), (300.7, 200.2), (500.1, 300.9)]
    image = discs(centres, ["pure-blue", "pure-blue", "yellow"], radius=5.0)
    small = discs([(200.4, 400.3)], ["pure-blue"], radius=1.4)
    image[380:420, 180:220] = small[380:420, 180:220]
    det = detect_colour_marks(image)
    pairs, dist = match_to_truth(det.points, centres + [(200.4, 400.3)], max_distance=0.5)
    assert len(det) == len(pairs) == 4, det
    assert sorted(det.colours()) == ["blue", "blue", "blue", "yellow"]
    assert len(detect_colour_marks(image, colour_ranges({"blue": PALETTE["blue"]}))) == 0   # the old default's band


def test_touching_marks_split_or_flagged():
    # two marks of one colour 4 px apart, 2.8 px across, blurred: one component, split at its two peaks
    centres = np.array([(100.3, 100.4), (104.3, 100.9)])
    det = detect_colour_marks(discs(centres, ["yellow", "yellow"], radius=1.4, blur=0.8, size=(200, 200)))
    pairs, dist = match_to_truth(det.points, centres, max_distance=0.5)
    assert len(det) == len(pairs) == 2 and det.touching.all(), det
    # two colours 3 px apart: separate components, flagged as touching
    centres = np.array([(50.2, 60.7), (52.3, 62.8)])
    det = detect_colour_marks(discs(centres, ["yellow", "pure-blue"], radius=1.4, size=(200, 200)))
    pairs, dist = match_to_truth(det.points, centres, max_distance=0.6)
    assert len(det) == len(pairs) == 2 and det.touching.all(), det
    # an isolated mark is not flagged
    assert not detect_colour_marks(discs([(80.5, 80.5)], ["green"], radius=1.4, size=(200, 200))).touching.any()


def test_colour_filter_narrows_the_search():
    centres = [(100.5, 100.5), (200.5, 100.5), (300.5, 100.5), (400.5, 100.5)]
    image = discs(centres, ["red", "green", "pure-blue", "yellow"], radius=3.0)
    assert sorted(detect_colour_marks(image).colours()) == ["blue", "green", "red", "yellow"]
    blue = detect_colour_marks(image, ["blue"])                       # named hues
    assert blue.colours() == ["blue"] and np.allclose(blue.points, [centres[2]], atol=0.1)
    mine = detect_colour_marks(image, {"mine": PALETTE["yellow"]})    # a palette: name -> BGR
    assert mine.colours() == ["mine"] and np.allclose(mine.points, [centres[3]], atol=0.1)
    assert len(detect_colour_marks(image, named_hue_ranges(["red", "green"]))) == 2
    with pytest.raises(ValueError, match="unknown colour"):
        named_hue_ranges(["purple-ish"])
    modes = any_hue_ranges(image)
    assert [r.name for r in modes] == ["red", "yellow", "green", "blue"]


@pytest.mark.parametrize("scenario_name, strays", [("exp2", 0), ("exp2-paper-scale", 2)])
def test_any_hue_leaves_out_the_robots_body_and_mark_fringes(scenario_name, strays):
    """The Pioneer's body is saturated red: searched for any hue it is a candidate, but one that encloses
    marks (a painted surface); a green mark's fringe on it reads yellow (a blend). Neither is a mark.
    At 25 px the body can break into pieces between the marks and a 2 px fringe is hard to call: a few
    strays are left (a palette avoids both; see benchmarks/results/features.md)."""
    scenario = load_scenario(scenario_name)
    for vehicle in ("H1", "H2"):
        frame = render_frame(scenario, 10, vehicle, clean=True)
        truth = frame.truth
        det = detect_colour_marks(frame.image)
        whole = truth.mark_uv[truth.fully_visible]
        found, _ = match_to_truth(det.points, whole, max_distance=1.0)
        near, _ = match_to_truth(det.points, truth.mark_uv, max_distance=3.0)
        assert len(found) == len(whole) and len(det) - len(near) <= strays, (vehicle, len(found), len(whole), len(det))


# -- image -> features -> pose ------------------------------------------------------------------------

def image_views(scenario, frame: int, vehicles) -> list[View]:
    ranges = colour_ranges(scenario.model.palette)
    views = []
    for vehicle in vehicles:
        rendered = render_frame(scenario, frame, vehicle)
        views.append(View(rendered.camera, detect_colour_marks(rendered.image, ranges).points))
    return views


def assert_recovers(scenario, frame: int, vehicles, problem_bounds=None):
    views = image_views(scenario, frame, vehicles)
    model = scenario.model.evopose_model()
    truth = scenario.target_pose(frame)
    problem = PoseProblem(model, tuple(views), problem_bounds or scenario.bounds())
    solution = solve(problem, seed=frame)
    rot, pos = pose_errors(solution.pose, truth, [np.eye(3)], model.points.mean(axis=0))
    distance = min(np.linalg.norm(truth[:3] - v.camera.center_world) for v in views)
    assert is_success(rot, pos, distance), (vehicles, frame, np.rad2deg(rot), pos, distance)
    return solution, rot, pos


@pytest.mark.parametrize("vehicles", [["H1"], ["H2"], ["H1", "H2"]])
@pytest.mark.parametrize("frame", [4, 23])
def test_exp2_image_to_pose(vehicles, frame):
    scenario = load_scenario("exp2")
    _, rot, pos = assert_recovers(scenario, frame, vehicles)
    if len(vehicles) == 2:  # two viewpoints fix the depth (paper Table II, H1 + H2)
        assert pos < 0.05


@pytest.mark.parametrize("frame", [2, 31])
def test_exp1_image_to_pose_roll_is_the_hard_part(frame):
    """Plain EvoPose on the airship (paper Table I): position and heading are found; roll, seen only
    through marks in rows along the roll axis, is the least certain angle."""
    scenario = load_scenario("exp1-airship")
    views = image_views(scenario, frame, [None])
    model = scenario.model.evopose_model()
    truth = scenario.target_pose(frame)
    solution = solve(PoseProblem(model, tuple(views), scenario.bounds()), seed=frame)
    rot, pos = pose_errors(solution.pose, truth, [np.eye(3)], model.points.mean(axis=0))
    distance = np.linalg.norm(truth[:3] - views[0].camera.center_world)
    assert pos < 0.05 * distance and rot < np.deg2rad(10), (np.rad2deg(rot), pos)
    assert abs(angle_difference(solution.pose[5], truth[5])) < np.deg2rad(3)  # yaw
    assert abs(angle_difference(solution.pose[4], truth[4])) < np.deg2rad(3)  # pitch


@pytest.mark.parametrize("frame", [2, 31, 60])
def test_exp1_imu_constraint_recovers_the_pose(frame):
    """EvoPose+IMU (paper Table I): roll, pitch and yaw searched within the IMU's reading +- its error."""
    scenario = load_scenario("exp1-airship")
    imu_rpy = render_frame(scenario, frame, clean=True).truth.sensors["imu_rpy"]
    bounds = scenario.bounds()
    for i, name in enumerate(("roll", "pitch", "yaw")):
        bounds = bounds.constrained(name, float(imu_rpy[i]), np.deg2rad(2.5))
    solution, rot, _ = assert_recovers(scenario, frame, [None], bounds)
    assert np.all(np.abs(angle_difference(solution.pose[3:], imu_rpy)) <= np.deg2rad(2.5) + 1e-9)
    # the constraint bounds each angle to +-2.5 deg of the reading, which is itself ~0.7 deg off (the IMU's bias):
    # the rotation error is bounded by that box (the image picks the pose inside it; frame 31: 3.7 deg with the
    # default mutual fitness, 0.02 deg with the robust one)
    truth_in_reading = np.abs(angle_difference(scenario.target_pose(frame)[3:], imu_rpy))
    assert rot <= np.linalg.norm(np.deg2rad(2.5) + truth_in_reading)
