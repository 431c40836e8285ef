"""The camera look estimated from the target's body and undone (vision/camera_look.py), tested by its effect."""

from pathlib import Path

import cv2
import numpy as np
import pytest

from vision.camera_look import DEAD_BAND, Look, chroma_of, estimate_look, neutral_chroma, to_reference_look
from vision.look_tracker import LookTracker

DATA = Path(__file__).parent / "data" / "photoreal"
PIONEER_BODY = (40, 40, 150)


def _frames(name: str) -> list[np.ndarray]:
    return [cv2.imread(str(p)) for p in sorted((DATA / name).glob("H*/00000[0-3].jpg"))]


def _grade(bgr: np.ndarray, saturation: float, turn_deg: float, cast: tuple[float, float]) -> np.ndarray:
    """A look made in the camera's way (not the estimator's): gains (B, R) in linear light, then chroma
    scaled and turned about the luma in YCrCb."""
    from scenarios.camera_model import linear_from_srgb, srgb_from_linear

    lin = linear_from_srgb(bgr) * np.array([cast[0], 1.0, cast[1]], np.float32)
    ycc = cv2.cvtColor(srgb_from_linear(lin), cv2.COLOR_BGR2YCrCb).astype(np.float32)
    c, s = np.cos(np.radians(turn_deg)), np.sin(np.radians(turn_deg))
    cr, cb = ycc[..., 1] - 128, ycc[..., 2] - 128
    ycc[..., 1], ycc[..., 2] = 128 + saturation * (c * cr - s * cb), 128 + saturation * (s * cr + c * cb)
    return cv2.cvtColor(np.clip(ycc + 0.5, 0, 255).astype(np.uint8), cv2.COLOR_YCrCb2BGR)


@pytest.mark.parametrize("name", ["paper", "telephoto", "absent"])
def test_reference_look_frames_are_left_as_they_are(name):
    """The front-end was tuned on the reference look: its frames must come back unchanged (no look is bought
    with another)."""
    for frame in _frames(name):
        look = estimate_look(frame, PIONEER_BODY)
        assert look.is_reference, look
        assert to_reference_look(frame, look) is frame


def test_another_robots_reference_look_frames_read_as_the_pioneers_do():
    """The second robot's pale yellow paint keeps more of its chroma in the reference look than the Pioneer's deep red
    does: measured against a gain constant over paints its frames read a saturation 1.26-1.32 (the Pioneer's 1.07-1.16
    at telephoto), at the dead band's edge, and a washed-out look of it was undone by less than the Pioneer's. Against
    :func:`reference_body_chroma` the two read alike."""
    from scenarios.target import load_model
    from vision.camera_look import REFERENCE_BODY_GAIN, REFERENCE_PAINT_CHROMA, reference_body_chroma

    def median_saturation(name: str, body: tuple[int, int, int]) -> float:
        looks = [estimate_look(frame, body, 500.0) for frame in _frames(name)]
        assert all(look.body_pixels > 0 for look in looks)
        return float(np.median([look.saturation for look in looks]))

    pioneer = median_saturation("telephoto", PIONEER_BODY)
    husky = median_saturation("husky-telephoto", load_model("husky").body_colour)
    assert abs(np.log(husky / pioneer)) < 0.08, (husky, pioneer)
    # the reference paint's own: the constant it was measured as; a paler paint keeps a larger share of its chroma
    assert reference_body_chroma(REFERENCE_PAINT_CHROMA) == REFERENCE_BODY_GAIN * REFERENCE_PAINT_CHROMA
    kept = [reference_body_chroma(c) / c for c in (0.3, 0.6, 0.9, 1.2)]
    assert kept == sorted(kept, reverse=True)


