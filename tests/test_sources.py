"""Real cameras (issue 14): `evopose agent --source` on real files through real OpenCV, as real processes, against
the renderer; the ROS camera_info reader; one line and exit 2 for every bad input."""

from __future__ import annotations

import queue
import sys
import threading
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from agents.cli.main import main
from agents.problem.camera_info import read_camera_file, read_camera_info, read_camera_pose
from agents.problem.problem_file import ProblemFileError
from agents.vehicle.sources import CaptureReader, FrameSkipped, LatestFrameReader, SourceEnded, open_reader
from scenarios.render import render_frame
from scenarios.world import load_scenario
from tests.fleet_procs import Proc, free_port, release_when_warm

FRAMES = 10
#: Slow enough that a frame (read, extract, one generation or a confirming search) never runs late: the renderer's
#: and the source's agents must take frame n on the same tick to seed the same searches.
FPS = 2.0
#: Lossless video codecs to try, (fourcc, suffix): this OpenCV build writes FFV1 (FFmpeg).
LOSSLESS = (("FFV1", ".mkv"), ("png ", ".avi"))


def camera_info_document(camera) -> dict:
    """A ROS camera_info mapping of an evopose camera."""
    k = [camera.fx, 0.0, camera.cx, 0.0, camera.fy, camera.cy, 0.0, 0.0, 1.0]
    return {"image_width": camera.width, "image_height": camera.height, "camera_name": "h1",
            "camera_matrix": {"rows": 3, "cols": 3, "data": k}, "distortion_model": "plumb_bob",
            "distortion_coefficients": {"rows": 1, "cols": 5, "data": [float(v) for v in camera.distortion]},
            "rectification_matrix": {"rows": 3, "cols": 3, "data": [1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0]},
            "projection_matrix": {"rows": 3, "cols": 4,
                                  "data": [camera.fx, 0.0, camera.cx, 0.0, 0.0, camera.fy, camera.cy, 0.0, 0, 0, 1, 0]}}


@pytest.fixture(scope="module")
def h1_media(tmp_path_factory):
    """Frames 0-9 of exp2 seen by H1 as a PNG sequence and as a lossless video, and H1's camera_info."""
    folder = tmp_path_factory.mktemp("h1_media")
    scenario = load_scenario("exp2")
    images = [render_frame(scenario, k, "H1").image for k in range(FRAMES)]
    (folder / "seq").mkdir()
    for k, image in enumerate(images):
        assert cv2.imwrite(str(folder / "seq" / f"h1_{k:02d}.png"), image)
    video = None
    for fourcc, suffix in LOSSLESS:
        path = folder / f"h1{suffix}"
        writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), 10, (640, 480))
        if writer.isOpened():
            for image in images:
                writer.write(image)
            writer.release()
            video = path
            break
    info = folder / "h1_camera_info.yaml"
    info.write_text(yaml.safe_dump(camera_info_document(scenario.camera("H1", 0))), encoding="utf-8")
    return folder, images, video, info


def run_agents(runs: dict[str, tuple[str, ...]], base: tuple[str, ...] = ("--vehicle", "H1", "--scenario", "exp2")
               ) -> dict[str, tuple[int, list[dict], str]]:
    """Agents started together, each alone in its fleet (features shared with nobody: a fixed number of
    generations per frame, so the same images give the same poses); per fleet its exit code, JSON records and
    stderr. At 2 frames/s a frame's work is a small share of its period, so they take the same ticks side by
    side (each run asserts it skipped no frame). ``base``: the arguments every run shares (the vehicle and world).
    """
    procs = {fleet: Proc([sys.executable, "-m", "agents.cli", "agent", "--fleet", fleet, *base,
                          "--share", "features", "--fps", str(FPS), "--epoch-from-stdin",
                          "--json", "--no-multicast", "--listen", f"tcp/127.0.0.1:{free_port()}", *args])
             for fleet, args in runs.items()}
    try:
        release_when_warm(list(procs.values()))   # one clock: frame 0 a second after the last is warm
        return {fleet: (proc.wait(120), proc.all_records(), proc.popen.stderr.read()) for fleet, proc in procs.items()}
    finally:
        for proc in procs.values():
            proc.kill()


