"""The camera model (scenarios.camera_model), judged by what it does to images: chroma subsampling, demosaicing
fringes, shot and read noise, auto exposure, the tone curve, JPEG quality, reproducibility, the schema's errors."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from scenarios.camera_model import (
    CameraModelSpec, capture, decode, linear_from_srgb, sensor, srgb_from_linear, tone_lut,
)
from scenarios.errors import ScenarioError
from scenarios.target import MODELS_DIR
from scenarios.world import SCENARIOS_DIR, load_scenario

#: A camera without noise, mosaic or loss: each test switches on the stage it judges.
CLEAN = CameraModelSpec(exposure=1.0, bayer="none", read_noise=0.0, full_well=1e7, bit_depth=16, jpeg_quality=None)


def _rng(seed: int = 0) -> np.random.Generator:
    return np.random.default_rng(seed)


def _grey(h: int = 64, w: int = 64, level: float = 0.18) -> np.ndarray:
    return np.full((h, w, 3), level, np.float32)


def _chroma_luma(image: np.ndarray, v: int, u: int, background: np.ndarray) -> tuple[float, float]:
    ycc = cv2.cvtColor(image, cv2.COLOR_BGR2YCrCb).astype(float)
    bg = cv2.cvtColor(background, cv2.COLOR_BGR2YCrCb).astype(float)[v, u]
    return float(np.linalg.norm(ycc[v, u, 1:] - bg[1:])), float(abs(ycc[v, u, 0] - bg[0]))


def test_srgb_round_trip():
    values = np.arange(256, dtype=np.uint8)
    assert np.array_equal(srgb_from_linear(linear_from_srgb(values)), values)
    assert linear_from_srgb(np.array([0, 255], np.uint8)).tolist() == [0.0, 1.0]
    np.testing.assert_allclose(linear_from_srgb(np.array([118.0])), 0.18, atol=0.003)  # mid-grey
    for shape in ((7, 3), (4, 5, 3), (2, 2, 2, 3), (3, 3, 7)):  # images (a table in OpenCV) and other arrays
        values = _rng(1).integers(0, 256, shape).astype(np.uint8)
        np.testing.assert_allclose(linear_from_srgb(values), linear_from_srgb(values.astype(float)), atol=1e-6)


def test_jpeg_420_washes_out_a_small_discs_colour_but_keeps_its_brightness():
    """A 3 px saturated disc on grey: 4:2:0 halves the chroma resolution, so most of its colour leaks away,
    while luminance (full resolution in both) keeps its contrast."""
    scene = _grey(48, 48)
    cv2.circle(scene, (23, 23), 1, (0.02, 0.02, 0.9), -1)  # a red disc, 3 px across
    background = capture(_grey(48, 48), CLEAN.model_copy(update={"jpeg_quality": 90}), _rng()).image
    out = {chroma: capture(scene, CLEAN.model_copy(update={"jpeg_quality": 90, "chroma": chroma}), _rng()).image
           for chroma in ("420", "444")}
    chroma_420, luma_420 = _chroma_luma(out["420"], 23, 23, background)
    chroma_444, luma_444 = _chroma_luma(out["444"], 23, 23, background)
    assert chroma_420 < 0.6 * chroma_444
    assert luma_420 > 0.7 * luma_444 and luma_420 > 10


def test_bayer_bilinear_fringes_a_grey_edge_and_keeps_a_flat_patchs_hue():
    edge = _grey(32, 32, 0.03)
    edge[:, 16:] = 0.6  # a sharp vertical grey edge
    spread = {}
    for bayer in ("none", "RGGB"):
        image = capture(edge, CLEAN.model_copy(update={"bayer": bayer}), _rng()).image.astype(int)
        near = image[4:28, 13:19]
        spread[bayer] = (near.max(axis=2) - near.min(axis=2)).max()  # the most coloured pixel by the edge
    assert spread["none"] <= 1 and spread["RGGB"] > 20
    patch = np.zeros((32, 32, 3), np.float32)
    patch[:] = (0.05, 0.45, 0.6)  # an orange-yellow, BGR linear
    reference = cv2.cvtColor(capture(patch, CLEAN, _rng()).image, cv2.COLOR_BGR2HSV)[16, 16]
    for bayer in ("RGGB", "BGGR", "GRBG", "GBRG"):
        for method in ("bilinear", "vng", "edge-aware"):
            spec = CLEAN.model_copy(update={"bayer": bayer, "demosaic": method})
            hsv = cv2.cvtColor(capture(patch, spec, _rng()).image, cv2.COLOR_BGR2HSV)[16, 16]
            assert abs(int(hsv[0]) - int(reference[0])) <= 1, (bayer, method)


@pytest.mark.parametrize("bayer", ["RGGB", "BGGR", "GRBG", "GBRG"])
def test_a_uniform_red_patch_stays_red(bayer):
    """OpenCV names Bayer patterns shifted by a row and a column: the mapping must keep red red."""
    patch = np.zeros((16, 16, 3), np.float32)
    patch[..., 2] = 0.5
    for method in ("bilinear", "vng", "edge-aware"):
        b, g, r = capture(patch, CLEAN.model_copy(update={"bayer": bayer, "demosaic": method}), _rng()).image[8, 8]
        assert r > 150 and b < 5 and g < 5, (bayer, method)


def test_shot_noise_grows_with_the_signal_and_read_noise_sets_the_floor():
    """In electrons (full well 4095 at 12 bits: one code per electron) shot noise variance equals the signal,
    read noise adds its square."""
    spec = CameraModelSpec(full_well=4095, bit_depth=12, read_noise=0.0)
    bright, dark = np.full((200, 200), 2000 / 4095, np.float32), np.full((200, 200), 200 / 4095, np.float32)
    var_bright, var_dark = sensor(bright, spec, _rng(1)).var(), sensor(dark, spec, _rng(2)).var()
    assert var_bright / var_dark == pytest.approx(10, rel=0.1)
    assert var_dark == pytest.approx(200, rel=0.1)
    faint = np.full((200, 200), 30 / 4095, np.float32)  # the Poisson branch
    raw = sensor(faint, spec, _rng(3))
    assert raw.mean() == pytest.approx(30, rel=0.03) and raw.var() == pytest.approx(30, rel=0.1)
    noisy = spec.model_copy(update={"read_noise": 10.0})
    assert sensor(dark, noisy, _rng(4)).var() == pytest.approx(200 + 100, rel=0.1)
    assert sensor(np.zeros((8, 8), np.float32), spec, _rng(5)).max() == 0  # no light, no read noise: black


def test_auto_exposure_brings_scenes_of_any_brightness_to_the_same_level():
    texture = (0.05 + 0.3 * _rng(7).random((64, 64, 3))).astype(np.float32)
    auto = CameraModelSpec(bayer="none", read_noise=0.0, full_well=1e7, jpeg_quality=None)
    dim, bright = (capture(texture * s, auto, _rng()).image.astype(float) for s in (0.01, 50.0))
    assert np.abs(dim - bright).max() <= 1
    grey = capture(_grey(32, 32, 7.0), auto, _rng()).image
    assert abs(int(np.median(grey)) - 118) <= 1  # the median at 0.18 of saturation: sRGB mid-grey
    brighter = capture(_grey(32, 32, 7.0), auto.model_copy(update={"exposure_bias_ev": 1.0}), _rng()).image
    assert abs(int(np.median(brighter)) - int(srgb_from_linear(np.array(0.36)))) <= 1
    fixed = [capture(texture * s, auto.model_copy(update={"exposure": 1.0}), _rng()).image.mean()
             for s in (0.5, 2.0)]
    assert fixed[1] > fixed[0] + 40
    # a small bright highlight does not drag the exposure down (the percentile), a large one does
    spot = _grey(100, 100, 0.1)
    spot[:5, :5] = 100.0
    assert int(np.median(capture(spot, auto, _rng()).image)) == pytest.approx(118, abs=2)


@pytest.mark.parametrize("tone", ["srgb", "gamma", "filmic"])
def test_tone_curve_is_monotone_from_black_to_white(tone):
    lut = tone_lut(tone, 2.2, 12).astype(int)
    assert lut[0] == 0 and lut[-1] == 255 and np.all(np.diff(lut) >= 0)
    spec = CLEAN.model_copy(update={"tone": tone, "bit_depth": 12})
    assert capture(_grey(8, 8, 0.0), spec, _rng()).image.max() == 0
    assert capture(_grey(8, 8, 3.0), spec, _rng()).image.min() == 255
    ramp = np.repeat(np.linspace(0, 1, 64, dtype=np.float32)[None, :, None], 3, axis=2)
    assert np.all(np.diff(capture(np.repeat(ramp, 4, axis=0), spec, _rng()).image[2, :, 1].astype(int)) >= 0)


def test_lower_jpeg_quality_loses_more():
    texture = cv2.GaussianBlur(_rng(3).random((96, 128, 3)).astype(np.float32), (0, 0), 1.5)
    lossless = capture(texture, CLEAN, _rng())
    assert lossless.suffix == ".png" and np.array_equal(decode(lossless.encoded), lossless.image)
    psnr, sizes = [], []
    for quality in (10, 30, 60, 85, 98):
        shot = capture(texture, CLEAN.model_copy(update={"jpeg_quality": quality}), _rng())
        assert shot.suffix == ".jpg" and np.array_equal(decode(shot.encoded), shot.image)
        psnr.append(cv2.PSNR(shot.image, lossless.image))
        sizes.append(len(shot.encoded))
    assert np.all(np.diff(psnr) > 0) and np.all(np.diff(sizes) > 0), (psnr, sizes)


def test_capture_is_reproducible_with_a_seed():
    scene = (_rng(9).random((40, 60, 3)) * 2).astype(np.float32)
    spec = CameraModelSpec()
    first, again, other = (capture(scene, spec, _rng(seed)) for seed in (5, 5, 6))
    assert first.encoded == again.encoded and np.array_equal(first.image, again.image)
    assert first.encoded != other.encoded
    assert first.image.shape == (40, 60, 3) and first.image.dtype == np.uint8


def test_white_balance_and_motion_blur():
    tinted = capture(_grey(16, 16, 0.2), CLEAN.model_copy(update={"white_balance": [0.8, 1.0, 1.25]}), _rng()).image
    b, g, r = tinted[8, 8].astype(int)
    assert r > g > b
    dot = np.zeros((41, 41, 3), np.float32)
    dot[20, 20] = 1.0
    streak = capture(dot, CLEAN.model_copy(update={"motion_blur_px": 10, "tone": "gamma", "gamma": 1.0}),
                     _rng()).image[..., 1]
    v, u = np.nonzero(streak > 0)
    assert np.ptp(u) >= 9 and np.ptp(v) <= 1  # a horizontal streak 10 px long
    vertical = capture(dot, CLEAN.model_copy(update={"motion_blur_px": 10, "motion_blur_angle_deg": 90}),
                       _rng()).image[..., 1]
    v, u = np.nonzero(vertical > 0)
    assert np.ptp(v) >= 9 and np.ptp(u) <= 1


def test_capture_refuses_a_non_image():
    with pytest.raises(ValueError, match="shape"):
        capture(np.zeros((4, 4), np.float32), CLEAN, _rng())
    with pytest.raises(ValueError, match="non-finite"):
        capture(np.full((4, 4, 3), np.nan, np.float32), CLEAN, _rng())


@pytest.mark.parametrize("camera_model, expected", [
    ({"bayer": "XGGB"}, "render.camera_model.bayer"),
    ({"jpeg_quality": 101}, "render.camera_model.jpeg_quality"),
    ({"chroma": 422}, "render.camera_model.chroma"),
    ({"full_well": -5}, "render.camera_model.full_well"),
    ({"exposure": "manual"}, "render.camera_model.exposure"),
    ({"white_balance": [1, 1]}, "render.camera_model.white_balance"),
    ({"demosaic": "magic"}, "render.camera_model.demosaic"),
    ({"shutter": 0.01}, "render.camera_model.shutter: unknown key"),
])
def test_invalid_camera_models_are_one_line_errors(tmp_path: Path, camera_model, expected):
    document = yaml.safe_load((SCENARIOS_DIR / "exp2.yaml").read_text(encoding="utf-8"))
    document["target"]["model"] = str(MODELS_DIR / "pioneer.yaml")
    document.setdefault("render", {})["camera_model"] = camera_model
    path = tmp_path / "world.yaml"
    path.write_text(yaml.safe_dump(document), encoding="utf-8")
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    message = str(info.value)
    assert expected in message and "\n" not in message and "world.yaml" in message


def test_a_camera_model_in_yaml_loads():
    document = {"exposure": "auto", "chroma": 444, "jpeg_quality": None, "white_balance": [0.95, 1, 1.05]}
    spec = CameraModelSpec.model_validate(document)
    assert spec.chroma == "444" and spec.jpeg_quality is None and spec.bayer == "RGGB"


# --- the renderer with a camera model: sun shading, the highlight, clutter -------------------------------------

#: A camera that keeps what the renderer drew: fixed exposure, no mosaic, no noise, lossless.
PLAIN = {"exposure": 1.0, "bayer": "none", "read_noise": 0.0, "full_well": 1e7, "bit_depth": 16, "jpeg_quality": None}


def _lit_world(eye, sun=(0.0, 0.0, 1.0), clutter=(), camera_model=PLAIN, **lighting):
    from scenarios.world import ScenarioSpec, build_scenario
    document = {
        "name": "lit", "target": {"model": str(MODELS_DIR / "pioneer.yaml"), "trajectory": {"start": {}}},
        "vehicles": [{"name": "C", "trajectory": {"start": dict(zip("xyz", eye))},
                      "camera": {"intrinsics": {"fx": 700, "fy": 700, "cx": 160, "cy": 120, "width": 320,
                                                "height": 240},
                                 "look_at": [0.0, 0.0, 0.12]}}],
        "render": {"lighting": {"ambient": 0.3, "sun": list(sun), **lighting}, "clutter": list(clutter),
                   "camera_model": camera_model},
    }
    return build_scenario(ScenarioSpec.model_validate(document))


def _face_median(frame, scenario, normal, channel: int) -> float:
    """Median of ``channel`` over the body's red face with this ``normal`` (eroded: no edge pixels)."""
    body = scenario.model.body  # the target stands at the origin, unturned: its frame is the world's
    red = [i for i in range(len(body)) if body.colours[i][2] > body.colours[i][1] + 50
           and np.allclose(body.normals[i], normal, atol=1e-6)]
    mask = np.zeros(frame.image.shape[:2], np.uint8)
    for i in red:
        uv, _ = frame.camera.project_world(body.vertices[body.faces[i]])
        cv2.fillConvexPoly(mask, np.round(uv).astype(np.int32), 255)
    mask = cv2.erode(mask, np.ones((5, 5), np.uint8))
    assert mask.sum() > 255 * 50, "the face is not in view"
    return float(np.median(frame.image[..., channel][mask > 0]))


