"""The label of a 2-4 px mark through the encoder's 4:2:0 chroma (vision.spot_colour), judged by its effect: a
real JPEG encoder's output, the truth's colours, and the committed Cycles frames."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from vision.blobs import _srgb_to_linear
from vision.spot_label import label_colours
from vision.spot_colour import chroma_420, label_small_spots

PALETTE = {"yellow": (20, 220, 240), "cyan": (220, 210, 20), "green": (40, 190, 40), "magenta": (200, 40, 210)}
BODY = (40, 40, 150)
#: Four 2.8 px marks on the red body, at sub-pixel centres on both parities of the 2 x 2 chroma grid.
CENTRES = np.array([(20.3, 24.6), (38.7, 23.2), (57.1, 25.5), (75.6, 24.1)])


def _body_with_marks(quality: int = 90, spots: tuple = ()) -> np.ndarray:
    """A grey ground, the red body and the four marks (and ``spots``: ((u, v), BGR) more discs of their size),
    area-sampled from 8x, through OpenCV's JPEG at 4:2:0."""
    s = 8
    big = np.zeros((48 * s, 96 * s, 3), np.float32)
    big[:] = (120, 125, 130)
    cv2.rectangle(big, (8 * s, 8 * s), (88 * s, 40 * s), BODY, -1)
    for (u, v), colour in [*zip(CENTRES, PALETTE.values()), *spots]:
        cv2.circle(big, (int((u + 0.5) * s), int((v + 0.5) * s)), int(1.4 * s), colour, -1)
    image = cv2.resize(big, (96, 48), interpolation=cv2.INTER_AREA).astype(np.uint8)
    ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality, cv2.IMWRITE_JPEG_SAMPLING_FACTOR,
                                            cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420])
    return cv2.imdecode(data, cv2.IMREAD_COLOR)


def _rgb_labels(image: np.ndarray) -> list[str]:
    """The linear-RGB blend fit (vision.spot_label.label_colours) at the same centres: spot pixel and ring median."""
    lin = _srgb_to_linear(image.astype(np.float32) / 255).astype(float)
    yy, xx = np.mgrid[:image.shape[0], :image.shape[1]]
    spots, rings = [], []
    for u, v in CENTRES:
        spots.append(lin[int(round(v)), int(round(u))])
        dist = np.hypot(xx - u, yy - v)
        rings.append(np.median(lin[(dist >= 2.9) & (dist <= 4.4)], axis=0))
    pal = _srgb_to_linear(np.array(list(PALETTE.values()), np.float32) / 255).astype(float)
    labels, _, _ = label_colours(np.array(spots), np.array(rings), pal)
    return [list(PALETTE)[i] for i in labels]


def test_through_4_2_0_chroma_every_small_mark_gets_its_colour_where_an_rgb_fit_does_not():
    image = _body_with_marks()
    labels, confidence = label_small_spots(image, CENTRES, np.full(4, 1.4), np.array(list(PALETTE.values()),
                                                                                      np.uint8), BODY)
    assert [list(PALETTE)[i] for i in labels] == list(PALETTE)
    assert np.all(confidence > 0.2)
    assert _rgb_labels(image) != list(PALETTE)   # the diluted chroma misleads the RGB fit (the reason for the module)


def test_a_spot_of_the_body_in_shade_is_no_colour_and_gets_no_label():
    # a dent or gap in the body's red: the same paint, darker. Every paint colour is lighter than the body, so none
    # explains it (MIN_EXPLAINED); the marks beside it keep their colours
    shade = (np.array([66.2, 32.9]), (20, 20, 75))
    image = _body_with_marks(spots=(shade,))
    points = np.concatenate([CENTRES, shade[0][None]])
    palette = np.array(list(PALETTE.values()), np.uint8)
    labels, _ = label_small_spots(image, points, np.full(5, 1.4), palette, BODY)
    assert [list(PALETTE)[i] for i in labels[:4]] == list(PALETTE) and labels[4] == -1
    without, _ = label_small_spots(image, points, np.full(5, 1.4), palette, BODY, min_explained=0.0)
    assert without[4] >= 0   # the nearest colour by misfit alone: a false mark