def frames_of(records: list[dict]) -> dict[int, dict]:
    return {r["frame"]: r for r in records if r.get("event") == "frame"}


@pytest.fixture(scope="module")
def source_runs(h1_media):
    """The renderer's agent, and agents on the PNG sequence and on the lossless video with its camera_info."""
    folder, _, video, info = h1_media
    # the renderer's drawings played back: the same front-end as the renderer's agent (auto takes a source for a
    # camera's images and would find the marks by their contrast)
    runs = {"render-h1": ("--frames", str(FRAMES)),
            "seq-h1": ("--source", str(folder / "seq" / "h1_%02d.png"), "--features", "marks")}
    if video is not None:
        runs["video-h1"] = ("--source", str(video), "--camera-info", str(info), "--features", "marks")
    return run_agents(runs)


@pytest.fixture(scope="module")
def renderer_run(source_runs):
    code, records, stderr = source_runs["render-h1"]
    assert code == 0, stderr
    return records


def assert_same_poses(source_records: list[dict], renderer_records: list[dict]) -> None:
    source, rendered = frames_of(source_records), frames_of(renderer_records)
    summary = next(r for r in source_records if r.get("event") == "summary")
    rendered_summary = next(r for r in renderer_records if r.get("event") == "summary")
    # comparable runs: both took frames 0..9 on the same ticks (same seeds), none skipped late
    assert summary["late_frames"] == rendered_summary["late_frames"] == 0
    assert sorted(source) == sorted(rendered) == list(range(FRAMES))
    for n in range(FRAMES):
        assert source[n]["scene_frame"] == rendered[n]["scene_frame"] == n
        assert source[n]["points"] == rendered[n]["points"]
        assert source[n]["pose"] == rendered[n]["pose"], n  # identical: lossless images, same seeds
        assert source[n]["good"] == rendered[n]["good"]
        assert "error" not in source[n] and "error" in rendered[n]  # no ground truth from a real source
    assert rendered_summary["good"] > 0 and summary["good"] == rendered_summary["good"]
    assert not [k for k in summary if k.startswith("error_")] and summary["last_error"] is None


def test_png_sequence_gives_the_renderers_poses_and_ends_cleanly(source_runs, renderer_run):
    code, records, stderr = source_runs["seq-h1"]
    assert code == 0 and "Traceback" not in stderr, stderr
    assert any(r.get("event") == "end-of-source" and r["frames"] == FRAMES for r in records)
    assert_same_poses(records, renderer_run)


def test_lossless_video_with_camera_info_gives_the_renderers_poses(h1_media, source_runs, renderer_run):
    folder, images, video, info = h1_media
    if video is None:
        pytest.skip("this OpenCV build writes no lossless video codec (FFV1, png)")
    capture = CaptureReader(cv2.VideoCapture(str(video)), str(video))
    assert all(np.array_equal(capture.read(), image) for image in images)  # the codec is really lossless
    with pytest.raises(SourceEnded):
        capture.read()
    code, records, stderr = source_runs["video-h1"]
    assert code == 0 and "Traceback" not in stderr, stderr
    assert_same_poses(records, renderer_run)


def test_a_directory_plays_its_images_in_name_order(h1_media):
    """A directory source gives its images in name order, then ends (the agent's loop is the sequence's)."""
    folder, images, _, _ = h1_media
    reader = open_reader(str(folder / "seq"))
    try:
        assert all(np.array_equal(reader.read(), image) for image in images)
        with pytest.raises(SourceEnded):
            reader.read()
    finally:
        reader.close()