def test_the_sunlit_top_is_brighter_than_a_side():
    from scenarios.render import render_frame
    world = _lit_world((2.5, 0.6, 2.2), specular=0.0)
    frame = render_frame(world, 0)
    top = _face_median(frame, world, (0, 0, 1), 2)
    side = _face_median(frame, world, (1, 0, 0), 2)
    assert top > side + 40  # Lambert: the sun straight above lights the top only (ambient 0.3 on the sides)


def test_a_highlight_shows_where_the_view_mirrors_the_sun():
    from scenarios.render import render_frame
    sun = np.array([0.3, 0.4, 1.0]) / np.linalg.norm([0.3, 0.4, 1.0])
    mirror = 4.0 * np.array([-sun[0], -sun[1], sun[2]])  # the sun's reflection off the top points here
    away = 4.0 * sun  # beside the sun: the half vector is the sun's, 27 deg off the top's normal
    green = {}
    for name, eye in (("mirror", mirror), ("away", away)):
        for specular in (0.0, 0.25):
            world = _lit_world(eye, sun=sun, specular=specular, shininess=60)
            green[name, specular] = _face_median(render_frame(world, 0), world, (0, 0, 1), 1)
    assert green["mirror", 0.25] > green["mirror", 0.0] + 60  # dark red paint turns pale in the glint
    assert abs(green["away", 0.25] - green["away", 0.0]) <= 3