def test_the_4_2_0_operator_keeps_a_block_aligned_field_and_averages_a_pixel_over_its_block():
    flat = np.full((6, 6), 3.0)
    assert np.allclose(chroma_420(flat, 0, 0), 3.0) and np.allclose(chroma_420(flat, 1, 1), 3.0)
    dot = np.zeros((8, 8))
    dot[4, 4] = 1.0
    # the dot's block (4..5, 4..5) holds its mean 1/4, spread to the neighbours by the upsampling: mass kept
    out = chroma_420(dot, 0, 0)
    assert abs(out.sum() - 1.0) < 1e-9 and np.allclose(out[4:6, 4:6], out[4, 4]) and out[4, 4] == out.max()
    # the same dot seen from a window starting on odd coordinates lands in the same image block
    shifted = np.zeros((8, 8))
    shifted[3, 3] = 1.0
    assert np.allclose(chroma_420(shifted, 1, 1)[3:5, 3:5], chroma_420(dot, 0, 0)[4:6, 4:6])


def test_on_the_committed_paper_scale_frames_most_matched_marks_have_their_colour():
    # Cycles frames at the paper's scale (tests/data/photoreal/paper): the RGB fit labelled 47 % / 51 % of the
    # matched marks right (H1 / H2), the encoder-aware fit 75 % / 91 % (BENCHMARKS.md, "labels" column)
    from benchmarks.bench_photoreal_features import evaluate

    rows = [r for r in evaluate(Path(__file__).parent / "data" / "photoreal" / "paper") if r["front_end"] == "contrast"]
    assert all(r["labels"] >= 0.7 for r in rows), rows


def test_a_saturated_mark_as_lit_as_its_ring_is_its_paint_however_dark_beside_the_scene():
    # the second robot's red mark on its shaded side under a low sun (telephoto g1-low, H1: linear BGR as measured)
    # is darker than a fifth of the sunlit scene, yet lit like the yellow paint around it
    husky = {"red": (35, 35, 200), "blue": (200, 90, 20), "violet": (190, 40, 130), "black": (30, 30, 30)}
    pal = _srgb_to_linear(np.array(list(husky.values()), np.float32) / 255).astype(float)
    body = _srgb_to_linear(np.array((20, 195, 240), np.float32) / 255).astype(float)
    spot, ring = np.array([[0.009, 0.009, 0.103]]), np.array([[0.008, 0.107, 0.162]])
    scene_bar = 0.12   # MIN_RELATIVE_BRIGHTNESS x the scene: more than the red paint's fit gives
    light = ring @ body / (body @ body)
    labels, misfit, _ = label_colours(spot, ring, pal, scene_bar, bleached=True, ring_light=light)
    assert list(husky)[labels[0]] == "red" and misfit[0] < 0.35
    labels, misfit, _ = label_colours(spot, ring, pal, scene_bar, bleached=True)   # the scene's bar alone
    assert list(husky)[labels[0]] != "red" or misfit[0] >= 0.35
    # a hole in the same paint, far darker than its ring, is still no lit paint
    _, misfit, _ = label_colours(np.array([[0.004, 0.004, 0.012]]), ring, pal[:3], scene_bar, bleached=True,
                                 ring_light=light)
    assert not np.isfinite(misfit[0])


