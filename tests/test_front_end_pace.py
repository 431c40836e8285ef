"""The contrast front-end keeps a camera's rate: halved where the target is large and full-resolution frames overrun
(vision/front_end_pace.py), back at full resolution when the halved frames leave room."""

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from scenarios.dataset import open_dataset
from vision.blobs import ContrastMarks
from vision.extract import feature_extractor
from vision.features import match_to_truth
from vision.front_end_pace import FRONT_END_SHARE, FULL_OVER_HALVED, RECENT, RETURN_SHARE, FrontEndPace, \
    detect_halved, largest_mark_px, placed_at_full
from vision.mark_prior import MarkPrior
from tests.fleet_procs import ROOT, free_port

DATA = Path(__file__).parent / "data" / "photoreal"
LARGE = MarkPrior((3.0, 14.0), 480.0)   # the second robot at telephoto: its scale space is built halved
SMALL = MarkPrior((2.5, 12.0), 210.0)   # the Pioneer at telephoto: never halved


def _at_full(period_s: float = 0.1) -> FrontEndPace:
    """A pace whose halved frames left room for full resolution: at full resolution."""
    pace = FrontEndPace(period_s)
    for _ in range(RECENT):
        pace.timed(RETURN_SHARE * period_s / FULL_OVER_HALVED * 0.8, True)
    assert not pace.halve(LARGE)
    return pace


def test_a_camera_with_a_clock_starts_halved_and_halved_frames_with_room_to_spare_return_it():
    pace = FrontEndPace(0.1)
    assert pace.halve(LARGE) and not pace.halve(SMALL)   # its first frames, from scratch, are its slowest
    for _ in range(RECENT - 1):
        pace.timed(RETURN_SHARE * 0.1 / FULL_OVER_HALVED * 0.8, True)
        assert pace.halve(LARGE)                     # a decision takes RECENT frames
    pace.timed(RETURN_SHARE * 0.1 / FULL_OVER_HALVED * 0.8, True)
    assert not pace.halve(LARGE)
    # halved frames whose full-resolution time would still overrun the return bar: halved on
    pace = FrontEndPace(0.1)
    for _ in range(2 * RECENT):
        pace.timed(RETURN_SHARE * 0.1 / FULL_OVER_HALVED * 1.2, True)
    assert pace.halve(LARGE)


def test_frames_over_the_share_of_the_period_halve_a_large_target():
    pace = _at_full()
    over = FRONT_END_SHARE * 0.1 * 1.2
    for _ in range(RECENT - 1):
        pace.timed(over, False)
        assert not pace.halve(LARGE)                 # a decision takes RECENT frames
    pace.timed(over, False)
    assert pace.halve(LARGE) and not pace.halve(SMALL)


def test_a_target_tracked_far_across_a_deep_area_is_not_halved_however_near_it_could_be():
    pace = FrontEndPace(0.1)
    # the prior's nearest marks are 14 px; tracked where its largest mark is 4 px, halving would leave 2 px marks
    assert pace.halve(LARGE) and pace.halve(LARGE, 12.0) and not pace.halve(LARGE, 4.0)


def test_a_marks_radius_where_the_target_is_tracked():
    from evopose import Camera
    camera = Camera(fx=2400.0, fy=2400.0, cx=320.0, cy=240.0, width=640, height=480)
    assert largest_mark_px(camera, np.array([0.0, 0.0, 20.0, 0.0, 0.0, 0.0]), 0.1) == pytest.approx(12.0)


def test_one_slow_frame_decides_nothing_and_without_a_period_nothing_is_halved():
    pace = _at_full()
    for seconds in (0.03, 0.5, 0.03, 0.03):
        pace.timed(seconds, False)
    assert not pace.halve(LARGE)
    free = FrontEndPace(None)
    for _ in range(2 * RECENT):
        free.timed(10.0, False)
    assert not free.halve(LARGE)
    with pytest.raises(ValueError, match="period_s"):
        FrontEndPace(0.0)


def test_halved_detections_come_back_in_the_full_images_pixels():
    seen = {}

    def detect(image, prior):
        seen["shape"], seen["prior"] = image.shape, prior
        return ContrastMarks(points=np.array([[10.0, 20.0]]), labels=np.array([0]), areas=np.array([28]),
                             names=("red",), radius=np.array([3.0]), label_confidence=np.ones(1),
                             contrast=np.ones(1))

    found = detect_halved(detect, np.zeros((101, 64, 3), np.uint8), LARGE)
    assert seen["shape"] == (50, 32, 3)
    assert seen["prior"] == MarkPrior((1.5, 7.0), 240.0)
    assert found.points.tolist() == [[20.5, 40.5]] and found.radius.tolist() == [6.0]
    assert found.areas.tolist() == [112]