@pytest.mark.parametrize("shape, centre, size, eye, camera_model", [
    ("box", [1.5, 0.0, 0.6], [0.3, 1.2, 1.2], (3.0, 0.0, 1.5), PLAIN),
    ("box", [1.5, 0.0, 0.6], [0.3, 1.2, 1.2], (3.0, 0.0, 1.5), None),  # the 8-bit path draws clutter too
    ("cylinder", [1.5, 0.0, 0.6], [0.8, 1.2, 1.2], (3.0, 0.0, 1.5), PLAIN),
    ("sphere", [1.5, 0.0, 0.7], [1.2, 1.2, 1.2], (3.0, 0.0, 1.5), PLAIN),
    ("disc", [0.0, 0.0, 0.6], [1.2, 1.2, 0.03], (0.5, 0.0, 4.0), PLAIN),  # a table top over the robot
])
def test_clutter_hides_marks_in_the_image_and_the_truth(shape, centre, size, eye, camera_model):
    from scenarios.render import render_frame
    clutter = {"shape": shape, "centre": centre, "size": size, "colour": [200, 180, 60]}  # a blue bin
    open_view = render_frame(_lit_world(eye, camera_model=camera_model), 0)
    hidden = render_frame(_lit_world(eye, clutter=[clutter], camera_model=camera_model), 0)
    assert len(open_view.truth.mark_index) >= 4 and len(hidden.truth.mark_index) == 0
    b, g, r = (hidden.image[int(v), int(u)].astype(int) for u, v in open_view.truth.mark_uv[:1]).__next__()
    assert b > r + 30  # where a mark was, the bin's paint