def test_undoing_a_look_maps_each_pixels_chroma_over_luma_as_defined():
    # the map as the docstring defines it, per pixel in float64 (q = (c - 128) / Y mapped by R(-turn) (q - n) / gain
    # + n - shift, times Y), against the one affine transform it is computed by, on 200,000 random colours and
    # the blacks (Y = 0: no chroma); rounding ties may differ by a unit in a channel
    from vision.camera_look import beyond_band

    rng = np.random.default_rng(5)
    bgr = rng.integers(0, 256, (400, 500, 3), dtype=np.uint8)
    bgr[0, :4] = [(0, 0, 0), (4, 0, 0), (0, 0, 1), (3, 0, 1)]   # Y rounds to 0
    for _ in range(4):
        look = Look(neutral=tuple(rng.normal(0, 0.06, 2)), saturation=float(np.exp(rng.normal(0, 0.4))),
                    turn_rad=float(rng.normal(0, 0.15)))
        shift, gain, turn = beyond_band(look)
        ycc = cv2.cvtColor(bgr, cv2.COLOR_BGR2YCrCb).astype(float)
        y = ycc[..., 0:1]
        q = (ycc[..., 1:] - 128.0) / np.maximum(y, 1.0) - look.neutral
        c, s = np.cos(-turn), np.sin(-turn)
        q = q @ (np.array([[c, -s], [s, c]]) / gain).T + look.neutral - shift
        ycc[..., 1:] = q * y + 128.0
        expected = cv2.cvtColor(np.clip(np.floor(ycc + 0.5), 0, 255).astype(np.uint8), cv2.COLOR_YCrCb2BGR)
        got = to_reference_look(bgr, look)
        off = np.abs(got.astype(int) - expected.astype(int)).max(axis=2)
        assert (off > 0).mean() < 1e-3 and off.max() <= 2, ((off > 0).mean(), off.max())
        assert (off[0, :4] == 0).all()   # the blacks too


def test_a_desaturated_turned_cast_look_is_measured_and_undone():
    frame = _frames("telephoto")[0]
    graded = _grade(frame, 0.45, 12.0, (1.25, 0.8))
    look = estimate_look(graded, PIONEER_BODY)
    assert look.body_pixels > 1000
    assert 0.35 < look.saturation < 0.6
    assert 7.0 < np.degrees(look.turn_rad) < 17.0
    assert not look.is_reference
    # undone: the body's chroma and the neutral come back near the reference frame's
    back = to_reference_look(graded, look)
    _, q_ref = chroma_of(frame)
    _, q_back = chroma_of(back)
    _, q_graded = chroma_of(graded)
    region = np.zeros(frame.shape[:2], bool)
    ys, xs = np.nonzero(cv2.inRange(frame, (0, 0, 60), (90, 90, 255)))   # the red body, in the reference frame
    region[ys, xs] = True
    err_back = np.median(np.hypot(*(q_back[region] - q_ref[region]).T))
    err_graded = np.median(np.hypot(*(q_graded[region] - q_ref[region]).T))
    # brought back to within the reference look's own spread over scenes (soft thresholding leaves that much)
    assert err_back < 0.6 * err_graded
    assert estimate_look(back, PIONEER_BODY).is_reference



def test_a_dark_washed_out_body_at_the_papers_scale_is_measured_and_a_scene_without_it_is_not():
    """Through a flat, dark, desaturated look (the committed paper-scale frames developed through ``flat-cool``) the
    Pioneer's ~25 px body keeps 0.15-0.25 of chroma: each frame's look is measured from it (under a bar of 0.16 one
    frame was not, and its marks fell outside the body's paint). The frames without the target find no body."""
    with_body = [estimate_look(f, PIONEER_BODY, 29.0) for f in _frames("paper-flat-cool")]
    assert len(with_body) == 8 and all(look.body_pixels > 300 for look in with_body), with_body
    assert all(look.saturation < 0.55 for look in with_body)   # a look 0.45 saturated is taken back
    assert all(estimate_look(f, PIONEER_BODY, 29.0).body_pixels == 0 for f in _frames("absent"))


def test_neutral_follows_a_white_balance_cast():
    frame = _frames("paper")[0]
    _, q = chroma_of(frame)
    n0, _ = neutral_chroma(q, np.ones(q.shape[:2], bool))
    _, q_warm = chroma_of(_grade(frame, 1.0, 0.0, (0.75, 1.3)))   # red up, blue down
    n1, _ = neutral_chroma(q_warm, np.ones(q.shape[:2], bool))
    assert n1[0] > n0[0] + 0.05 and n1[1] < n0[1] - 0.05   # Cr up, Cb down
    assert not estimate_look(_grade(frame, 1.0, 0.0, (0.75, 1.3)), PIONEER_BODY).is_reference