def _run(name: str, period_s: float, rounds: int = 3) -> tuple[list[np.ndarray], float]:
    """The agent's extractor over a fixture's frames, ``rounds`` times (the look tracked, the pace decided): the
    last round's points per image and its recall of fully visible marks (3 px)."""
    ds = open_dataset(DATA / name)
    world = ds.world()
    extract = feature_extractor("contrast", world.model, world.bounds(), period_s=period_s)
    points, found, visible = [], 0, 0
    for round_ in range(rounds):
        for cam in ds.cameras:
            for k in range(ds.frames):
                image = cv2.imread(str(ds.image_path(cam, k)), cv2.IMREAD_COLOR)
                pts, _ = extract(image, ds.camera(cam, k), near=ds.truth(k).target_pose)
                if round_ == rounds - 1:
                    marks = ds.truth(k).cameras[cam].marks
                    whole = np.array([m.uv for m in marks if m.fully_visible])
                    points.append(pts)
                    found += len(match_to_truth(pts, whole, 3.0)[0])
                    visible += len(whole)
    return points, found / visible


def test_an_overrunning_front_end_finds_the_second_robots_marks_on_the_image_halved():
    # a period no frame can keep: every frame runs halved (the second robot is 456-500 px across); a period every
    # frame keeps: full resolution after the first RECENT frames (halved, as every camera with a clock starts)
    halved_points, halved_recall = _run("husky-telephoto", 1e-9)
    full_points, full_recall = _run("husky-telephoto", 1e9)
    assert any(len(a) != len(b) or not np.array_equal(a, b) for a, b in zip(halved_points, full_points))
    assert full_recall >= 0.93 and halved_recall >= 0.9


def test_a_target_too_small_to_halve_is_never_halved():
    assert all(np.array_equal(a, b) for a, b in zip(_run("telephoto", 1e-9, 2)[0], _run("telephoto", 1e9, 2)[0]))


def test_a_mark_found_on_the_image_halved_is_placed_at_its_whole_blobs_centre_at_full_resolution():
    # an oblique black mark (a 4:1 ellipse, 12 x 3 px half-axes) on a yellow face, found 3 px off along its length
    # (a halved pixel is two: the halved blob joined the dark beside it): placed again on the full image
    image = np.zeros((80, 120, 3), np.uint8)
    image[:] = (40, 190, 220)
    big = np.zeros((80 * 8, 120 * 8, 3), np.uint8)
    big[:] = (40, 190, 220)
    cv2.ellipse(big, (int(60.5 * 8), int(40.5 * 8)), (12 * 8, 3 * 8), 0, 0, 360, (25, 25, 25), -1)
    image = cv2.resize(big, (120, 80), interpolation=cv2.INTER_AREA)   # the disc's edge blended into its pixels
    centre = np.array([[60.5 - 0.5 / 8 * 7, 40.5 - 0.5 / 8 * 7]])       # the drawn centre in the resized pixels
    found = centre + [[3.0, 0.0]]
    placed = placed_at_full(image, None, found, np.array([3.0]), 14.0)
    assert np.abs(placed - centre).max() < 0.3 < np.abs(found - centre).max()
    assert placed_at_full(image, None, np.zeros((0, 2)), np.zeros(0), 14.0).shape == (0, 2)


def _agent_frames(world: str, frames: int) -> tuple[list[dict], dict]:
    """A real agent process alone on ``world`` at 50 fps, a period whose 0.6 no front-end here keeps (it takes
    60-220 ms a frame): its frames' JSON lines and its summary."""
    done = subprocess.run([sys.executable, "-m", "agents.cli", "agent", "--fleet", "pace", "--scenario", world,
                           "--vehicle", "H1", "--frames", str(frames), "--fps", "50", "--json", "--no-multicast",
                           "--listen", f"tcp/127.0.0.1:{free_port()}"], cwd=ROOT, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    records = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]
    return [r for r in records if r.get("event") == "frame"], next(r for r in records if r.get("event") == "summary")


def test_an_agent_that_overruns_its_clock_on_a_large_target_halves_and_says_so_and_stays_right():
    frames, summary = _agent_frames("exp2-photoreal-telephoto-husky", 7)
    assert len(frames) == 7
    # it starts halved and its halved frames leave no room for full resolution: every frame halved, each JSON line
    # says so
    assert [r.get("front_end") for r in frames] == ["halved"] * 7
    assert summary["halved_frames"] == 7
    for r in frames:   # halved or not, every published pose within 5 cm and 1 deg of the truth (measured <= 1.8 cm)
        error = r["error"]
        assert error["position"] <= 0.05 and max(error[a] for a in ("roll", "pitch", "yaw")) <= 1.0, r["error"]
    # the Pioneer at telephoto (200-220 px across) is never halved, however late
    frames, summary = _agent_frames("exp2-photoreal-telephoto", 5)
    assert all("front_end" not in r for r in frames) and summary["halved_frames"] == 0


def test_the_pace_answers_a_plain_bool_for_a_prior_of_numpy_numbers():
    # a dataset's camera gives numpy floats: the answer goes into an agent's JSON summary (json cannot write np.bool_)
    assert type(FrontEndPace(0.1).halve(MarkPrior((np.float64(2.5), np.float64(12.0)), np.float64(210.0)))) is bool