def test_lens_distortion_moves_each_point_where_the_camera_projects_it():
    # Blender renders a pinhole image; develop.distort resamples it through the lens. A spot drawn at a point's
    # pinhole projection must land where the project's own plumb_bob projection (evopose.Camera) puts that point,
    # not where the inverse mapping would (the spots are 5-20 px from their pinhole places near the corners)
    from evopose import Camera
    from scenarios.photoreal.develop import distort

    camera = Camera(800.0, 800.0, 320.0, 240.0, 640, 480, np.array([-0.28, 0.09, 0.001, -0.0015, 0.0]))
    pinhole = Camera(800.0, 800.0, 320.0, 240.0, 640, 480)
    points = np.array([[x, y, 1.0] for x in (-0.33, -0.12, 0.2, 0.33) for y in (-0.24, 0.05, 0.24)])
    expected, _ = camera.project_camera_points(points)
    undistorted, _ = pinhole.project_camera_points(points)
    yy, xx = np.mgrid[0:480, 0:640]
    image = np.zeros((480, 640), np.float32)
    for u, v in undistorted:
        image += np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * 1.5 ** 2)).astype(np.float32)
    seen = distort(image, camera)
    for (u, v), (u0, v0) in zip(expected, undistorted):
        x0, y0 = int(round(u)) - 8, int(round(v)) - 8
        patch = seen[y0:y0 + 17, x0:x0 + 17]
        py, px = np.mgrid[y0:y0 + 17, x0:x0 + 17]
        centroid = np.array([(patch * px).sum(), (patch * py).sum()]) / patch.sum()
        assert np.linalg.norm(centroid - (u, v)) < 0.25, ((u, v), centroid)
    moved = np.linalg.norm(expected - undistorted, axis=1)
    assert moved.max() > 5.0  # the lens moves the corner spots: the test can tell the mapping's direction