def test_without_a_body_or_a_colour_image_only_the_neutral_or_nothing():
    frame = _frames("paper")[0]
    look = estimate_look(frame, None)
    assert look.saturation == 1.0 and look.turn_rad == 0.0 and look.body_pixels == 0
    assert estimate_look(np.zeros((4, 4), np.uint8), PIONEER_BODY) == Look()
    grey_body = estimate_look(frame, (128, 128, 128))   # a paint without hue: the neutral only
    assert grey_body.body_pixels == 0


def test_dead_band_and_tracker():
    assert Look().is_reference
    assert not Look(saturation=float(np.exp(DEAD_BAND[1] + 0.05))).is_reference
    tracker = LookTracker(window=3)
    for s in (0.5, 0.55, 2.0, 0.52):   # one odd frame does not move a camera's look
        tracked = tracker.update(Look(saturation=s, body_pixels=100))
    assert tracked.saturation == pytest.approx(0.55)   # the median of the last three
    assert tracker.update(Look()).saturation == pytest.approx(0.55)   # a frame without the body keeps the track
    with pytest.raises(ValueError):
        LookTracker(0)


def test_a_tracked_look_is_estimated_again_every_few_frames_once_its_window_is_full():
    tracker = LookTracker(window=3, every=4)
    due, between = [], []
    for frame in range(12):
        due.append(tracker.due())
        if due[-1]:
            tracker.update(Look(saturation=0.5 + 0.01 * frame, body_pixels=100))
        else:   # the median of the last three estimates
            between.append(round(tracker.current().saturation, 6))
    assert between == [0.51, 0.52, 0.52, 0.52, 0.54, 0.54, 0.54]
    assert due == [True, True, True, False, True, False, False, False, True, False, False, False]
    assert LookTracker(every=4).current() == Look()   # nothing tracked yet: the reference look


@pytest.mark.parametrize("name, body", [("telephoto", PIONEER_BODY), ("telephoto-flat-cool", PIONEER_BODY),
                                        ("husky-telephoto", None)])
def test_a_large_bodys_patch_found_on_a_quarter_of_the_pixels_reads_as_the_whole_image_does(name, body):
    """Where the target is large (vision.camera_look.LOOK_STRIDE_FROM_EXTENT_PX) its paint patch is found on every
    other pixel of every other row and measured on the image's own pixels: the same gain, turn and pixel count as
    the patch found on every pixel."""
    from scenarios.target import load_model
    from vision.camera_look import LOOK_STRIDE, body_chroma
    body = load_model("husky").body_colour if body is None else body
    _, paint_q = chroma_of(np.array(body, np.uint8))
    for frame in _frames(name):
        y, q = chroma_of(frame)
        usable = (y >= 24) & (y <= 245)
        neutral, spread = neutral_chroma(q, usable)
        whole, n_whole = body_chroma(q, usable, neutral, spread, paint_q, 500.0)
        sampled, n_sampled = body_chroma(q, usable, neutral, spread, paint_q, 500.0, stride=LOOK_STRIDE)
        assert whole is not None and sampled is not None
        assert abs(np.hypot(*sampled) / np.hypot(*whole) - 1) < 0.02
        assert abs(np.degrees(np.arctan2(sampled[1], sampled[0]) - np.arctan2(whole[1], whole[0]))) < 1.0
        assert abs(n_sampled / n_whole - 1) < 0.1   # counted in the image's pixels, not the sample's


def _faces(ground: tuple[int, int, int]) -> np.ndarray:
    """A red body's face, a pale pink face beside it (its paint bleached by a tone curve's shoulder and a low
    saturation), a pale pink patch and a green one away from it, on a ground of colour ``ground``: BGR uint8."""
    image = np.full((240, 320, 3), ground, np.uint8)
    image[80:120, 80:140] = PIONEER_BODY
    image[80:120, 140:180] = (180, 184, 214)
    image[120:140, 80:140] = (50, 50, 62)            # a dull patch below it, as hued but darker than the paint
    image[20:40, 250:290] = (120, 200, 120)
    image[190:210, 250:290] = (180, 184, 214)
    noise = np.random.default_rng(0).normal(0, 2, image.shape)
    return np.clip(image + noise, 0, 255).astype(np.uint8)