def test_a_live_reader_returns_the_newest_frame_and_ends_with_its_device(h1_media):
    """The device path's reader, on a video file read as fast as it decodes: each read gives the newest frame, never
    one read before (a tick without a new one is skipped), and the end of the stream ends the source."""
    folder, images, video, _ = h1_media
    reader = LatestFrameReader(cv2.VideoCapture(str(folder / "seq" / "h1_%02d.png")), "seq")
    try:
        seen = []
        while True:
            try:
                image = reader.read()
            except SourceEnded:
                break
            except FrameSkipped as skip:
                assert skip.reason == "no new image"
                continue
            seen.append(next(k for k, im in enumerate(images) if np.array_equal(im, image)))
            time.sleep(0.05)
        assert seen == sorted(set(seen)) and reader.frames_read == FRAMES
    finally:
        reader.close()


class QueuedCapture:
    """A device whose frames come when the test puts them (None: the device stops)."""

    def __init__(self) -> None:
        self.frames: queue.Queue = queue.Queue()

    def read(self):
        frame = self.frames.get()
        return (frame is not None), frame

    def release(self) -> None:
        self.frames.put(None)


def test_a_live_reader_never_gives_one_frame_twice():
    """A camera slower than the fleet's clock: a tick without a new frame waits up to new_frame_wait_s, then is
    skipped; the frame that comes later is the next tick's."""
    capture = QueuedCapture()
    reader = LatestFrameReader(capture, "slow", first_timeout_s=5.0, new_frame_wait_s=0.05)
    a, b = np.zeros((2, 2, 3), np.uint8), np.ones((2, 2, 3), np.uint8)
    try:
        capture.frames.put(a)
        assert reader.read() is a
        with pytest.raises(FrameSkipped, match="no new image: no frame from slow since the last tick's"):
            reader.read()
        reader.new_frame_wait_s = 5.0   # a frame just after the tick is waited for (and taken as soon as it comes)
        threading.Timer(0.01, capture.frames.put, (b,)).start()
        started = time.monotonic()
        assert reader.read() is b and time.monotonic() - started < 4.0
    finally:
        reader.close()


# -- camera files ---------------------------------------------------------------------------------------------

GOOD = camera_info_document(load_scenario("exp2").camera("H1", 0))


def test_camera_info_is_read_as_the_camera(tmp_path):
    path = tmp_path / "ci.yaml"
    path.write_text(yaml.safe_dump(GOOD), encoding="utf-8")
    camera = read_camera_info(path)
    assert (camera.fx, camera.fy, camera.cx, camera.cy, camera.width, camera.height) == (12000, 12000, 320, 240,
                                                                                         640, 480)
    assert np.array_equal(camera.world_from_camera, np.eye(4))
    assert read_camera_file(path).fx == 12000  # solve --camera takes either format


def test_the_chessboard_calibration_is_a_valid_camera_info():
    camera = read_camera_info(Path(__file__).resolve().parents[1] / "examples/chessboard/camera_info.yaml")
    assert camera.width == 640 and camera.height == 480 and 500 < camera.fx < 580 and camera.distortion[0] < 0


