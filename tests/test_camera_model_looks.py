"""The camera model's looks (docs/camera-model.md, "Looks"): Blender's view transforms as 3D LUTs, saturation, hue
rotation, lens blur, white balance; each stage tested by its effect. The defaults leave every capture what it was
before these stages existed (hashes of seeded captures taken before the change). No Blender needed: the LUTs are
committed (scenarios/view_luts.npz, baked by scenarios/photoreal/bake_view_luts.py)."""

from __future__ import annotations

import hashlib
import math
from typing import get_args

import numpy as np
import pytest

from scenarios.camera_model import (_YCBCR_FROM_BGR, LOOK_FIELD_DEFAULTS, CameraModelSpec, Tone, capture,
                                    colour_adjust, lens_blur, linear_from_srgb, spec_record, srgb_from_linear)
from scenarios.errors import WorldError
from scenarios.looks import LOOKS, RANDOM_TONES, apply_look, corner_look, look_spec, random_look
from scenarios.view_luts import (VIEW_LUTS_FILE, VIEW_TONES, apply_view_lut, view_grid, view_lut, view_transform,
                                 view_transform_codes)


def _radiance() -> np.ndarray:
    rng = np.random.default_rng(7)
    h, w = 48, 64
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    img = np.stack([x / w, y / h, (x + y) / (w + h)], axis=-1) * 2.0
    img += rng.random((h, w, 3), dtype=np.float32) * 0.3
    img[10:20, 10:20] = (0.05, 0.1, 3.0)
    return img.astype(np.float32)


#: sha256 of the encoded bytes and of the decoded image of seeded captures, taken before the look stages existed.
BEFORE_LOOKS = {
    "default": ({}, "32d01fb811dd957f760f34abc9f8971e1c1f63e44bc9e8b851087d7d63148c94",
                "569cb84e0855da60f88aea400576b89157dd95a1fd82df6271a7c54facc1e2a1"),
    "filmic": ({"tone": "filmic"}, "e302336e10c6e758c9eb88eee815b9c6dd4297e7251a5f2c71d0f9fc815a7e47",
               "74b58b84765898a6809c199fd311ac8a0af4b633c339b747f7c62b60598b55c9"),
    "gamma": ({"tone": "gamma", "gamma": 2.6}, "3642e18a2164a0db71c7b4f81137ee8f73ec87ddc398fc66efd4325a1c6fe6e9",
              "6fdce642c1de8b2d834c55c96bb1b18abe4da9537f2130871b4c2124d7dfabca"),
    "vng-png": ({"demosaic": "vng", "jpeg_quality": None},
                "42e7d7a12e4e37ca71d1d86dbe973231ed197a1511dc8d5c603c74a34b41e5b8",
                "c98930f407605ed0a832449ed0d8036719e07cbdee75e6a26c28e1d07cf9bf58"),
    "wb-blur": ({"white_balance": [0.8, 1.0, 1.2], "motion_blur_px": 3.0, "exposure_bias_ev": 1.0},
                "79742ecd2d4da2b6f97bc15c09e9dc488aaada616d0b2c08bb88902fb3dc9b0e",
                "7215e1334fd80f49211b9c11abcee84a79bd32d4135d4b38497942262fb644c6"),
    "none-444": ({"bayer": "none", "chroma": "444", "exposure": 0.5},
                 "d4a859b5adc6661fd2b7f7042f524189f0d1cf6efb6e9c409835ee6959a5fd20",
                 "660f23a650be23d6b3875a49e460c1c64fe88dd9c2a08ef798afe60d0f925e33"),
}


@pytest.mark.parametrize("name", sorted(BEFORE_LOOKS))
def test_defaults_capture_exactly_what_they_did_before_the_looks(name):
    fields, encoded, image = BEFORE_LOOKS[name]
    shot = capture(_radiance(), CameraModelSpec(**fields), np.random.default_rng(123))
    assert hashlib.sha256(shot.encoded).hexdigest() == encoded
    assert hashlib.sha256(shot.image.tobytes()).hexdigest() == image