def test_a_face_bleached_toward_grey_is_hued_like_the_body_and_the_ground_is_not():
    from vision.body_paint import LINEAR_OF_BYTE, body_paint, srgb_to_linear
    from vision.camera_look import hued_like_body

    paint_linear = srgb_to_linear(np.array(PIONEER_BODY, np.float32) / 255)
    image = _faces((128, 130, 131))
    sure, paint = body_paint(LINEAR_OF_BYTE[image], paint_linear)
    assert sure[80:120, 80:140].all() and paint[80:120, 140:180].mean() < 0.01   # the light's model: red alone
    hued = hued_like_body(image, estimate_look(image, PIONEER_BODY), PIONEER_BODY, sure)
    assert hued[80:120, 140:180].mean() > 0.95
    assert not hued[20:40, 250:290].any() and hued[:, :60].mean() < 0.001            # green, grey ground
    assert sure[122:140, 80:140].mean() < 0.05 and hued[122:140, 80:140].mean() < 0.05   # a bleached face is bright
    assert hued[190:210, 250:290].mean() > 0.95   # hued like the body too: only the hysteresis joins it to the body
    _, joined = body_paint(LINEAR_OF_BYTE[image], paint_linear,
                           hued=lambda sure: hued_like_body(image, estimate_look(image, PIONEER_BODY),
                                                            PIONEER_BODY, sure))
    assert joined[80:120, 140:180].mean() > 0.95 and not joined[190:210, 250:290].any() and not joined[:, :60].any()
    # a ground tinted in the body's own hue as much as the bleached face raises the bar past it
    tinted = _faces((160, 165, 195))
    sure, _ = body_paint(LINEAR_OF_BYTE[tinted], paint_linear)
    hued = hued_like_body(tinted, estimate_look(tinted, PIONEER_BODY), PIONEER_BODY, sure)
    assert hued[:, :60].mean() < 0.01 and hued[80:120, 140:180].mean() < 0.01


def test_a_strong_cast_is_a_cast_where_the_body_stands_out_from_it_and_a_close_up_of_paint_is_none():
    from vision.camera_look import MAX_NEUTRAL_SHIFT, MAX_NEUTRAL_SHIFT_WITH_BODY, REFERENCE_NEUTRAL

    # a white balance 45 / 70 % off (blue down, red up) with a saturation of 1.5: the neutral moves past 0.3
    graded = _grade(_frames("telephoto")[0], 1.5, 0.0, (0.55, 1.7))
    _, q = chroma_of(graded)
    neutral, _ = neutral_chroma(q, np.ones(q.shape[:2], bool))
    shift = float(np.hypot(*(neutral - np.asarray(REFERENCE_NEUTRAL))))
    assert MAX_NEUTRAL_SHIFT < shift < MAX_NEUTRAL_SHIFT_WITH_BODY
    look = estimate_look(graded, PIONEER_BODY)
    assert np.allclose(look.neutral, neutral, atol=0.01) and look.body_pixels > 1000   # the cast, with the body
    assert np.allclose(estimate_look(graded, None).neutral, REFERENCE_NEUTRAL)  # no body to confirm it: none
    # a close-up of a pale red paint: the picture's grey is the paint, from which no body stands out
    close = np.clip(np.full((120, 160, 3), (70, 80, 160), np.float64)
                    + np.random.default_rng(0).normal(0, 2, (120, 160, 3)), 0, 255).astype(np.uint8)
    _, q = chroma_of(close)
    neutral, _ = neutral_chroma(q, np.ones(q.shape[:2], bool))
    assert MAX_NEUTRAL_SHIFT < float(np.hypot(*(neutral - np.asarray(REFERENCE_NEUTRAL)))) < MAX_NEUTRAL_SHIFT_WITH_BODY
    assert np.allclose(estimate_look(close, PIONEER_BODY).neutral, REFERENCE_NEUTRAL)