@pytest.mark.parametrize("field, value, expected", [
    ("image_width", 0, "image_width: must be > 0"),
    ("image_height", "480", "image_height: expected an integer"),
    ("camera_matrix", {"rows": 3, "cols": 3, "data": [1.0] * 8}, "camera_matrix: data: expected rows x cols = 9"),
    ("camera_matrix", {"rows": 3, "cols": 4, "data": [1.0] * 12}, "camera_matrix: expected a 3x3 matrix"),
    ("camera_matrix", {"rows": 3, "cols": 3, "data": [-5.0, 0, 320, 0, 5.0, 240, 0, 0, 1]}, "fx and fy must be > 0"),
    ("camera_matrix", {"rows": 3, "cols": 3, "data": [500, 2.0, 320, 0, 500, 240, 0, 0, 1]}, "(no skew)"),
    ("camera_matrix", "K", "camera_matrix: expected a mapping"),
    ("distortion_model", "equidistant", "distortion_model: expected 'plumb_bob'"),
    ("distortion_coefficients", {"rows": 1, "cols": 8, "data": [0.0] * 8}, "plumb_bob has 5 coefficients"),
    ("distortion_coefficients", {"rows": 1, "cols": 5, "data": [0.0, 0, 0, 0, ".nan"]}, "distortion_coefficients"),
    ("rectification_matrix", {"rows": 2, "cols": 2, "data": [1.0] * 4}, "rectification_matrix: expected a 3x3"),
    ("projection_matrix", {"rows": 3, "cols": 3, "data": [1.0] * 9}, "projection_matrix: expected a 3x4"),
    ("camera_name", 7, "camera_name"),
    ("lens", "wide", "lens: unknown key"),
])
def test_each_malformed_camera_info_field_is_one_line_naming_it(tmp_path, field, value, expected):
    path = tmp_path / "ci.yaml"
    path.write_text(yaml.safe_dump({**GOOD, field: value}), encoding="utf-8")
    with pytest.raises(ProblemFileError) as err:
        read_camera_info(path)
    assert expected in str(err.value) and str(path) in str(err.value) and "\n" not in str(err.value)


def test_a_missing_camera_matrix_and_a_bad_pose_are_named(tmp_path):
    path = tmp_path / "ci.yaml"
    path.write_text(yaml.safe_dump({k: v for k, v in GOOD.items() if k != "camera_matrix"}), encoding="utf-8")
    with pytest.raises(ProblemFileError, match="camera_matrix: required field missing"):
        read_camera_info(path)
    pose = tmp_path / "pose.yaml"
    pose.write_text("{x: 1, y: 2, z: 3, roll: 0, pitch: 0}\n", encoding="utf-8")
    with pytest.raises(ProblemFileError, match="yaw: required field missing"):
        read_camera_pose(pose)
    pose.write_text("{x: 1, y: 2, z: 3, roll: 0, pitch: 0.5, yaw: 0}\n", encoding="utf-8")
    assert read_camera_pose(pose).tolist() == [1, 2, 3, 0, 0.5, 0]


def test_solve_image_takes_a_camera_info_file_as_its_camera(h1_media, tmp_path):
    from agents.problem.solve import solve_image

    folder, _, _, info = h1_media
    spec = tmp_path / "camera.yaml"  # the same camera in the problem file's fields
    spec.write_text(yaml.safe_dump({"fx": 12000.0, "fy": 12000.0, "cx": 320.0, "cy": 240.0, "width": 640,
                                    "height": 480}), encoding="utf-8")
    image = folder / "seq" / "h1_04.png"
    a = solve_image(image, "pioneer", info, seed=3)
    b = solve_image(image, "pioneer", spec, seed=3)
    assert a["pose"] == b["pose"] and a["confident"]


# -- one line and exit 2 for every bad input ------------------------------------------------------------------


def agent_error(capfd, *args: str) -> str:
    """Run ``evopose agent`` in this process; it must fail before joining a fleet, with one line and exit 2."""
    code = main(["agent", "--fleet", "bad", "--vehicle", "H1", "--no-multicast", "--listen",
                 f"tcp/127.0.0.1:{free_port()}", "--frames", "1", *args])
    err = capfd.readouterr().err
    lines = err.splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in err, err
    return lines[0]


def test_bad_sources_are_one_line_and_exit_2(capfd, h1_media, tmp_path):
    folder, _, _, info = h1_media
    garbage = tmp_path / "garbage.mp4"
    garbage.write_bytes(np.random.default_rng(0).integers(0, 256, 5000, dtype=np.uint8).tobytes())
    empty = tmp_path / "empty"
    empty.mkdir()
    cases = [
        (["--source", str(tmp_path / "missing.mkv")], "no such file, directory or device"),
        (["--source", str(garbage)], "not a video OpenCV can read"),
        (["--source", "/dev/video97"], "/dev/video97: no such device"),
        (["--source", "97"], "97: the V4L2 device does not open"),
        (["--source", str(empty)], "the directory holds no images"),
        (["--source", str(tmp_path / "*.png")], "the pattern matches no files"),
        (["--source", str(tmp_path / "f%03d.png")], "no image sequence matches the pattern"),
        (["--source", str(folder / "seq"), "--features", "edges"], "--features must be one of auto, marks, contrast, corners"),
        (["--camera-info", str(info)], "--camera-info and --camera-pose describe a real camera: they need --source"),
    ]
    for args, expected in cases:
        assert expected in agent_error(capfd, *args), args