def test_a_default_spec_is_recorded_without_the_look_fields():
    record = spec_record(CameraModelSpec())
    assert not set(LOOK_FIELD_DEFAULTS) & set(record)
    assert CameraModelSpec.model_validate(record) == CameraModelSpec()
    record = spec_record(CameraModelSpec(saturation=0.5, tone="blender-agx"))
    assert record["saturation"] == 0.5 and record["tone"] == "blender-agx" and "hue_rotation_deg" not in record


# --- measuring colour ---------------------------------------------------------------------------------------------

def _ycc(bgr) -> np.ndarray:
    return np.asarray(bgr, np.float64) @ _YCBCR_FROM_BGR.T


def _patch_capture(patch_srgb, **fields) -> np.ndarray:
    """A lossless, noise-free, three-chip capture of a grey scene with a colour patch; the patch's mean BGR."""
    radiance = np.full((64, 64, 3), linear_from_srgb(np.array([118, 118, 118], np.uint8)), np.float32)
    radiance[16:48, 16:48] = linear_from_srgb(np.array(patch_srgb, np.uint8))
    spec = CameraModelSpec(bayer="none", read_noise=0, full_well=1e7, jpeg_quality=None, **fields)
    image = capture(radiance, spec, np.random.default_rng(0)).image
    return image[24:40, 24:40].reshape(-1, 3).mean(axis=0)


ORANGE = [40, 120, 200]  # BGR, saturated but not clipped


def test_saturation_scales_the_chroma_about_the_luma():
    home = _ycc(_patch_capture(ORANGE))
    for saturation in (0.5, 1.4):
        ycc = _ycc(_patch_capture(ORANGE, saturation=saturation))
        assert abs(ycc[0] - home[0]) < 1.0  # the luma stays
        assert np.hypot(*ycc[1:]) / np.hypot(*home[1:]) == pytest.approx(saturation, abs=0.02)
    grey = _patch_capture([90, 90, 90], saturation=2.5)
    assert np.ptp(grey) < 1.0  # a grey has no chroma to scale


@pytest.mark.parametrize("angle", [20.0, -10.0])
def test_hue_rotation_turns_the_hue_angle_by_the_set_angle(angle):
    home, turned = _ycc(_patch_capture(ORANGE)), _ycc(_patch_capture(ORANGE, hue_rotation_deg=angle))
    turn = math.degrees(math.atan2(turned[2], turned[1]) - math.atan2(home[2], home[1]))
    assert turn == pytest.approx(angle, abs=1.0)
    assert np.hypot(*turned[1:]) == pytest.approx(np.hypot(*home[1:]), rel=0.02)
    assert abs(turned[0] - home[0]) < 1.0


def test_positive_hue_rotation_turns_red_towards_yellow():
    red = np.array([[[30, 30, 200]]], np.uint8)
    b, g, r = colour_adjust(red, 1.0, 30.0)[0, 0].astype(int)
    assert g > 30 + 20 and r > g  # more green: towards orange and yellow


def test_white_balance_gains_of_thirty_percent_either_way():
    gains = [0.7, 1.0, 1.3]
    linear = linear_from_srgb(_patch_capture([100, 100, 100], white_balance=gains).round().astype(np.uint8))
    assert linear[0] / linear[1] == pytest.approx(0.7, rel=0.04)
    assert linear[2] / linear[1] == pytest.approx(1.3, rel=0.04)


def test_lens_blur_spreads_an_edge_and_is_off_at_zero():
    edge = np.zeros((32, 32, 3), np.float32)
    edge[:, 16:] = 1.0
    assert lens_blur(edge, 0.0) is edge
    blurred = lens_blur(edge, 1.5)
    assert 0.1 < blurred[16, 14, 0] < 0.5 < blurred[16, 17, 0] < 0.9
    assert blurred.mean() == pytest.approx(edge.mean(), abs=1e-3)


# --- Blender's view transforms ------------------------------------------------------------------------------------