def test_a_spot_lighter_than_its_ring_is_no_paint_far_darker_than_the_body():
    # the second robot's black is 1/43 of its yellow's luminance: a black mark is darker than the paint beside it
    # under any light they share, so a glint on a dark tyre (a grey spot lighter than its ring) is not one
    husky = {"red": (35, 35, 200), "blue": (200, 90, 20), "violet": (190, 40, 130), "black": (30, 30, 30)}
    pal = _srgb_to_linear(np.array(list(husky.values()), np.float32) / 255).astype(float)
    body = _srgb_to_linear(np.array((20, 195, 240), np.float32) / 255).astype(float)
    glint, tyre = np.array([[0.05, 0.05, 0.055]]), np.array([[0.015, 0.015, 0.016]])
    labels, misfit, _ = label_colours(glint, tyre, pal)
    assert list(husky)[labels[0]] == "black" and misfit[0] < 0.35     # any grey fits black at some light
    labels, misfit, _ = label_colours(glint, tyre, pal, body_linear=body)
    assert list(husky)[labels[0]] != "black" or not np.isfinite(misfit[0])
    # a black mark on the yellow paint is darker than its ring: still black
    mark, paint = np.array([[0.006, 0.007, 0.008]]), np.array([[0.008, 0.107, 0.162]])
    labels, misfit, _ = label_colours(mark, paint, pal, body_linear=body)
    assert list(husky)[labels[0]] == "black" and misfit[0] < 0.35
    # the converse on the Pioneer: its yellow (8.6 times its red's luminance) is no spot darker than its ring
    pioneer = _srgb_to_linear(np.array(list(PALETTE.values()), np.float32) / 255).astype(float)
    red = _srgb_to_linear(np.array(BODY, np.float32) / 255).astype(float)
    dim_yellow, lit_ring = np.array([[0.003, 0.09, 0.11]]), np.array([[0.02, 0.12, 0.14]])
    labels, misfit, _ = label_colours(dim_yellow, lit_ring, pioneer)
    assert list(PALETTE)[labels[0]] == "yellow" and np.isfinite(misfit[0])
    labels, misfit, _ = label_colours(dim_yellow, lit_ring, pioneer, body_linear=red)
    assert list(PALETTE)[labels[0]] != "yellow" or not np.isfinite(misfit[0])


def test_the_fit_of_every_spot_colour_and_brightness_at_once_is_the_explicit_least_squares():
    """spot_colour._least_squares, from five sums per window, against the model written out per spot, colour and
    brightness, ``m = [g (k Y_c - Y_r), S[g] (k C_c - C_r)]``, its coverage ``a`` clipped to [0, MAX_COVERAGE] and
    the residual formed: the same least residual, and the colour that fits best is the same."""
    from vision.spot_colour import MAX_COVERAGE, _least_squares

    rng = np.random.default_rng(4)
    k, c, g, n = 7, 4, 16, 49
    profile_y, profile_c = rng.uniform(0, 1, (k, n)), rng.uniform(0, 1, (k, n))
    coef_y, coef_c = rng.normal(0, 60, (k, c, g)), rng.normal(0, 40, (k, c, g, 2))
    dy, dc = rng.normal(0, 30, (k, n)), rng.normal(0, 20, (k, n, 2))
    dy[0], dc[0] = 0.0, 0.0                                           # a spot that does not differ from its ring
    coef_y[1, 2], coef_c[1, 2] = coef_y[1, 2] * 0, coef_c[1, 2] * 0   # a colour no brightness makes differ
    dy[2], dc[2] = 0.8 * profile_y[2] * coef_y[2, 1, 5], 0.8 * profile_c[2, :, None] * coef_c[2, 1, 5]   # a clean spot
    dy[3], dc[3] = 2.0 * profile_y[3] * coef_y[3, 0, 3], 2.0 * profile_c[3, :, None] * coef_c[3, 0, 3]   # beyond full
    got = _least_squares(coef_y, coef_c, profile_y, profile_c, dy, dc)
    obs = np.concatenate([dy, dc[..., 0], dc[..., 1]], axis=1)                                       # (K, 3N)
    model = np.concatenate([profile_y[:, None, None, :] * coef_y[..., None],
                            profile_c[:, None, None, :] * coef_c[..., 0, None],
                            profile_c[:, None, None, :] * coef_c[..., 1, None]], axis=3)              # (K, C, G, 3N)
    norm = np.sum(model * model, axis=3)
    a = np.clip(np.sum(model * obs[:, None, None, :], axis=3) / np.maximum(norm, 1e-12), 0.0, MAX_COVERAGE)
    expected = np.min(np.sum((obs[:, None, None, :] - a[..., None] * model) ** 2, axis=3), axis=2)
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-6)
    assert np.array_equal(np.argmin(got[1:], axis=1), np.argmin(expected[1:], axis=1))
    assert got[2, 1] < 1e-6 * np.sum(obs[2] ** 2)   # the clean spot is its colour at 0.8 coverage
    assert got[3, 0] > 0.01 * np.sum(obs[3] ** 2)   # twice the colour is no coverage above MAX_COVERAGE