def test_bad_camera_files_and_wrong_sizes_are_one_line_and_exit_2(capfd, h1_media, tmp_path):
    folder, _, _, _ = h1_media
    seq = str(folder / "seq")
    small = tmp_path / "small.yaml"
    small.write_text(yaml.safe_dump({**GOOD, "image_width": 320, "image_height": 240}), encoding="utf-8")
    line = agent_error(capfd, "--source", seq, "--camera-info", str(small))
    assert "frame 0 is 640x480, the camera (--camera-info" in line and "320x240" in line
    broken = tmp_path / "broken.yaml"
    broken.write_text("camera_matrix: [1, 2\n", encoding="utf-8")
    assert "invalid YAML" in agent_error(capfd, "--source", seq, "--camera-info", str(broken))
    assert "cannot read: No such file" in agent_error(capfd, "--source", seq, "--camera-info", str(tmp_path / "none.yaml"))
    pose = tmp_path / "pose.yaml"
    pose.write_text("{x: 1, y: 2, z: 3, roll: 0, pitch: 0, yaw: north}\n", encoding="utf-8")
    assert "yaw: expected a number" in agent_error(capfd, "--source", seq, "--camera-pose", str(pose))


def test_a_bad_mark_scorer_is_one_line_and_exit_2(capfd, h1_media, tmp_path):
    import json

    from vision.mark_scorer import shipped

    folder, _, _, _ = h1_media
    seq = str(folder / "seq")
    line = agent_error(capfd, "--source", seq, "--features", "marks", "--mark-scorer", str(tmp_path / "s.json"))
    assert "--mark-scorer is for --features contrast, got --features marks" in line
    contrast = ("--source", seq, "--features", "contrast", "--mark-scorer")
    assert "cannot read it" in agent_error(capfd, *contrast, str(tmp_path / "none.json"))
    broken = tmp_path / "broken.json"
    broken.write_text(json.dumps({**shipped().to_dict(), "threshold": "high"}), encoding="utf-8")
    assert "field threshold: expected a number" in agent_error(capfd, *contrast, str(broken))
    other = tmp_path / "other.json"  # fitted on other features (a column the front-end does not compute)
    doc = shipped().to_dict()
    doc["names"] = [*doc["names"][:-1], "label_orange"]
    other.write_text(json.dumps(doc), encoding="utf-8")
    assert "the mark scorer was fitted on the features" in agent_error(capfd, *contrast, str(other))


def test_mark_scorer_names_the_shipped_models_or_the_bars():
    # --mark-scorer shipped (the default) and bars are names, not files; the agent's extractor takes either
    from agents.vehicle.cameras import _mark_scorer
    from agents.vehicle.config import AgentConfig
    from scenarios.target import load_model
    from vision.extract import feature_extractor

    assert _mark_scorer(AgentConfig(fleet="f", vehicle="H1", scenario=None, mark_scorer="shipped")) is None
    assert _mark_scorer(AgentConfig(fleet="f", vehicle="H1", scenario=None)) is None
    assert _mark_scorer(AgentConfig(fleet="f", vehicle="H1", scenario=None, mark_scorer="bars")) == "bars"
    model = load_model("pioneer")
    assert callable(feature_extractor("contrast", model, None, "bars"))
    with pytest.raises(ValueError, match="scorer must be"):
        feature_extractor("contrast", model, None, "best")