def test_lut_interpolation_reproduces_the_grid_nodes():
    nodes, step = view_grid()
    assert step == pytest.approx(0.5) and nodes[0] == 0 and nodes[-6] == 1.0  # saturation is a node
    rng = np.random.default_rng(1)
    idx = rng.integers(0, len(nodes), (500, 3))
    idx[:4] = [[0, 0, 0], [len(nodes) - 1] * 3, [0, len(nodes) - 1, 5], [25, 25, 25]]
    for tone in ("blender-agx", "blender-filmic"):
        lut = view_lut(tone)
        got = apply_view_lut(nodes[idx].astype(np.float32), lut)
        np.testing.assert_allclose(got, lut[idx[:, 0], idx[:, 1], idx[:, 2]], atol=2e-5)


def test_lut_interpolation_between_nodes_is_linear_in_log2():
    nodes, _ = view_grid()
    lut = view_lut("blender-agx")
    a, b = nodes[20], nodes[21]
    mid = math.sqrt(a * b)  # halfway in log2
    got = apply_view_lut(np.array([[mid, a, a]], np.float32), lut)[0]
    np.testing.assert_allclose(got, (lut[20, 20, 20] + lut[21, 20, 20]) / 2, atol=2e-5)


def test_blender_standard_is_the_srgb_curve():
    x = np.linspace(0, 1, 2001, dtype=np.float32)
    grey = np.repeat(x[:, None], 3, axis=1)
    diff = np.abs(view_transform(grey, "blender-standard").astype(int) - srgb_from_linear(grey).astype(int))
    assert diff.max() <= 1 and diff.mean() < 0.5
    assert view_transform(np.ones((1, 3), np.float32), "blender-standard").min() == 255


@pytest.mark.parametrize("tone", VIEW_TONES)
def test_view_transforms_are_monotone_along_a_grey_ramp(tone):
    x = np.concatenate([[0.0], np.geomspace(1e-5, 5.0, 3000)]).astype(np.float32)
    out = view_transform(np.repeat(x[:, None], 3, axis=1), tone).astype(int)
    # Khronos PBR Neutral is not separable near black and in its shoulder (it offsets by the smallest channel and
    # compresses by the largest): between the grid's nodes trilinear interpolation dips by up to 0.6 level there
    assert np.diff(out, axis=0).min() >= (-1 if tone == "blender-khronos-pbr-neutral" else 0)
    assert out[0].max() <= 1 and out[-1].min() >= 200
    assert np.abs(out - out[:, 1:2]).max() <= 1  # a grey stays grey


def test_agx_keeps_mid_grey_and_compresses_a_bright_saturated_colour():
    mid = view_transform(np.full((1, 3), 0.18, np.float32), "blender-agx")[0]
    assert np.all(np.abs(mid.astype(int) - srgb_from_linear(np.float32(0.18))) <= 1)
    bright_red = np.array([[0.02, 0.04, 0.95]], np.float32)  # BGR
    chroma = {tone: np.hypot(*_ycc(out)[0, 1:]) for tone, out in
              (("srgb", srgb_from_linear(bright_red)), ("blender-agx", view_transform(bright_red, "blender-agx")),
               ("blender-filmic", view_transform(bright_red, "blender-filmic")))}
    assert chroma["blender-agx"] < 0.75 * chroma["srgb"]
    assert chroma["blender-filmic"] < 0.9 * chroma["srgb"]
    # and AgX never clips to white: saturation (1.0) stays below 255
    assert view_transform(np.ones((1, 3), np.float32), "blender-agx").max() < 230


def test_the_raw_code_path_matches_the_level_path():
    rng = np.random.default_rng(2)
    codes = rng.integers(0, 4096, (40, 50, 3)).astype(np.uint16)
    codes[0, :4] = [[0, 0, 0], [4095, 4095, 4095], [1, 2, 3], [737, 737, 737]]
    for tone in ("blender-agx", "blender-agx-punchy"):
        fast = view_transform_codes(codes, tone, 12).astype(int)
        slow = view_transform(codes.astype(np.float32) / np.float32(4095), tone).astype(int)
        assert np.abs(fast - slow).max() <= 1


