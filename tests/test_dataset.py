"""Rendered datasets (docs/datasets.md): the writer's layout read back exactly, resuming, and one DatasetError line
naming the file, the line and the field for every malformed input."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from agents.problem.camera_info import read_camera_info
from evopose import Camera
from geometry import pose_from_matrix
from scenarios.dataset import DatasetError, DatasetWriter, image_name, locate_dataset, open_dataset
from scenarios.errors import WorldError
from scenarios.render import render_frame
from scenarios.world import load_scenario

FRAMES = 3
ROOT = Path(__file__).resolve().parents[1]


def write_dataset(root: Path, world: str = "exp2", frames: int = FRAMES, suffix: str = ".png", **options) -> Path:
    """A dataset of ``world``'s first frames drawn by the project's renderer, written by the DatasetWriter."""
    writer = DatasetWriter(root, world, engine={"name": "opencv"}, frames=frames, **options)
    for k in range(writer.next_frame, frames):
        writer.add_frame(k, {c: render_frame(writer.scenario, k, c) for c in writer.cameras}, suffix)
    return root


@pytest.fixture(scope="module")
def dataset_dir(tmp_path_factory) -> Path:
    return write_dataset(tmp_path_factory.mktemp("datasets") / "exp2")


@pytest.fixture
def copy(dataset_dir, tmp_path) -> Path:
    """A copy of the dataset to break."""
    return Path(shutil.copytree(dataset_dir, tmp_path / "ds"))


def test_the_written_dataset_reads_back_as_the_renderer_drew_it(dataset_dir):
    scenario = load_scenario("exp2")
    ds = open_dataset(dataset_dir)
    assert ds.cameras == ("H1", "H2") and ds.frames == FRAMES and ds.fps == 10 and ds.has_truth
    assert ds.manifest.format == "evopose-dataset/1" and ds.manifest.engine.name == "opencv" and ds.target_visible
    assert sorted(p.name for p in dataset_dir.iterdir()) == ["H1", "H2", "manifest.yaml", "model.yaml",
                                                             "truth.jsonl", "world.yaml"]
    for k in range(FRAMES):
        truth = ds.truth(k)
        assert truth.frame == k and truth.time == k / 10 and truth.target_visible
        assert np.array_equal(truth.target_pose, scenario.target_pose(k))
        for camera in ds.cameras:
            rendered = render_frame(scenario, k, camera)
            assert ds.image_path(camera, k) == dataset_dir / camera / f"{k:06d}.png"
            assert np.array_equal(cv2.imread(str(ds.image_path(camera, k))), rendered.image)  # lossless PNG
            cam = ds.camera(camera, k)
            assert (cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height) == (
                rendered.camera.fx, rendered.camera.fy, rendered.camera.cx, rendered.camera.cy, 640, 480)
            assert np.allclose(cam.world_from_camera, rendered.camera.world_from_camera, rtol=0, atol=1e-12)
            assert np.array_equal(ds.world_from_camera(camera, k), pose_from_matrix(rendered.camera.world_from_camera))
            view = truth.cameras[camera]
            assert np.array_equal(view.world_from_camera, rendered.truth.camera_pose)
            assert [m.index for m in view.marks] == rendered.truth.mark_index.tolist()
            assert [list(m.uv) for m in view.marks] == rendered.truth.mark_uv.tolist()  # exact through JSON
            assert [m.colour for m in view.marks] == rendered.truth.mark_colour
            assert [m.fully_visible for m in view.marks] == rendered.truth.fully_visible.tolist()
    world = ds.world()
    assert world.name == "exp2" and world.frames == FRAMES and world.path == dataset_dir / "world.yaml"
    assert np.array_equal(world.model.mark_points, scenario.model.mark_points)
    assert yaml.safe_load((dataset_dir / "world.yaml").read_text())["target"]["model"] == "model.yaml"
    assert (dataset_dir / "model.yaml").read_bytes() == (ROOT / "scenarios/models/pioneer.yaml").read_bytes()


def test_a_camera_folder_opens_its_dataset(dataset_dir):
    assert locate_dataset(dataset_dir) == (dataset_dir, None)
    assert locate_dataset(dataset_dir / "H2") == (dataset_dir, "H2")
    assert locate_dataset(dataset_dir.parent) is None
    assert open_dataset(dataset_dir / "H2").root == dataset_dir


def test_camera_info_is_read_back_exactly_by_the_agents_reader(tmp_path):
    """The writer lives in scenarios/, the fleet's camera_info reader in agents/problem: they agree to the bit,
    distortion included."""
    odd = Camera(1234.5678901234, 1230.000000001, 321.123456789, 239.987654321, 640, 480,
                 np.array([-0.123456789, 0.0456, 1e-05, -2.5e-06, 0.001]))
    root = write_dataset(tmp_path / "ds", frames=1, intrinsics={"H1": odd})
    for camera, expected in (("H1", odd), ("H2", load_scenario("exp2").camera("H2", 0))):
        agents_view = read_camera_info(root / camera / "camera_info.yaml")
        ours = open_dataset(root).intrinsics(camera)
        for c in (agents_view, ours):
            assert (c.fx, c.fy, c.cx, c.cy, c.width, c.height) == (expected.fx, expected.fy, expected.cx, expected.cy,
                                                                   expected.width, expected.height)
            assert np.array_equal(c.distortion, expected.distortion)
    document = yaml.safe_load((root / "H1" / "camera_info.yaml").read_text())
    assert document["camera_name"] == "H1" and document["distortion_model"] == "plumb_bob"
    assert document["projection_matrix"]["data"][:3] == [odd.fx, 0.0, odd.cx]


def test_a_world_that_extends_another_is_written_resolved(tmp_path):
    root = write_dataset(tmp_path / "ds", world="exp2-degraded", frames=1, cameras=["H2"])
    document = yaml.safe_load((root / "world.yaml").read_text())
    assert "extends" not in document and document["target"]["model"] == "model.yaml"
    ds = open_dataset(root)
    assert ds.cameras == ("H2",) and not (root / "H1").exists()
    assert ds.world().spec == load_scenario("exp2-degraded").spec.model_copy(
        update={"frames": 1, "fps": 10.0, "target": ds.world().spec.target})


def test_resuming_goes_on_after_the_last_complete_frame(tmp_path):
    root = write_dataset(tmp_path / "ds", frames=2)
    # a run cut short in frame 2 of 4: H1's image and poses line, half of H2's, no truth line
    manifest = yaml.safe_load((root / "manifest.yaml").read_text())
    manifest["frames"] = 4
    (root / "manifest.yaml").write_text(yaml.safe_dump(manifest))
    world = yaml.safe_load((root / "world.yaml").read_text())
    world["frames"] = 4
    (root / "world.yaml").write_text(yaml.safe_dump(world))
    shutil.copy(root / "H1" / "000001.png", root / "H1" / "000002.png")
    with open(root / "H1" / "poses.jsonl", "a") as f:
        f.write(json.dumps({"frame": 2, "world_from_camera": dict(x=0, y=0, z=0, roll=0, pitch=0, yaw=0)}) + "\n")
    with open(root / "H2" / "poses.jsonl", "a") as f:
        f.write('{"frame": 2, "world_from')
    with pytest.raises(DatasetError, match="exists and is not an empty directory"):
        DatasetWriter(root, "exp2", engine={"name": "opencv"}, frames=4)
    with pytest.raises(DatasetError, match=r"manifest.yaml: frames: the dataset has 4, resuming would write 5"):
        DatasetWriter(root, "exp2", engine={"name": "opencv"}, frames=5, resume=True)
    writer = DatasetWriter(root, "exp2", engine={"name": "opencv"}, frames=4, resume=True)
    assert writer.next_frame == writer.complete_frames() == 2 and not writer.done
    assert len((root / "H1" / "poses.jsonl").read_text().splitlines()) == 2
    assert (root / "H2" / "poses.jsonl").read_text().endswith("}\n")  # the cut line is gone
    with pytest.raises(DatasetError, match="frame 3 out of order: frame 2 is next"):
        writer.append_pose("H1", 3, np.eye(4))
    with pytest.raises(DatasetError, match="write the image and the poses line before the truth line"):
        writer.append_truth(2, np.zeros(6), {c: render_frame(writer.scenario, 2, c).truth for c in writer.cameras})
    write_dataset(root, frames=4, resume=True)
    ds = open_dataset(root)
    assert ds.frames == 4 and np.array_equal(ds.truth(3).target_pose, load_scenario("exp2").target_pose(3))
    assert np.allclose(ds.camera("H1", 2).world_from_camera, load_scenario("exp2").camera("H1", 2).world_from_camera,
                       atol=1e-12)


def test_writer_inputs_are_checked(tmp_path):
    with pytest.raises(DatasetError, match="no vehicle 'H9' to render"):
        DatasetWriter(tmp_path / "a", "exp2", engine={"name": "opencv"}, cameras=["H9"])
    with pytest.raises(DatasetError, match=r"manifest.yaml: engine.name: expected 'cycles' or 'opencv'"):
        DatasetWriter(tmp_path / "b", "exp2", engine={"name": "povray"})
    with pytest.raises(DatasetError, match=r"manifest.yaml: frames: must be >= 1"):
        DatasetWriter(tmp_path / "c", "exp2", engine={"name": "opencv"}, frames=0)
    writer = DatasetWriter(tmp_path / "d", "exp2", engine={"name": "cycles", "samples": 24, "blender": "4.5.3"},
                           frames=2, camera_model={"jpeg_quality": 90})
    assert writer.image_path("H2", 7) == tmp_path / "d" / "H2" / "000007.jpg"
    assert image_name(12, ".png") == "000012.png"
    with pytest.raises(DatasetError, match="image suffix '.exr' is not one of"):
        writer.image_path("H1", 0, ".exr")
    with pytest.raises(DatasetError, match="no camera 'H3'"):
        writer.image_path("H3", 0)
    manifest = yaml.safe_load((tmp_path / "d" / "manifest.yaml").read_text())
    assert manifest["engine"] == {"name": "cycles", "samples": 24, "blender": "4.5.3"}
    assert manifest["camera_model"] == {"jpeg_quality": 90} and writer.complete_frames() == 0


def test_jpeg_images_are_written_and_read(tmp_path):
    root = write_dataset(tmp_path / "ds", frames=1, suffix=".jpg")
    ds = open_dataset(root)
    assert ds.image_path("H1", 0).name == "000000.jpg"
    assert cv2.imread(str(ds.image_path("H1", 0))).shape == (480, 640, 3)


# -- one line per malformed file ------------------------------------------------------------------------------


def edit_yaml(path: Path, change) -> None:
    document = yaml.safe_load(path.read_text())
    change(document)
    path.write_text(yaml.safe_dump(document))


def edit_line(path: Path, n: int, change) -> None:
    """Change line ``n`` (1-based) of a JSON-lines file: ``change(dict)`` in place, or a str replacing it."""
    lines = path.read_text().splitlines()
    if isinstance(change, str):
        lines[n - 1] = change
    else:
        document = json.loads(lines[n - 1])
        change(document)
        lines[n - 1] = json.dumps(document)
    path.write_text("\n".join(lines) + "\n")


def _set(path: list, value):
    def change(document):
        for key in path[:-1]:
            document = document[key]
        document[path[-1]] = value
    return change


def _delete(path: list):
    def change(document):
        for key in path[:-1]:
            document = document[key]
        del document[path[-1]]
    return change


MANIFEST_CASES = [
    (_set(["format"], "evopose-dataset/2"), "manifest.yaml: format: expected 'evopose-dataset/1'"),
    (_set(["frames"], 0), "manifest.yaml: frames: must be >= 1"),
    (_set(["fps"], -1), "manifest.yaml: fps: must be > 0"),
    (_set(["cameras"], ["H1", "H1"]), "manifest.yaml: cameras: camera names must be unique"),
    (_set(["cameras"], ["../etc"]), "manifest.yaml: cameras[0]: "),
    (_set(["cameras"], []), "manifest.yaml: cameras: must not be empty"),
    (_set(["engine"], {"samples": 3}), "manifest.yaml: engine.name: required field missing"),
    (_set(["lens"], "wide"), "manifest.yaml: lens: unknown key"),
    (_delete(["world"]), "manifest.yaml: world: required field missing"),
    (_set(["cameras"], ["H1", "H2", "H3"]), "manifest.yaml: cameras: no folder H3/ for camera 'H3'"),
    (_set(["frames"], 4), "poses.jsonl: 3 lines, the manifest says 4 frames"),
]


@pytest.mark.parametrize("change, expected", MANIFEST_CASES)
def test_a_malformed_manifest_is_one_line_naming_the_field(copy, change, expected):
    edit_yaml(copy / "manifest.yaml", change)
    assert_one_line(copy, expected)


LINE_CASES = [
    ("truth.jsonl", 2, _set(["target_pose", "yaw"], "north"), "truth.jsonl:2: target_pose.yaw: expected a number"),
    ("truth.jsonl", 2, _delete(["target_pose", "z"]), "truth.jsonl:2: target_pose.z: required field missing"),
    ("truth.jsonl", 3, _set(["frame"], 7), "truth.jsonl:3: frame: expected 2 (frames in order from 0), got 7"),
    ("truth.jsonl", 1, _set(["cameras", "H1", "marks", 0, "uv"], [1.0]), "truth.jsonl:1: cameras.H1.marks[0].uv: "),
    ("truth.jsonl", 1, _set(["cameras", "H1", "marks", 0, "index"], -1),
     "truth.jsonl:1: cameras.H1.marks[0].index: must be >= 0"),
    ("truth.jsonl", 2, _delete(["cameras", "H2"]), "truth.jsonl:2: cameras: expected H1, H2, got H1"),
    ("truth.jsonl", 2, _set(["extra"], 1), "truth.jsonl:2: extra: unknown key"),
    ("truth.jsonl", 2, '{"frame": 1, "frame": 1}', "truth.jsonl:2: invalid JSON: duplicate key 'frame'"),
    ("truth.jsonl", 2, '{"frame": NaN}', "truth.jsonl:2: invalid JSON: NaN is not a number JSON allows"),
    ("truth.jsonl", 2, "[1, 2]", "truth.jsonl:2: expected a JSON object, got a list"),
    ("truth.jsonl", 2, '{"frame": 1,', "truth.jsonl:2:13: invalid JSON"),
    ("truth.jsonl", 2, "", "truth.jsonl:2: empty line"),
    ("truth.jsonl", 2, "[" * 40 + "]" * 40, "truth.jsonl:2: invalid JSON: nesting deeper than 32 levels"),
    ("H2/poses.jsonl", 3, _delete(["world_from_camera", "yaw"]),
     "H2/poses.jsonl:3: world_from_camera.yaw: required field missing"),
    ("H1/poses.jsonl", 1, _set(["world_from_camera", "x"], None), "H1/poses.jsonl:1: world_from_camera.x: "),
    ("H1/poses.jsonl", 2, _set(["frame"], 0), "H1/poses.jsonl:2: frame: expected 1"),
    ("H1/poses.jsonl", 2, "x" * 5000, "H1/poses.jsonl:2: line is 5000 bytes, more than the limit of 4096"),
]


@pytest.mark.parametrize("file, line, change, expected", LINE_CASES)
def test_a_malformed_json_line_is_one_line_naming_the_file_line_and_field(copy, file, line, change, expected):
    edit_line(copy / file, line, change)
    assert_one_line(copy, expected)


def test_other_malformed_files_are_one_line(copy):
    edit_yaml(copy / "H1" / "camera_info.yaml", _set(["camera_matrix", "data", 1], 2.0))
    assert_one_line(copy, "H1/camera_info.yaml: camera_matrix: expected [fx, 0, cx, 0, fy, cy, 0, 0, 1] (no skew)")
    edit_yaml(copy / "H1" / "camera_info.yaml", _delete(["camera_matrix"]))
    assert_one_line(copy, "H1/camera_info.yaml: camera_matrix: required field missing")
    (copy / "H1" / "camera_info.yaml").unlink()
    assert_one_line(copy, "H1/camera_info.yaml: cannot read: No such file")


def test_missing_and_doubled_images_and_a_missing_dataset_are_named(copy, dataset_dir, tmp_path):
    (copy / "H2" / "000001.png").unlink()
    assert_one_line(copy, "H2: no image of frame 1 (000001.jpg or another image suffix); the manifest says 3 frames")
    shutil.copy(copy / "H2" / "000000.png", copy / "H2" / "000001.png")
    shutil.copy(copy / "H2" / "000000.png", copy / "H2" / "000001.jpg")
    assert_one_line(copy, "H2: two images of frame 1: ")
    assert_one_line(tmp_path / "nothing", "nothing: no such directory")
    assert_one_line(tmp_path, "not a dataset directory (no manifest.yaml)")
    (copy / "H2" / "000001.jpg").unlink()
    (copy / "truth.jsonl").write_text("")
    assert_one_line(copy, "truth.jsonl: 0 lines, the manifest says 3 frames")
    (copy / "truth.jsonl").unlink()  # a recording without ground truth: allowed
    ds = open_dataset(copy)
    assert not ds.has_truth and ds.truth(0) is None
    with pytest.raises(DatasetError, match="frame 3 out of range: the dataset has frames 0..2"):
        ds.camera("H1", 3)
    with pytest.raises(DatasetError, match="no camera 'H7'"):
        ds.image_path("H7", 0)
    (copy / "world.yaml").unlink()
    with pytest.raises(DatasetError, match="world.yaml: the dataset has no world.yaml"):
        ds.world()
    (copy / "model.yaml").write_text("name: broken\n")
    (copy / "world.yaml").write_text((dataset_dir / "world.yaml").read_text())
    with pytest.raises(DatasetError, match=r"world.yaml: target.model: .*model.yaml: mark_radius: required field"):
        ds.world()


def assert_one_line(path: Path, expected: str) -> None:
    with pytest.raises(DatasetError) as err:
        open_dataset(path)
    message = str(err.value)
    assert isinstance(err.value, WorldError) and "\n" not in message and expected in message, message
