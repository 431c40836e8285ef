"""The photoreal renderer's pure parts (no Blender): the scene description, the camera mapping onto Blender's
camera, the world schema's lighting and clutter, the OpenEXR reader, the truth's obstacles."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from evopose import Camera
from geometry import matrix_from_pose
from scenarios.errors import ScenarioError
from scenarios.photoreal.exr import read_exr
from scenarios.photoreal.scene import (ENGINE_DEFAULTS, FORMAT, blender_camera, blender_matrix, describe_frame,
                                       describe_scene, project_blender, render_seed, srgb_to_linear)
from scenarios.photoreal.shapes import MARK_STANDOFF, clutter_mesh, clutter_solid, cylinder, mark_disc
from scenarios.photoreal.truth import view_truth
from scenarios.render import render_frame
from scenarios.world import ClutterSpec, IntrinsicsSpec, load_scenario

DATA = Path(__file__).resolve().parent / "data" / "photoreal"


def _world(tmp_path: Path, text: str, name: str = "w.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


# -- the camera mapping ------------------------------------------------------------------------------------------

CAMERAS = [IntrinsicsSpec(fx=1700, fy=1700, cx=320, cy=240, width=640, height=480),
           IntrinsicsSpec(fx=12000, fy=12000, cx=320, cy=240, width=640, height=480),
           IntrinsicsSpec(fx=90.0, fy=90.0, cx=41.3, cy=37.8, width=97, height=61),
           IntrinsicsSpec(fx=500.0, fy=500.0, cx=150.2, cy=310.9, width=300, height=400)]  # taller than wide


@pytest.mark.parametrize("k", CAMERAS, ids=lambda k: f"{k.width}x{k.height}-f{k.fx:g}")
def test_blender_camera_projects_like_the_project_camera(k):
    rng = np.random.default_rng(5)
    pose = np.r_[rng.uniform(-30, 30, 3), rng.uniform(-np.pi, np.pi, 3)]
    T = matrix_from_pose(pose)
    camera = Camera(k.fx, k.fy, k.cx, k.cy, k.width, k.height, np.zeros(5), T)
    # points in front of the camera, across the whole image
    uv = rng.uniform([0, 0], [k.width, k.height], (50, 2))
    rays = np.linalg.solve(camera.matrix, np.c_[uv, np.ones(50)].T).T * rng.uniform(2, 40, (50, 1))
    points = rays @ T[:3, :3].T + T[:3, 3]
    expected, in_front = camera.project_world(points)
    assert in_front.all()
    got = project_blender(blender_camera(k), blender_matrix(T), points)
    assert np.abs(got - expected).max() < 1e-6


def test_blender_camera_looks_down_its_minus_z_with_y_up():
    T = matrix_from_pose([1.0, 2.0, 3.0, 0.3, -0.2, 1.1])
    B = blender_matrix(T)
    assert np.allclose(B[:3, 2], -T[:3, 2])   # Blender's -z is the optical axis
    assert np.allclose(B[:3, 1], -T[:3, 1])   # Blender's +y is the image's up (OpenCV's -y)
    assert np.allclose(B[:3, 0], T[:3, 0]) and np.allclose(B[:3, 3], T[:3, 3])
    assert np.linalg.det(B[:3, :3]) == pytest.approx(1.0)


def test_blender_camera_fields_and_square_pixels():
    cam = blender_camera(IntrinsicsSpec(fx=1150, fy=1150, cx=320, cy=240, width=640, height=480))
    assert cam["lens"] / cam["sensor_width"] * cam["width"] == 1150 and cam["sensor_fit"] == "HORIZONTAL"
    # the principal point (320, 240) is half a pixel right of and below the image's centre (319.5, 239.5)
    assert cam["shift_x"] == pytest.approx(-0.5 / 640) and cam["shift_y"] == pytest.approx(0.5 / 640)
    with pytest.raises(ScenarioError, match="square pixels"):
        blender_camera(IntrinsicsSpec(fx=1000, fy=1010, cx=320, cy=240, width=640, height=480), "H9")


def test_srgb_to_linear_is_the_standard_curve():
    assert srgb_to_linear([0, 0, 0]) == [0, 0, 0]
    assert srgb_to_linear([255, 255, 255]) == [1, 1, 1]
    r, g, b = srgb_to_linear([10, 128, 255])  # BGR in, RGB out
    assert r == pytest.approx(1.0) and g == pytest.approx(0.21586, abs=1e-5) and b == pytest.approx(10 / 255 / 12.92,
                                                                                                        abs=1e-6)


# -- the scene description ----------------------------------------------------------------------------------------

def test_scene_description_of_the_photoreal_world(tmp_path):
    world = load_scenario("exp2-photoreal")
    scene = describe_scene(world, tmp_path)
    assert scene["format"] == FORMAT and json.loads(json.dumps(scene)) == scene  # plain JSON
    assert scene["engine"] == ENGINE_DEFAULTS and scene["engine"]["denoise"] is False
    names = [o["name"] for o in scene["objects"]]
    model = world.model
    assert sum(n.startswith("part") for n in names) == len(model.parts)
    assert {n for n in names if n.startswith("marks-")} == {f"marks-{c}" for c in set(model.mark_colours)}
    assert sum(n.startswith("clutter") for n in names) == len(world.render.clutter) == 7
    assert names.count("occluder0") == 1
    by_name = {o["name"]: o for o in scene["objects"]}
    assert by_name["occluder0"]["parent"] == "mover" and by_name["part0"]["parent"] == "target"
    # materials: linear albedo of the model's colours, the roughness defaults
    assert scene["materials"]["part0"]["base_colour"] == srgb_to_linear(model.parts[0].colour)
    assert scene["materials"]["part0"]["roughness"] == 0.45
    assert scene["materials"]["mark-yellow"]["roughness"] == 0.35
    assert (tmp_path / "ground.png").is_file() and scene["materials"]["ground"]["tile"] == pytest.approx(10.24)
    light = scene["lighting"]
    assert light["sky"] == "clear" and light["sun_strength"] == 4.0
    assert light["sun_elevation"] == pytest.approx(np.radians(60), abs=1e-3)
    assert set(scene["cameras"]) == {"H1", "H2"}
    # one disc per mark, each with 2 x 32 vertices
    discs = sum(len(by_name[n]["vertices"]) for n in names if n.startswith("marks-"))
    assert discs == len(model.mark_points) * 4 * 32


def test_scene_without_target_and_overcast(tmp_path):
    path = _world(tmp_path, "extends: exp2-photoreal\nname: o\nrender: {lighting: {sky: overcast, sky_strength: 2}}\n")
    scene = describe_scene(load_scenario(path), tmp_path, target=False, cameras=["H2"])
    assert not any(o["parent"] == "target" for o in scene["objects"])
    assert scene["lighting"]["sky"] == "overcast" and scene["lighting"]["sky_strength"] == 2
    assert list(scene["cameras"]) == ["H2"]


def test_frame_description_moves_target_camera_and_occluders(tmp_path):
    path = _world(tmp_path, "extends: exp2-photoreal\nname: m\nrender:\n  occluders:\n"
                            "    - {centre: [1, 0, 0.5], size: [0.2, 0.2, 1], velocity: [0.5, 0, 0]}\n")
    world = load_scenario(path)
    frame = describe_frame(world, 4, {"H1": tmp_path / "a.exr", "H2": tmp_path / "b.exr"})
    assert np.allclose(frame["target"], matrix_from_pose(world.target_pose(4)))
    assert np.allclose(np.array(frame["movers"]["occluder0"])[:3, 3], [1 + 0.5 * 0.4, 0, 0.5])
    h1 = frame["renders"][0]
    assert np.allclose(h1["matrix"], blender_matrix(world.vehicle("H1").world_from_camera(0.4)))
    seeds = {r["seed"] for r in frame["renders"]} | {render_seed(world, 5, 0)}
    assert len(seeds) == 3 and describe_frame(world, 4, {"H1": tmp_path / "a.exr"})["renders"][0]["seed"] == h1["seed"]
    assert describe_frame(world, 0, {"H1": tmp_path / "a.exr"}, target=False)["target"] is None


def test_mark_disc_stands_off_its_face_along_the_normal():
    disc = mark_disc([0.1, 0.2, 0.3], [0, 0, 2.0], 0.025)
    assert np.allclose(disc.vertices.mean(axis=0), [0.1, 0.2, 0.3 + MARK_STANDOFF])
    radial = np.linalg.norm(disc.vertices[:, :2] - [0.1, 0.2], axis=1)
    assert np.allclose(radial, 0.025)
    side = mark_disc([0, 0, 0], [1, 0, 0], 0.03)
    assert np.allclose(side.vertices.mean(axis=0), [MARK_STANDOFF, 0, 0]) and np.ptp(side.vertices[:, 0]) < 0.0011


def test_clutter_shapes_have_their_size_and_outward_faces():
    for shape in ("box", "cylinder", "sphere", "disc"):
        spec = ClutterSpec(shape=shape, centre=[1, 2, 0.1], size=[0.2, 0.1, 0.2], colour=[0, 255, 255], yaw=0.0)
        solid = clutter_solid(spec)
        lo, hi = solid.vertices.min(axis=0), solid.vertices.max(axis=0)
        assert np.allclose((lo + hi) / 2, [1, 2, 0.1], atol=1e-9)
        assert np.allclose(hi - lo, [0.2, 0.1, 0.2], atol=1e-9)
        mesh = solid.mesh()
        out = mesh.centres - [1, 2, 0.1]
        assert (np.sum(mesh.normals * out, axis=1) > 0).all(), shape
    c = cylinder(0.1, 0.1, 0.2)
    assert sum(c.smooth) == len(c.faces) - 2  # smooth sides, flat caps
    assert len(clutter_mesh([spec, spec])) == 2 * len(clutter_solid(spec).faces)


# -- the world schema -----------------------------------------------------------------------------------------------

def test_every_shipped_world_keeps_the_defaults():
    light = load_scenario("exp2").render.lighting
    assert (light.sun_strength, light.sky, light.sky_strength) == (4.0, "clear", 1.0)
    assert load_scenario("exp2-paper-scale").render.clutter == []
    assert load_scenario("exp2").model.mark_roughness == 0.35


@pytest.mark.parametrize("block, field", [
    ("{lighting: {sky: foggy}}", "render.lighting.sky"),
    ("{lighting: {sun_strength: -1}}", "render.lighting.sun_strength"),
    ("{lighting: {sky_strength: 1000}}", "render.lighting.sky_strength"),
    ("{clutter: [{shape: cone, centre: [0, 0, 0], size: [1, 1, 1], colour: [0, 0, 0]}]}", "render.clutter[0].shape"),
    ("{clutter: [{shape: box, centre: [0, 0, 0], size: [1, 0, 1], colour: [0, 0, 0]}]}", "render.clutter[0].size"),
    ("{clutter: [{shape: box, centre: [0, 0], size: [1, 1, 1], colour: [0, 0, 0]}]}", "render.clutter[0].centre"),
    ("{clutter: [{shape: box, centre: [0, 0, 0], size: [1, 1, 1], colour: [0, 0, 300]}]}", "render.clutter[0].colour"),
    ("{clutter: [{shape: box, centre: [0, 0, 0], size: [1, 1, 1], colour: [0, 0, 0], roughness: 2}]}",
     "render.clutter[0].roughness"),
    ("{clutter: [{shape: box, centre: [0, 0, 0], size: [1, 1, 1], colour: [0, 0, 0], mass: 2}]}", "mass"),
])
def test_bad_lighting_and_clutter_are_one_line(tmp_path, block, field):
    path = _world(tmp_path, f"extends: exp2\nname: bad\nrender: {block}\n")
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    message = str(err.value)
    assert "\n" not in message and field in message and str(path) in message


def test_good_lighting_and_clutter(tmp_path):
    path = _world(tmp_path, "extends: exp2\nname: good\nrender:\n  lighting: {sky: overcast, sun_strength: 0, "
                            "sky_strength: 3.5}\n  clutter:\n    - {shape: disc, centre: [1, 1, 0.01], "
                            "size: [0.2, 0.2, 0.02], colour: [10, 20, 30], yaw: 1}\n")
    render = load_scenario(path).render
    assert render.lighting.sky == "overcast" and render.lighting.sky_strength == 3.5
    assert render.clutter[0].shape == "disc" and render.clutter[0].roughness == 0.5


def test_model_roughness_is_validated(tmp_path):
    from scenarios.errors import ModelFileError
    from scenarios.target import load_model

    text = Path("scenarios/models/pioneer.yaml").read_text(encoding="utf-8")
    (tmp_path / "m.yaml").write_text(text.replace("mark_radius: 0.025", "mark_radius: 0.025\nmark_roughness: 0.2")
                                     .replace("  colour: [40, 40, 150]", "  colour: [40, 40, 150]\n  roughness: 0.8"),
                                     encoding="utf-8")
    model = load_model(tmp_path / "m.yaml")
    assert model.mark_roughness == 0.2 and model.parts[0].roughness == 0.8 and model.parts[1].roughness == 0.45
    (tmp_path / "bad.yaml").write_text(text.replace("mark_radius: 0.025", "mark_radius: 0.025\nmark_roughness: 1.5"),
                                       encoding="utf-8")
    with pytest.raises(ModelFileError, match="mark_roughness"):
        load_model(tmp_path / "bad.yaml")


# -- the OpenEXR reader -----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("codec", ["zip", "zips", "none"])
def test_exr_reader_matches_blenders_own_reading(codec):
    expected = json.loads((DATA / "tiny-exr.json").read_text(encoding="utf-8"))
    h, w = expected["height"], expected["width"]
    rgba = np.array(expected["rgba_bottom_up"], np.float32).reshape(h, w, 4)
    image = read_exr(DATA / f"tiny-{codec}.exr")
    assert image.shape == (h, w, 3) and image.dtype == np.float32
    assert np.abs(image - rgba[::-1, :, 2::-1]).max() < 1e-5  # rows top-down, BGR
    assert image[..., 2].max() > 1.5  # values above 1 are kept (radiance is not clipped)


def test_exr_reader_errors_are_one_line(tmp_path):
    from scenarios.errors import ImageError

    (tmp_path / "x.exr").write_bytes(b"not an exr at all")
    for path in (tmp_path / "x.exr", tmp_path / "missing.exr"):
        with pytest.raises(ImageError) as err:
            read_exr(path)
        assert "\n" not in str(err.value) and str(path) in str(err.value)
    data = (DATA / "tiny-zip.exr").read_bytes()
    (tmp_path / "cut.exr").write_bytes(data[: len(data) // 2])
    with pytest.raises(ImageError):
        read_exr(tmp_path / "cut.exr")


# -- the truth ----------------------------------------------------------------------------------------------------------

def test_clutter_and_occluders_hide_marks_in_the_truth(tmp_path):
    world = load_scenario("exp2-photoreal-telephoto")
    clean = render_frame(world, 0, "H1", clean=True).truth
    plain = view_truth(world, 0, "H1")
    assert set(plain.mark_index) <= set(clean.mark_index) and len(plain.mark_index) >= 6
    # a box between H1 and the robot hides every mark
    eye = world.vehicle("H1").world_from_camera(0.0)[:3, 3]
    wall = (0.1 * eye + 0.9 * np.array([0, 0, 0.12])).round(3).tolist()
    path = _world(tmp_path, f"extends: exp2-photoreal-telephoto\nname: wall\nrender:\n  clutter:\n"
                            f"    - {{shape: box, centre: {wall}, size: [2, 2, 2], colour: [0, 0, 0]}}\n")
    hidden = view_truth(load_scenario(path), 0, "H1")
    assert len(hidden.mark_index) == 0
    assert len(view_truth(world, 0, "H1", target=False).mark_index) == 0