@pytest.mark.parametrize("demosaic", ["bilinear", "vng", "edge-aware"])
@pytest.mark.parametrize("tone", ["blender-agx", "blender-filmic-high-contrast"])
def test_a_red_patch_stays_red_through_a_blender_tone(tone, demosaic):
    radiance = np.full((64, 64, 3), 0.1, np.float32)
    radiance[16:48, 16:48] = (0.02, 0.03, 0.6)
    shot = capture(radiance, CameraModelSpec(tone=tone, demosaic=demosaic), np.random.default_rng(3))
    b, g, r = shot.image[24:40, 24:40].reshape(-1, 3).mean(axis=0)
    assert r > g + 40 and r > b + 40


def test_blender_tones_are_committed_and_small():
    assert set(get_args(Tone)) == {"srgb", "gamma", "filmic", *VIEW_TONES}
    assert VIEW_LUTS_FILE.stat().st_size < 1_500_000
    with np.load(VIEW_LUTS_FILE) as luts:
        assert str(luts["blender"]).startswith("4.5")
        assert sorted(str(v) for v in luts["views"]) == sorted(VIEW_TONES)


# --- named and random looks ---------------------------------------------------------------------------------------

def test_named_looks_are_valid_camera_models():
    base = CameraModelSpec()
    assert look_spec(base, "camera") == base
    assert len(LOOKS) >= 7
    for name in LOOKS:
        spec = look_spec(base, name)
        for key, value in LOOKS[name].items():
            assert getattr(spec, key) == value, (name, key)
    assert look_spec(base, "agx").tone == "blender-agx"
    assert look_spec(CameraModelSpec(jpeg_quality=None), "agx").jpeg_quality is None  # over the base


def test_looks_refuse_unknown_names_and_bad_fields():
    with pytest.raises(WorldError, match="unknown look 'sepia'"):
        look_spec(CameraModelSpec(), "sepia")
    with pytest.raises(WorldError, match="saturation"):
        apply_look(CameraModelSpec(), {"saturation": 5})
    with pytest.raises(WorldError, match="sharpness: unknown key"):
        apply_look(CameraModelSpec(), {"sharpness": 1})


def test_random_looks_stay_in_their_ranges():
    rng = np.random.default_rng(4)
    tones = set()
    for _ in range(300):
        look = random_look(rng)
        spec = apply_look(CameraModelSpec(), look)
        tones.add(spec.tone)
        assert 0.4 <= spec.saturation <= 1.5 and all(0.7 <= g <= 1.3 for g in spec.white_balance)
        assert -1.5 <= spec.exposure_bias_ev <= 1.5 and -10 <= spec.hue_rotation_deg <= 10
        assert 50 <= spec.jpeg_quality <= 95 and 0 <= spec.lens_blur_px <= 1.5
    assert tones == set(RANDOM_TONES)
    assert random_look(np.random.default_rng(5)) == random_look(np.random.default_rng(5))


def test_corner_looks_lie_at_the_edges_of_the_random_ranges():
    rng = np.random.default_rng(4)
    for _ in range(100):
        spec = apply_look(CameraModelSpec(), corner_look(rng))
        assert spec.saturation in (0.4, 0.45, 1.5) and set(spec.white_balance) <= {0.7, 1.0, 1.3}
        assert abs(spec.exposure_bias_ev) == 1.5 and spec.jpeg_quality in (50, 55)
        assert -10 <= spec.hue_rotation_deg <= 10 and 0 <= spec.lens_blur_px <= 1.5
    assert corner_look(np.random.default_rng(5)) == corner_look(np.random.default_rng(5))


@pytest.mark.parametrize("name", sorted(LOOKS))
def test_every_named_look_captures(name):
    shot = capture(_radiance(), look_spec(CameraModelSpec(), name), np.random.default_rng(6))
    assert shot.image.shape == (48, 64, 3) and shot.image.dtype == np.uint8
