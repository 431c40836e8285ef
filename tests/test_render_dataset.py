"""`evopose render WORLD --out DIR`: datasets in the layout of docs/datasets.md (the OpenCV engine end to end,
resuming, bad arguments) and the committed photoreal datasets of tests/data/photoreal."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from agents.tools.render_dataset import render_dataset
from scenarios.dataset import DatasetError, open_dataset
from scenarios.render import render_frame
from scenarios.world import load_scenario
from tests.cli_run import run_cli

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "photoreal"


def evopose(*args, env=None, timeout: float = 120) -> subprocess.CompletedProcess:
    """The CLI in this process (tests/cli_run.py), or with ``env`` added to the environment, in a process of its own."""
    import os

    if env is None:
        return run_cli(*args)
    return subprocess.run([sys.executable, "-m", "agents.cli", *map(str, args)], cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout, env={**os.environ, **env})


def assert_usage_error(result: subprocess.CompletedProcess, expected: str) -> None:
    assert result.returncode == 2, (result.returncode, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and expected in lines[0], result.stderr


@pytest.fixture(scope="module")
def opencv_dataset(tmp_path_factory):
    out = tmp_path_factory.mktemp("ds") / "paper"
    events = []
    summary = render_dataset("exp2-paper-scale", out, engine="opencv", frames=2, progress=events.append)
    return out, summary, events


def test_opencv_dataset_has_the_layout(opencv_dataset):
    out, summary, events = opencv_dataset
    assert summary["images_rendered"] == 4 and summary["complete_frames"] == 2
    assert [(e["camera"], e["frame"]) for e in events] == [("H1", 0), ("H2", 0), ("H1", 1), ("H2", 1)]
    assert [e["done"] for e in events] == [1, 2, 3, 4] and {e["total"] for e in events} == {4}
    manifest = yaml.safe_load((out / "manifest.yaml").read_text())
    assert manifest["format"] == "evopose-dataset/1" and manifest["engine"] == {"name": "opencv"}
    assert manifest["frames"] == 2 and manifest["cameras"] == ["H1", "H2"] and manifest["target_visible"] is True
    assert manifest["camera_model"]["jpeg_quality"] == 85  # the default camera model, as applied
    for name in ("world.yaml", "model.yaml", "truth.jsonl", "H1/camera_info.yaml", "H1/poses.jsonl",
                 "H2/000001.jpg"):
        assert (out / name).is_file(), name
    ds = open_dataset(out)
    assert ds.frames == 2 and ds.cameras == ("H1", "H2")
    image = cv2.imread(str(ds.image_path("H2", 1)))
    assert image.shape == (480, 640, 3)
    world = load_scenario("exp2-paper-scale")
    for k in range(2):
        truth = ds.truth(k)
        assert np.allclose(truth.target_pose, world.target_pose(k)) and truth.target_visible
        for camera in ("H1", "H2"):
            expected = render_frame(world, k, camera).truth
            view = truth.cameras[camera]
            assert [m.index for m in view.marks] == expected.mark_index.tolist()
            assert np.allclose([m.uv for m in view.marks], expected.mark_uv)
            assert np.allclose(ds.world_from_camera(camera, k), view.world_from_camera)
            assert np.allclose(ds.camera(camera, k).world_from_camera, world.camera(camera, k).world_from_camera)


def test_resume_renders_only_what_is_missing(opencv_dataset, tmp_path):
    import shutil

    src, _, _ = opencv_dataset
    out = tmp_path / "copy"
    shutil.copytree(src, out)
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    (out / "H2" / "000000.jpg").unlink()
    events = []
    summary = render_dataset("exp2-paper-scale", out, engine="opencv", frames=2, progress=events.append)
    assert [(e["camera"], e["frame"]) for e in events if e["rendered"]] == [("H2", 0)]
    assert summary["images_rendered"] == 1 and summary["complete_frames"] == 2
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after == before  # the same image again (seeded), the same poses and truth lines
    # nothing missing: nothing rendered
    assert render_dataset("exp2-paper-scale", out, engine="opencv", frames=2)["images_rendered"] == 0


def test_other_settings_in_an_existing_dataset_need_force(opencv_dataset, tmp_path):
    import shutil

    src, _, _ = opencv_dataset
    out = tmp_path / "copy"
    shutil.copytree(src, out)
    with pytest.raises(DatasetError) as err:
        render_dataset("exp2-paper-scale", out, engine="opencv", frames=3)
    assert "\n" not in str(err.value) and "frames" in str(err.value) and "--force" in str(err.value)
    with pytest.raises(DatasetError, match="world"):
        render_dataset("exp2", out, engine="opencv", frames=2)
    summary = render_dataset("exp2", out, engine="opencv", frames=1, force=True)
    assert summary["images_rendered"] == 2 and open_dataset(out).name == "exp2"
    assert not (out / "H1" / "000001.jpg").exists()


def test_absent_target_dataset(tmp_path):
    out = tmp_path / "absent"
    render_dataset("exp2-paper-scale", out, engine="opencv", frames=1, cameras=["H2"], target=False)
    ds = open_dataset(out)
    assert ds.cameras == ("H2",) and ds.target_visible is False
    truth = ds.truth(0)
    assert truth.target_visible is False and truth.cameras["H2"].marks == ()
    with_target = cv2.imread(str(render_dataset_image(tmp_path)))
    without = cv2.imread(str(ds.image_path("H2", 0)))
    # the robot's red body is in one image and not in the other
    red = lambda im: int(np.sum((im[..., 2] > 100) & (im[..., 2] > 2 * im[..., 1].astype(int))))  # noqa: E731
    assert red(with_target) > 20 and red(without) == 0


def render_dataset_image(tmp_path: Path) -> Path:
    out = tmp_path / "present"
    render_dataset("exp2-paper-scale", out, engine="opencv", frames=1, cameras=["H2"])
    return out / "H2" / "000000.jpg"


# -- the command line -----------------------------------------------------------------------------------------------

def test_cli_renders_an_opencv_dataset_with_json_summary(tmp_path):
    result = evopose("render", "exp2-paper-scale", "--out", tmp_path / "d", "--engine", "opencv", "--frames", 1,
                     "--cameras", "H2", "--json")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["cameras"] == ["H2"] and summary["images_rendered"] == 1
    assert "H2 frames" in result.stderr  # the progress bar, on stderr
    assert open_dataset(tmp_path / "d").frames == 1


@pytest.mark.parametrize("args, expected", [
    (["--engine", "blender"], "--engine"),
    (["--frames", 0], "--frames"),
    (["--samples", 0], "--samples"),
    (["--cameras", "H1,,H2"], "--cameras"),
    (["--cameras", "H7", "--engine", "opencv"], "H7"),
    (["--frame", 3], "--frame"),
    (["--clean"], "--clean"),
])
def test_cli_bad_dataset_arguments_are_one_line(tmp_path, args, expected):
    assert_usage_error(evopose("render", "exp2-paper-scale", "--out", tmp_path / "d", *args), expected)


def test_cli_dataset_options_with_an_image_out_are_one_line(tmp_path):
    assert_usage_error(evopose("render", "exp2", "--out", tmp_path / "x.png", "--frames", 3), "--frames")
    assert_usage_error(evopose("render", "exp2", "--out", tmp_path / "x.png", "--no-target"), "dataset")


def test_cli_without_blender_says_how_to_install_it(tmp_path):
    result = evopose("render", "exp2-photoreal", "--out", tmp_path / "d", "--frames", 1,
                     env={"EVOPOSE_BPY_PYTHON": str(tmp_path / "no-python")})
    assert_usage_error(result, "make photoreal")
    assert not (tmp_path / "d").exists()


def test_cli_existing_dataset_of_other_settings_is_one_line(opencv_dataset, tmp_path):
    import shutil

    src, _, _ = opencv_dataset
    shutil.copytree(src, tmp_path / "d")
    result = evopose("render", "exp2-paper-scale", "--out", tmp_path / "d", "--engine", "opencv", "--frames", 5)
    assert_usage_error(result, "--force")


# -- the committed photoreal datasets ------------------------------------------------------------------------------------

@pytest.mark.parametrize("name, world, frames, target", [("paper", "exp2-photoreal", 4, True),
                                                         ("telephoto", "exp2-photoreal-telephoto", 4, True),
                                                         ("absent", "exp2-photoreal", 2, False)])
def test_committed_photoreal_datasets(name, world, frames, target):
    root = DATA / name
    if not (root / "manifest.yaml").is_file():
        pytest.skip(f"{root} not rendered (benchmarks: see docs/datasets.md)")
    ds = open_dataset(root)
    assert ds.name == world and ds.frames == frames and ds.target_visible is target
    assert ds.manifest.engine.name == "cycles" and ds.manifest.engine.samples == 24
    assert not list(root.rglob("*.exr")) and not (root / ".blender").exists()
    scenario = load_scenario(world)
    for k in range(frames):
        truth = ds.truth(k)
        assert np.allclose(truth.target_pose, scenario.target_pose(k))
        for camera in ds.cameras:
            image = cv2.imread(str(ds.image_path(camera, k)))
            assert image.shape == (480, 640, 3)
            marks = truth.cameras[camera].marks
            assert (len(marks) >= 6) if target else not marks
            assert np.allclose(ds.world_from_camera(camera, k), truth.cameras[camera].world_from_camera)


def test_committed_photoreal_datasets_are_small():
    size = sum(p.stat().st_size for p in DATA.rglob("*") if p.is_file())
    assert size <= 5 * 1024 * 1024, size
