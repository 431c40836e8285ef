"""The contrast front-end (vision.blobs): marks found by contrast at the scale the geometry allows, labelled by
fitting each paint colour on the line ring -> spot; judged against the renderer's truth and on made-up images."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from vision.blobs import MarkPrior, detect_contrast_marks, mark_prior
from vision.spot_label import label_colours
from vision.features import match_to_truth
from scenarios.render import render_frame
from scenarios.world import load_scenario

PALETTE = {"yellow": (20, 220, 240), "cyan": (220, 210, 20), "green": (40, 190, 40), "magenta": (200, 40, 210)}


def _jpeg_420(image: np.ndarray, quality: int = 85) -> np.ndarray:
    ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality, cv2.IMWRITE_JPEG_SAMPLING_FACTOR,
                                            cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420])
    return cv2.imdecode(data, cv2.IMREAD_COLOR)


@pytest.mark.parametrize("world, match_px", [("exp2-paper-scale", 1.5), ("exp2", 3.0)])
def test_the_marks_of_rendered_frames_are_found_and_labelled(world, match_px):
    scenario = load_scenario(world)
    area = scenario.bounds()
    found = marks = correct = detections = labelled = 0
    for vehicle in ("H1", "H2"):
        for k in (0, 20):
            frame = render_frame(scenario, k, vehicle, clean=True)
            prior = mark_prior(frame.camera, scenario.model.mark_radius, scenario.model.size, area.lo[:3],
                               area.hi[:3])
            det = detect_contrast_marks(frame.image, scenario.model.palette, prior)
            truth = frame.truth
            pairs, _ = match_to_truth(det.points, truth.mark_uv[truth.fully_visible], match_px)
            any_pairs, _ = match_to_truth(det.points, truth.mark_uv, match_px)
            found, marks = found + len(pairs), marks + int(truth.fully_visible.sum())
            correct, detections = correct + len(any_pairs), detections + len(det)
            labelled += sum(det.names[det.labels[i]] == truth.mark_colour[j] for i, j in any_pairs)
    assert found / marks >= 0.9 and correct / detections >= 0.7 and labelled == correct


def test_paper_scale_marks_survive_jpeg_chroma_subsampling_better_than_hue_bands():
    from vision.features import colour_ranges, detect_colour_marks

    scenario = load_scenario("exp2-paper-scale")
    area = scenario.bounds()
    recall = {"contrast": 0, "hues": 0}
    total = 0
    for k in (0, 10, 20, 30):
        frame = render_frame(scenario, k, "H1")
        image = _jpeg_420(frame.image)
        prior = mark_prior(frame.camera, scenario.model.mark_radius, scenario.model.size, area.lo[:3], area.hi[:3])
        whole = frame.truth.mark_uv[frame.truth.fully_visible]
        total += len(whole)
        recall["contrast"] += len(match_to_truth(detect_contrast_marks(image, scenario.model.palette, prior).points,
                                                 whole, 1.5)[0])
        recall["hues"] += len(match_to_truth(detect_colour_marks(image, colour_ranges(scenario.model.palette)).points,
                                             whole, 1.5)[0])
    assert recall["contrast"] > 1.3 * recall["hues"] and recall["contrast"] / total >= 0.6


def _canvas(colour=(40, 40, 150)) -> np.ndarray:
    rng = np.random.default_rng(0)
    image = np.full((120, 160, 3), colour, np.float32) + rng.normal(0, 2, (120, 160, 3))
    return np.clip(image, 0, 255).astype(np.uint8)


def test_a_small_mark_is_found_to_a_tenth_of_a_pixel_with_its_colour():
    canvas = _canvas()
    big = cv2.resize(canvas, None, fx=8, fy=8, interpolation=cv2.INTER_NEAREST)
    cv2.circle(big, (int(80.3 * 8 + 4), int(60.6 * 8 + 4)), 12, PALETTE["cyan"], -1, cv2.LINE_AA)
    image = cv2.resize(big, (160, 120), interpolation=cv2.INTER_AREA)   # a 3 px disc, area-sampled
    det = detect_contrast_marks(image, PALETTE, MarkPrior((1.0, 2.5)))
    assert len(det) == 1 and det.colours() == ["cyan"]
    assert np.linalg.norm(det.points[0] - (80.3, 60.6)) < 0.15


def test_a_dark_spot_on_the_red_body_is_no_mark():
    image = _canvas()
    cv2.circle(image, (80, 60), 3, (20, 20, 25), -1, cv2.LINE_AA)     # a hole, a wheel hub: less red, not cyan
    assert len(detect_contrast_marks(image, PALETTE, MarkPrior((1.5, 5.0)))) == 0


@pytest.mark.xfail(strict=True, reason="known weakness: the 3 x 3 Hessian of a fine DoG level does not tell a long "
                   "straight edge in a mark colour from an oblique disc (MAX_EDGE_RATIO 100 lets 4:1 discs through); "
                   "peaks along such an edge are labelled marks")
def test_an_edge_of_a_painted_surface_is_no_mark():
    image = _canvas((110, 110, 110))
    image[:, 80:] = PALETTE["yellow"]                                 # a yellow crate's side
    assert len(detect_contrast_marks(image, PALETTE, MarkPrior((1.0, 4.0)))) == 0


def test_labels_fit_a_blend_with_the_ring_at_any_brightness():
    ring = np.array([[0.02, 0.02, 0.30]])                              # linear BGR: the red body
    cyan = np.array([0.72, 0.64, 0.007])
    palette = np.array([[0.007, 0.72, 0.87], cyan, [0.02, 0.51, 0.02], [0.58, 0.02, 0.65]])
    for light in (0.3, 1.0):
        for coverage in (0.3, 1.0):
            spot = ring + coverage * (light * cyan - ring)
            label, misfit, confidence = label_colours(spot, ring, palette)
            assert label[0] == 1 and misfit[0] < 0.05 and confidence[0] > 0.5


def test_with_the_body_context_a_mark_coloured_ball_on_the_ground_is_dropped_and_the_marks_on_the_body_kept():
    image = _canvas((110, 115, 120))                                  # grey ground
    cv2.rectangle(image, (40, 30), (100, 80), (40, 40, 150), -1)      # the red body
    image[30:55, 40:101] = np.clip(image[30:55, 40:101] * 0.6 + 45, 0, 255)   # a glossy top face: paint + sky
    for centre, colour in (((55, 40), "cyan"), ((85, 68), "yellow")):        # two marks on the body
        cv2.circle(image, centre, 3, PALETTE[colour], -1, cv2.LINE_AA)
    cv2.circle(image, (130, 60), 4, PALETTE["yellow"], -1, cv2.LINE_AA)      # a yellow ball on the ground
    prior = MarkPrior((2.0, 5.0))
    without = detect_contrast_marks(image, PALETTE, prior)
    with_body = detect_contrast_marks(image, PALETTE, prior, body=(40, 40, 150))
    ball = lambda det: [p for p in det.points if np.hypot(*(p - (130, 60))) < 3]   # noqa: E731
    assert ball(without)                       # without context the ball is a yellow mark
    assert not ball(with_body)
    kept = match_to_truth(with_body.points, np.array([[55.0, 40.0], [85.0, 68.0]]), 1.5)[0]
    assert len(kept) == 2 and sorted(with_body.colours()) == ["cyan", "yellow"]


def test_paint_pixels_take_the_body_in_sun_in_shadow_and_under_gloss_but_not_grey_ground_or_marks():
    from vision.blobs import _srgb_to_linear
    from vision.body_paint import paint_pixels

    red = _srgb_to_linear(np.array([40, 40, 150], np.float32) / 255)
    pixels = np.array([[red, 0.2 * red, 0.4 * red + 0.06,                # sunlit, sky-lit shadow, gloss
                        [0.25, 0.3, 0.35], [0.007, 0.72, 0.87], [0.72, 0.64, 0.007]]], np.float32)  # ground, marks
    assert paint_pixels(pixels, red).tolist() == [[True, True, True, False, False, False]]


def test_a_glossy_face_is_paint_where_it_touches_the_surely_painted_body_and_grey_ground_never_is():
    # a low sun's sky gloss on a red top face seen at a grazing angle leaves the paint ~0.2 of its light (Cycles
    # telephoto g1-low: the face's five marks were outside the body and lost); ground up to ~0.16
    from vision.blobs import _srgb_to_linear
    from vision.body_paint import connected_paint, paint_pixels

    red = _srgb_to_linear(np.array([40, 40, 150], np.float32) / 255)
    glossy = 0.39 * red + 0.165                                   # share 0.21 (measured on the Cycles face)
    # grey ground, most of the picture as in a camera's (the hysteresis reads the ground's own share away from the
    # body: a yellow body on beige ground raises it, vision.body_paint.connected_share)
    image = np.zeros((60, 80, 3), np.float32) + np.float32(0.2)
    image[2:18, 2:10] = red                                       # the sunlit side
    image[2:18, 10:18] = glossy                                   # the glossy top, touching it
    image[2:18, 22:28] = glossy                                   # the same colour apart: a grey-pink patch
    assert not paint_pixels(image, red)[5, 12]
    paint = connected_paint(image, red)
    assert paint[2:18, 2:18].all() and not paint[2:18, 22:28].any() and not paint[0].any() and not paint[:, 19].any()
    assert not paint[20:].any() and not paint[:, 30:].any()


def test_an_over_exposed_face_is_paint_and_a_white_glare_or_warm_ground_clipped_in_red_is_not():
    # the second robot's yellow top face through vivid-warm: clipped in red and green (BGR ~ (3, 253, 254)), lemon,
    # which the yellow paint's dichromatic fit refuses; a clipped channel is a lower bound of its light
    from vision.body_paint import LINEAR_OF_BYTE, body_paint, clipped_channels, paint_share, srgb_to_linear

    yellow = srgb_to_linear(np.array([20, 195, 240], np.float32) / 255)
    image = np.full((60, 80, 3), 120, np.uint8)                   # grey ground
    image[10:30, 10:40] = (3, 253, 254)                           # the blown top face
    image[30:45, 10:40] = (8, 150, 190)                           # the side face below it
    image[10:30, 50:70] = (3, 253, 254)                           # a blown yellow patch apart from the body
    image[30:45, 40:50] = (250, 255, 255)                         # white glare beside the side face
    image[45:55, 10:40] = (215, 232, 255)                         # warm sunlit ground clipped in red, below it
    lin = LINEAR_OF_BYTE[image]
    sure, paint = body_paint(lin, yellow)
    assert sure[35, 20] and not paint[20, 20]                     # the top face as if unclipped: no paint
    sure, paint = body_paint(lin, yellow, clipped_channels(image))
    assert sure[20, 20] and sure[20, 60] and paint[10:45, 10:40].all()   # the face is the paint's, sure
    assert not paint[35, 45] and not paint[50, 20] and not paint[5, 5]
    # the Pioneer's red (equal green and blue) lit past the exposure in red alone is still its paint
    red = srgb_to_linear(np.array([40, 40, 150], np.float32) / 255)
    sunlit = np.array([[[60, 62, 255], [120, 125, 255], [200, 210, 255]]], np.uint8)
    share = paint_share(LINEAR_OF_BYTE[sunlit], red, clipped_channels(sunlit))[0]
    assert share[0] > 0.9 and share[1] > 0.5 and 0 <= share[2] < 0.18   # the last: a pink glare


def test_a_mark_on_a_face_is_ringed_by_paint_and_a_spot_on_or_beside_the_outline_is_not():
    from vision.body_paint import paint_around

    paint = np.zeros((30, 40), bool)
    paint[5:25, 5:30] = True                   # a face, with a 2 px mark's hole in it
    paint[13:17, 13:17] = False
    points = np.array([[14.5, 14.5],           # the mark inside the face
                       [15.0, 5.0],            # a spot centred on the face's top outline
                       [32.5, 15.0],           # a spot on the ground 3 px beside the face
                       [38.5, 15.0]])          # near the image's edge: outside the image is no paint
    share = paint_around(paint, points, np.array([2.0, 1.0, 1.0, 1.0]))
    assert share[0] == 1.0 and 0.3 < share[1] < 0.7 and share[2] < 0.1 and share[3] == 0.0
    # a blurred mark's blend with the paint (2 px wide here) is no paint: the ring 1 px out misses the paint, 3 px
    # out finds it
    paint[11:19, 11:19] = False
    blurred = [paint_around(paint, points[:1], np.array([2.0]), gap)[0] for gap in (1.0, 3.0)]
    assert blurred[0] == 0.0 and blurred[1] == 1.0, blurred


@pytest.mark.parametrize("name, rms_px", [("paper", 0.5), ("telephoto", 1.0)])
def test_on_the_committed_photoreal_frames_a_found_mark_is_placed_to_a_fraction_of_a_pixel(name, rms_px):
    # the issue's "positions sub-pixel from luminance", on Cycles frames against the marks' true projections:
    # measured 0.26 / 0.35 px per axis at the paper's scale (H1 / H2) and 0.54 / 0.69 px at telephoto
    from benchmarks.bench_photoreal_features import evaluate

    rows = [r for r in evaluate(Path(__file__).parent / "data" / "photoreal" / name) if r["front_end"] == "contrast"]
    assert rows and all(r["position_rms_px"] <= rms_px for r in rows), [r["position_rms_px"] for r in rows]


@pytest.mark.parametrize("name, recall, precision", [("paper", 0.75, 0.8), ("telephoto", 0.95, 0.8)])
def test_on_the_committed_photoreal_frames_the_contrast_front_end_with_the_body_finds_the_marks(name, recall,
                                                                                             precision):
    # Blender Cycles frames (tests/data/photoreal, docs/datasets.md): at telephoto the recall bar (0.95;
    # measured 1.00, precision 0.83; 0.95 / 0.77 without re-centring an oblique disc's window); at the paper's
    # scale the precision bar (0.8; measured 0.89 with the shipped mark scorer, 0.56 with the hand-set bars
    # alone) and the recall measured (0.77; 0.79 with the bars; the 0.8 is not met there), so a regression
    # fails the benchmark's own evaluation (match radius, recall over whole marks, precision over every detection)
    from benchmarks.bench_photoreal_features import evaluate, pooled

    every = evaluate(Path(__file__).parent / "data" / "photoreal" / name)
    found = {front_end: pooled(every, front_end) for front_end in ("contrast", "bars", "marks")}
    assert found["contrast"]["recall"] >= recall and found["contrast"]["precision"] >= precision, found
    if name == "paper":  # where the hue bands are blind (0.13 recall here) and the scorer drops the body's detail
        assert found["contrast"]["recall"] > 3 * found["marks"]["recall"], found
        assert found["contrast"]["precision"] > found["bars"]["precision"] + 0.2, found
        assert found["contrast"]["recall"] > found["bars"]["recall"] - 0.05, found


def _contrast_counts(name: str, look) -> dict:
    """Recall, precision and labels of the contrast front-end (``look``: "auto" or None) on a committed dataset, by
    the benchmark's own evaluation."""
    from benchmarks.bench_photoreal_features import evaluate, pooled

    return pooled(evaluate(Path(__file__).parent / "data" / "photoreal" / name, look=look), "contrast")


@pytest.mark.parametrize("name, recall, precision", [
    ("paper-agx", 0.8, 0.75), ("telephoto-agx", 0.98, 0.95),          # measured 0.86 / 0.80, 1.00 / 1.00
    ("paper-flat-cool", 0.6, 0.75), ("telephoto-flat-cool", 0.85, 0.75),   # 0.66 / 0.82, 1.00 / 0.97
])
def test_through_looks_it_was_never_tuned_on_the_marks_are_found(name, recall, precision):
    # the Pioneer's g2 worlds (a geometry the committed reference-look frames do not have) developed through Blender's
    # AgX view (never looked at while developing) and a cold, flat, dark, JPEG-50 camera (scenarios/looks.py; seen on
    # telephoto-g1-high, not this g2 world, when the telephoto spot rules were chosen). The
    # flat camera halves the chroma and casts it blue: taken as the reference look shows it, the front-end is
    # blind there at the paper's scale (recall 0.03 measured) and half blind at telephoto (0.57: its bleached colours,
    # vision.blobs.bleached_misfit, read some desaturated marks; 0.25 without them), with the look estimated from the
    # body it sees
    found = _contrast_counts(name, "auto")
    assert found["recall"] >= recall and found["precision"] >= precision, found
    if "flat-cool" in name:
        blind = _contrast_counts(name, None)
        assert found["recall"] > min(2 * blind["recall"], blind["recall"] + 0.3), (found, blind)


def test_where_the_context_model_weighs_the_spots_a_mark_misfitting_its_label_reaches_it(monkeypatch):
    # through the cold, flat JPEG-50 camera a telephoto mark's colour misfits its paint 0.35-0.5: the hand-set bar of
    # 0.35 dropped it before the context model (which weighs the misfit among its measures) saw it. Measured: the
    # Pioneer's flat-cool frames recall 0.966 -> 1.000 (precision 0.989 -> 0.970), the second robot's 0.938 -> 0.958.
    # Both held out: the bar was chosen on the Pioneer's telephoto training worlds t1, t2, these are its g2 world and
    # the second robot. Since marks are placed at their whole blob's centre (vision.spot_position.blob_centroids) the
    # second robot's mark is found at either bar. With the context rings following an oblique mark's blob (the
    # model refitted, its threshold lower) the Pioneer's frames measure precision 0.922 (0.950 before: four
    # low-contrast spots inside a face at JPEG 50 just over the threshold); the look's nine benchmark worlds
    # 0.873 -> 0.897 (BENCHMARKS.md, "context rings along an oblique mark"). On the second robot's frames the
    # weighed bar now finds one mark of 48 fewer than the hand-set one (0.938 against 0.958: a marginal mark's
    # measures relative to the other spots move with the spots the looser bar lets in); on its five benchmark worlds
    # it finds 0.9-6.3 points more than the hand-set bar in every named look
    import vision.blobs as blobs

    names = ("telephoto-flat-cool", "husky-telephoto")
    weighed = {name: _contrast_counts(name, "auto") for name in names}
    monkeypatch.setattr(blobs, "MAX_LABEL_MISFIT_WEIGHED", blobs.MAX_LABEL_MISFIT)
    barred = {name: _contrast_counts(name, "auto") for name in names}
    assert weighed["telephoto-flat-cool"]["recall"] > barred["telephoto-flat-cool"]["recall"], (weighed, barred)
    assert weighed["telephoto-flat-cool"]["recall"] >= 0.98 and weighed["telephoto-flat-cool"]["precision"] >= 0.9
    husky = weighed["husky-telephoto"]["recall"], barred["husky-telephoto"]["recall"]
    assert husky[0] >= 0.93 and husky[1] - husky[0] <= 1 / 48 + 1e-9, (weighed, barred)
    assert weighed["husky-telephoto"]["precision"] >= 0.95, weighed   # measured 1.000
    assert all(weighed[name]["labels"] == 1.0 for name in names), weighed


def test_on_a_second_robot_it_was_never_tuned_on():
    # the Husky-like UGV (scenarios/models/husky.yaml): yellow body, red, blue, violet and black marks. Found: 0.90 of
    # its marks at telephoto (black ones too: a dark paint escapes the lit-paint rule; 0.69 without), labels all
    # right, precision 0.90 (0.16 before a mark had to be ringed by one paint, vision.mark_selection.surrounded, a
    # rule chosen on the Pioneer: peaks where the body meets its plate, tyres and shadows). At the paper's scale
    # recall 0.60, precision 0.32 (the palette-relative scorer, never fitted on it): the front-end's open gap, said
    # so in BENCHMARKS.md
    tele = _contrast_counts("husky-telephoto", "auto")
    assert tele["recall"] >= 0.85 and tele["precision"] >= 0.8 and tele["labels"] >= 0.95, tele
    paper = _contrast_counts("husky-paper", "auto")
    assert paper["recall"] >= 0.5, paper


def test_one_per_disc_keeps_the_likeliest_of_a_mark_seen_twice_and_both_of_two_marks_apart():
    from vision.blobs import one_per_disc

    # a mark peaking twice 1.2 px apart (its yellow at one pixel, its luminance at the next), a second mark 3.1 px
    # away (the closest two visible marks lie at the paper's scale), and a third candidate within its disc
    pts = np.array([[10.0, 10.0], [11.2, 10.0], [10.0, 13.1], [10.5, 13.6]])
    score = np.array([0.4, 0.7, 0.5, 0.3])
    assert one_per_disc(pts, score, 1.7).tolist() == [1, 2]
    assert one_per_disc(pts, score, 0.5).tolist() == [0, 1, 2, 3]   # discs of 0.5 px: all four are apart
    assert one_per_disc(np.zeros((0, 2)), np.zeros(0), 1.7).tolist() == []


def test_on_the_committed_paper_sequence_no_mark_is_found_twice():
    # a 2-4 px mark peaks in several channels a pixel apart; the scorer alone keeps both copies (50 on these 32
    # frames), which count twice in eq. 1's sum. Visible marks' projections lie >= 3.0 px apart at this scale
    from vision.mark_scorer import shipped
    from scenarios.dataset import open_dataset

    data = open_dataset(Path(__file__).parent / "data" / "photoreal" / "paper-sequence")
    world, area = data.world(), data.world().bounds()
    copies_kept_by_the_scorer_alone = 0
    for cam in data.cameras:
        for k in range(data.frames):
            image = cv2.imread(str(data.image_path(cam, k)), cv2.IMREAD_COLOR)
            prior = mark_prior(data.camera(cam, k), world.model.mark_radius, world.model.size, area.lo[:3],
                               area.hi[:3])
            found = detect_contrast_marks(image, world.model.palette, prior, body=world.model.body_colour)
            apart = np.linalg.norm(found.points[:, None] - found.points[None], axis=2) + np.eye(len(found)) * 1e9
            assert apart.min(initial=np.inf) >= prior.radius_px[1], (cam, k)
            every = detect_contrast_marks(image, world.model.palette, prior, body=world.model.body_colour,
                                          scorer="all")
            kept = every.points[shipped().marks(every.features)]
            apart = np.linalg.norm(kept[:, None] - kept[None], axis=2) + np.eye(len(kept)) * 1e9
            copies_kept_by_the_scorer_alone += int((apart.min(axis=1, initial=np.inf) < prior.radius_px[1]).sum())
    assert copies_kept_by_the_scorer_alone > 10


def test_on_the_committed_frames_without_the_target_no_body_paint_means_no_marks():
    from scenarios.dataset import open_dataset

    data = open_dataset(Path(__file__).parent / "data" / "photoreal" / "absent")
    world, area = data.world(), data.world().bounds()
    for cam in data.cameras:
        for k in range(data.frames):
            image = cv2.imread(str(data.image_path(cam, k)), cv2.IMREAD_COLOR)
            prior = mark_prior(data.camera(cam, k), world.model.mark_radius, world.model.size, area.lo[:3],
                               area.hi[:3])
            assert len(detect_contrast_marks(image, world.model.palette, prior)) > 0   # clutter in the marks' hues
            assert len(detect_contrast_marks(image, world.model.palette, prior, body=world.model.body_colour)) == 0


def test_a_mark_is_surrounded_by_one_paint_and_a_peak_on_an_edge_is_not():
    from vision.mark_selection import surrounded

    image = np.zeros((60, 120, 3), np.uint8)
    image[:] = (20, 195, 240)                                           # a yellow face
    image[:, 80:] = (35, 35, 35)                                        # a black plate beside it
    image = cv2.GaussianBlur(image, (0, 0), 1.0)                        # the lens: the edge is a blend
    cv2.circle(image, (30, 30), 6, (30, 30, 30), -1, cv2.LINE_AA)       # a black mark on the face
    lab = cv2.cvtColor(image.astype(np.float32) / 255.0, cv2.COLOR_BGR2Lab)
    # a contrast peak on the edge sees half its surroundings as one paint, half as the other, and its centre (the
    # blend) between them: no direction is its usual surroundings
    share = surrounded(lab, np.array([[30.0, 30.0], [79.5, 30.0]]), np.array([6.0, 4.0]))
    assert share[0] == 1.0 and share[1] < 0.5, share   # MIN_SURROUND is 0.5


def _through_random_looks(name: str, seeds: tuple[int, ...], scorer: str = "shipped") -> tuple[int, int, int]:
    """Marks found, visible and detections on a committed dataset's frames developed again (their sRGB as light)
    through :func:`scenarios.looks.random_look` of each seed, by the front-end with ``scorer``."""
    from scenarios.camera_model import capture
    from scenarios.dataset import open_dataset
    from scenarios.looks import apply_look, random_look
    from scenarios.photoreal.develop import camera_model_of, radiance_of_srgb
    from vision.blobs import mark_prior

    data = open_dataset(Path(__file__).parent / "data" / "photoreal" / name)
    world, area = data.world(), data.world().bounds()
    found = visible = detections = 0
    for seed in seeds:
        spec = apply_look(camera_model_of(world), random_look(np.random.default_rng(seed)))
        for cam in data.cameras:
            light = radiance_of_srgb(cv2.imread(str(data.image_path(cam, 0)), cv2.IMREAD_COLOR))
            captured = capture(light, spec, np.random.default_rng(1))
            image = cv2.imdecode(np.frombuffer(captured.encoded, np.uint8), cv2.IMREAD_COLOR)
            prior = mark_prior(data.camera(cam, 0), world.model.mark_radius, world.model.size, area.lo[:3],
                               area.hi[:3])
            det = detect_contrast_marks(image, world.model.palette, prior, body=world.model.body_colour,
                                        scorer=scorer)
            whole = np.array([m.uv for m in data.truth(0).cameras[cam].marks if m.fully_visible])
            found += len(match_to_truth(det.points, whole, 3.0)[0])
            visible, detections = visible + len(whole), detections + len(det.points)
    return found, visible, detections


def test_a_blurred_mark_ringed_by_its_blend_with_the_paint_is_found_and_a_sunlit_one_labelled(monkeypatch):
    # two random looks that blur (1.2 and 1.4 px) and over-expose (+1.1, +1.2 EV): a cyan mark on the red paint
    # blends to grey, which is no paint, so its 1 px ring shows none; a mark on the sunlit face is bleached toward
    # white past the blend's misfit. Measured: 44 of 46 marks; 42 with the 1 px ring alone and no
    # bleached colours
    import vision.blobs as blobs
    import vision.spot_label as spot_label

    found, visible, detections = _through_random_looks("telephoto", (7, 9), "bars")
    assert found >= 44 and found / detections >= 0.9, (found, visible, detections)
    monkeypatch.setattr(blobs, "RING_GAPS_PX", (1.0,))
    monkeypatch.setattr(spot_label, "bleached_misfit",
                        lambda spot, ring, palette, *_: np.full((len(spot), len(palette)), np.inf))
    # the paint hued like the body (vision.camera_look.hued_like_body) rings these two marks as well: without it
    monkeypatch.setattr(blobs, "HUED_PAINT", False)
    assert _through_random_looks("telephoto", (7, 9), "bars")[0] <= found - 2


def test_a_bright_mark_bleached_toward_white_fits_its_paint_and_a_glint_on_the_body_fits_none():
    from vision.spot_label import bleached_misfit

    yellow_body = np.array([0.01, 0.5, 0.8])                            # linear BGR
    palette = np.array([[0.007, 0.72, 0.87], [0.72, 0.64, 0.007], [0.02, 0.51, 0.02], [0.58, 0.02, 0.65]])
    bleached_green = 0.6 * palette[2] + 0.3                             # a tone curve's highlight: paint + white
    glint = yellow_body + 0.4                                           # the body's own paint + white
    shadow = 0.3 * yellow_body
    misfit = bleached_misfit(np.stack([bleached_green, glint, shadow]), np.stack([yellow_body * 0.5] * 3), palette)
    assert np.argmin(misfit[0]) == 2 and misfit[0, 2] < 0.01
    assert misfit[1, [1, 2, 3]].min() > 0.35    # only the body's own hue (yellow, a palette colour here) could fit
    assert np.isinf(misfit[2]).all()            # darker than its ring: not bleached


def test_a_mark_on_a_face_in_the_bodys_shade_is_lit_paint_when_its_ring_is_the_bodys_paint(monkeypatch):
    # two random looks whose tone curve takes the shaded side face under the scene's brightness bar: its green mark
    # was "no lit paint" while its ring, the body's paint, was itself under the bar (measured: 46 of 46, 44 without)
    import vision.blobs as blobs

    found, visible, _ = _through_random_looks("telephoto", (0, 2))
    assert found == visible == 46
    monkeypatch.setattr(blobs, "PAINT_RING_LIT", 2.0)   # no ring is more than all paint
    assert _through_random_looks("telephoto", (0, 2))[0] == found - 2


def test_a_mark_bleached_nearly_white_is_lit_by_its_whole_light_and_a_dim_one_is_not():
    from vision.spot_label import bleached_misfit

    palette = np.array([[0.007, 0.72, 0.87], [0.72, 0.64, 0.007], [0.02, 0.51, 0.02], [0.58, 0.02, 0.65]])
    ring = np.array([[0.45, 0.47, 0.6]])                                # a pale sunlit top face, linear BGR
    pale_green = 0.25 * palette[2] + 0.55                               # over-exposed, desaturated: mostly white
    dim_green = 0.25 * palette[2] + 0.05                                # the same paint, as little white: dim
    bar = 0.6   # the scene's brightness bar (channel sum): the paint's share alone, 0.25 x 0.55, lies under it
    misfit = bleached_misfit(np.stack([pale_green, dim_green]), np.repeat(ring, 2, axis=0) * [[1], [0.1]], palette,
                             min_brightness=bar)
    assert np.argmin(misfit[0]) == 2 and misfit[0, 2] < 0.01          # lit: its paint and white together
    assert np.isinf(misfit[1]).all()                                    # 0.25 x 0.55 + 3 x 0.05 < 0.6: unlit


def test_an_oblique_mark_peaking_at_both_ends_is_one_detection_at_its_centre_and_two_marks_stay_two():
    # a disc seen at a grazing angle (an 11 x 3 px ellipse) peaks towards both ends at the finest scale, with no
    # larger scale peaking at its centre; two round marks of one colour 14 px apart have paint between them
    s, body = 8, (40, 40, 150)
    big = cv2.resize(np.full((160, 240, 3), (120, 125, 130), np.float32), None, fx=s, fy=s,
                     interpolation=cv2.INTER_NEAREST)
    cv2.rectangle(big, (30 * s, 30 * s), (210 * s, 130 * s), body, -1)
    marks = [((80.3, 80.6), (11, 3), "cyan"), ((150.4, 110.2), (5, 5), "yellow"),
             ((100.3, 110.2), (5, 5), "cyan"), ((114.3, 110.2), (5, 5), "cyan")]
    for (u, v), axes, colour in marks:
        cv2.ellipse(big, (int(u * s), int(v * s)), (axes[0] * s, axes[1] * s), 0, 0, 360, PALETTE[colour], -1,
                    cv2.LINE_AA)
    image = cv2.resize(big, (240, 160), interpolation=cv2.INTER_AREA)
    image = np.clip(image + np.random.default_rng(0).normal(0, 2, image.shape), 0, 255).astype(np.uint8)
    det = detect_contrast_marks(image, PALETTE, MarkPrior((2.5, 12.0), 200.0), body=body)
    # each mark's centre in the image's pixel coordinates (area sampling of the 8x drawing)
    centres = np.array([((int(u * s) + 0.5) / s - 0.5, (int(v * s) + 0.5) / s - 0.5) for (u, v), _, _ in marks])
    found, _ = match_to_truth(det.points, centres, 0.6)
    assert len(det) == 4 and len(found) == 4, det.points
    assert sorted(det.colours()) == ["cyan", "cyan", "cyan", "yellow"]


def test_a_target_400_px_across_is_looked_for_on_the_image_halved_and_its_marks_placed_at_full_resolution(
        monkeypatch):
    # vision.scale_space.HALVE_FROM_EXTENT_PX: the second robot's telephoto image is 456-500 px across, the Pioneer's
    # 200-217 px. On the second robot's committed frames the scale space is built on the image halved; measured:
    # recall 0.938 / precision 1.000 against 0.958 / 0.979 at full resolution (this test's evaluation), positions within
    # 1 px rms of the truth per camera as at full resolution (they are taken there, not from the halved peaks)
    import vision.blobs as blobs
    from benchmarks.bench_photoreal_features import evaluate, pooled
    from scenarios.dataset import open_dataset
    from vision import scale_space

    root = Path(__file__).parent / "data" / "photoreal"
    for name, large in (("husky-telephoto", True), ("telephoto", False)):
        ds = open_dataset(root / name)
        world, area = ds.world(), ds.world().bounds()
        priors = [mark_prior(ds.camera(c, 0), world.model.mark_radius, world.model.size, area.lo[:3], area.hi[:3])
                  for c in ds.cameras]
        assert all(scale_space.halved(p) == large for p in priors), (name, priors)
    built_on = []
    real = blobs.contrast_responses
    monkeypatch.setattr(blobs, "contrast_responses", lambda lab, sigmas: built_on.append(lab.shape) or real(lab, sigmas))
    rows = [r for r in evaluate(root / "husky-telephoto") if r["front_end"] == "contrast"]
    half = pooled(rows, "contrast")
    assert built_on and all(h < 300 and w < 330 for h, w, _ in built_on), built_on   # the 640 x 480 frames, halved
    assert all(r["position_rms_px"] <= 1.0 for r in rows), [r["position_rms_px"] for r in rows]
    monkeypatch.setattr(scale_space, "HALVE_FROM_EXTENT_PX", np.inf)
    full = pooled(evaluate(root / "husky-telephoto"), "contrast")
    assert half["recall"] >= full["recall"] - 0.05 and half["precision"] >= full["precision"] - 0.02, (half, full)
    # (absolute bars: recall 0.938, precision 1.000 measured since the context model's rings follow an oblique mark's
    # blob (vision.spot_outline); 0.979 / 0.845 before: this fixture's 48 marks lose two that stand on a face's
    # outline, its false points go; the robot's five benchmark worlds gain recall in every look, BENCHMARKS.md)
    assert half["recall"] >= 0.93 and half["precision"] >= 0.95, half


def _recentred_one_at_a_time(lin, peak, r, spot, ring, steps):
    """The re-centring of one spot, spelled out: the coverage centroid of the pixels within r + 1.5 px of the centre
    (inside the image), the centre held within r of the peak, until it moves under 0.05 px."""
    from vision.features import mark_coverage

    h, w = lin.shape[:2]
    centre, reach = np.array(peak, float), r + 1.5
    ys, xs = np.mgrid[0:h, 0:w]
    for _ in range(steps):
        inside = np.hypot(xs - centre[0], ys - centre[1]) <= reach
        a = mark_coverage(lin[inside] - ring, (spot - ring)[None, :])
        if a.sum() <= 1e-6:
            break
        moved = np.array([(a * xs[inside]).sum(), (a * ys[inside]).sum()]) / a.sum()
        offset = moved - peak
        moved = peak + offset * min(1.0, r / max(float(np.hypot(*offset)), 1e-9))
        step, centre = float(np.hypot(*(moved - centre))), moved
        if step < 0.05:
            break
    return centre


def test_a_large_spots_recentring_is_each_spots_own_also_at_the_image_border():
    # vision.spot_position._recentred takes the spots of one radius in one array (windows of one shape, the pixels
    # outside the image weighing nothing): each spot's centre must be what re-centring it alone gives, for discs
    # cut by the image's border and peaks up to their radius off (an oblique disc's response peaks off its centre)
    from vision.spot_position import CENTROID_STEPS, coverage_centroids

    rng = np.random.default_rng(4)
    lin = np.full((60, 90, 3), 0.2, np.float32) + rng.normal(0, 0.01, (60, 90, 3)).astype(np.float32)
    centres = np.array([[2.0, 30.0], [88.5, 4.0], [45.0, 58.7], [40.0, 25.0], [60.3, 30.2]])
    radius = np.array([4.0, 6.0, 5.0, 8.0, 4.0])
    ys, xs = np.mgrid[0:60, 0:90]
    for (u, v), r in zip(centres, radius):
        lin[np.hypot(xs - u, ys - v) <= r] = (0.05, 0.6, 0.7)
    peaks = centres + rng.uniform(-1, 1, centres.shape) * radius[:, None] * 0.6
    spot, ring = np.tile([0.05, 0.6, 0.7], (5, 1)), np.tile([0.2, 0.2, 0.2], (5, 1))
    together = coverage_centroids(lin, peaks, radius, spot, ring)
    alone = np.array([_recentred_one_at_a_time(lin, p, r, s, g, CENTROID_STEPS)
                      for p, r, s, g in zip(peaks, radius, spot, ring)])
    np.testing.assert_allclose(together, alone, atol=1e-9)
    # the whole discs are found (a disc the border cuts: the centre of its visible part)
    assert np.all(np.hypot(*(together - centres)[3:].T) < 0.1), together - centres



def test_an_oblique_marks_centre_is_its_whole_blobs_and_a_blob_past_the_largest_mark_keeps_its_centre():
    # a disc seen at a grazing angle is a 4:1 ellipse whose response peaks near one end; the re-centred window stalls
    # inside it (a window wholly within a uniform strip does not move), 3-4 px from the centre on a large robot's
    # side (random robots at telephoto: most of their "missed" marks were such detections, 3.0-3.9 px off). Its
    # whole blob's centroid is the centre; paint in the spot's colour reaching past the largest mark is no blob
    from vision.spot_position import blob_centroids, coverage_centroids

    lin = np.full((60, 100, 3), 0.1, np.float32)
    ys, xs = np.mgrid[0:60, 0:100]
    c, s_ = np.cos(np.radians(20)), np.sin(np.radians(20))
    du, dv = xs - 30.3, ys - 30.6
    lin[(((c * du + s_ * dv) / 12.0) ** 2 + ((-s_ * du + c * dv) / 3.0) ** 2) <= 1] = (0.6, 0.1, 0.5)   # the mark
    lin[:, 70:] = (0.6, 0.1, 0.5)                       # a face in the mark's colour, past any mark's size
    spot, ring = np.array([[0.6, 0.1, 0.5]] * 2), np.array([[0.1, 0.1, 0.1]] * 2)
    peaks = np.array([[30.3 - 7.5 * c, 30.6 - 7.5 * s_], [80.0, 30.0]])
    stalled = coverage_centroids(lin, peaks, np.array([3.5, 3.5]), spot, ring)
    assert np.hypot(*(stalled[0] - (30.3, 30.6))) > 2.5          # the window's mean shift alone
    centred, long_axis = blob_centroids(lin, stalled, spot, ring, max_radius=14.0)
    assert np.hypot(*(centred[0] - (30.3, 30.6))) < 0.2, centred
    np.testing.assert_array_equal(centred[1], stalled[1])        # the face: its centre as given
    # the blob's long half-axis: 12 px along the ellipse's axis (either sign); the face has none of its own
    assert abs(np.hypot(*long_axis[0]) - 12.0) < 0.8 and abs(abs(long_axis[0] @ (c, s_)) - 12.0) < 0.8, long_axis
    np.testing.assert_array_equal(long_axis[1], 0.0)


def test_an_oblique_mark_joined_by_a_blend_to_an_area_of_its_colour_is_cut_from_it(monkeypatch):
    # the second robot's dark mark on the thin yellow strip beside its dark top plate: the blend between mark and plate
    # is over half the mark's colour, so the mark's blob joins the plate's and reaches past the largest mark; at a
    # higher coverage the blend is not the mark's colour and the mark's blob is its own
    import vision.spot_position as sp

    lin = np.full((60, 100, 3), 0.6, np.float32)       # the strip's paint
    ys, xs = np.mgrid[0:60, 0:100]
    mark = (((xs - 40.3) / 9.0) ** 2 + ((ys - 30.6) / 4.0) ** 2) <= 1
    lin[mark] = 0.05                                     # the dark mark
    lin[:25, :] = 0.05                                   # the dark plate, its edge 1.6 px above the mark's top
    lin[25:27, 37:44] = 0.6 - 0.55 * 0.58                # a blend, 0.58 of the way to the mark's colour, joins them
    spot, ring = np.array([[0.05] * 3]), np.array([[0.6] * 3])
    stalled = np.array([[36.8, 30.5]])                   # a peak 3.5 px toward the mark's end
    centred, _ = sp.blob_centroids(lin, stalled, spot, ring, max_radius=12.0)
    assert np.hypot(*(centred[0] - (40.3, 30.6))) < 0.5, centred
    monkeypatch.setattr(sp, "SEPARATING_COVERAGE", ())
    kept, _ = sp.blob_centroids(lin, stalled, spot, ring, max_radius=12.0)
    np.testing.assert_array_equal(kept, stalled)         # joined to the plate: no blob of its own, the peak kept


def test_each_windows_blob_is_its_own_when_the_windows_are_labelled_side_by_side():
    from vision.spot_position import _centre_blobs

    # five windows labelled in one mosaic: a full one (its blob every pixel, to its edges) beside a window whose centre
    # blob runs to the edge they share, with another blob there that only the full window would join to it; one with a
    # ring around an unset centre (no blob), one whose blob has a diagonal neighbour, and an empty one
    blob = np.zeros((5, 7, 7), bool)
    blob[0] = True
    blob[1, 3, :4] = blob[1, 6, 0] = True
    blob[2, 2:5, 2:5], blob[2, 3, 3] = True, False
    blob[3, 3, 3] = blob[3, 4, 4] = blob[3, 0, 6] = True
    mine = _centre_blobs(blob)
    assert mine[0].all() and mine[1].sum() == 4 and not mine[1, 6, 0], mine[1]
    assert not mine[2].any() and not mine[4].any()
    assert mine[3].sum() == 2 and mine[3, 4, 4] and not mine[3, 0, 6]


def test_the_second_robots_oblique_marks_are_placed_at_their_centres_through_the_front_end():
    # the wiring of blob_centroids into detect_contrast_marks: on the second robot's committed telephoto frames (marks
    # up to 15 px, its sides seen obliquely) 9 detections lay 1.5-3 px from their mark with the window alone, 2 now
    from scenarios.dataset import open_dataset

    d = Path(__file__).parent / "data" / "photoreal" / "husky-telephoto"
    ds = open_dataset(d)
    world, area = ds.world(), ds.world().bounds()
    off = []
    for cam in ds.cameras:
        for k in range(ds.frames):
            image = cv2.imread(str(ds.image_path(cam, k)))
            prior = mark_prior(ds.camera(cam, k), world.model.mark_radius, world.model.size, area.lo[:3], area.hi[:3])
            found = detect_contrast_marks(image, world.model.palette, prior, body=world.model.body_colour)
            uv = np.array([m.uv for m in ds.truth(k).cameras[cam].marks])
            off += np.hypot(*(found.points[:, None, :] - uv[None]).transpose(2, 0, 1)).min(axis=1).tolist()
    off = np.array(off)
    assert np.count_nonzero((off > 1.5) & (off <= 3.0)) <= 3 and np.count_nonzero(off <= 1.5) >= 40, np.sort(off)

def test_a_mark_on_an_over_exposed_face_is_found_through_the_front_end():
    # the wiring of vision.body_paint.censored_share into detect_contrast_marks: a red mark on a yellow top face
    # clipped in red and green (lemon, as the second robot's through vivid-warm) is ringed by paint and found
    husky = {"red": (35, 35, 200), "blue": (200, 90, 20), "violet": (190, 40, 130), "black": (30, 30, 30)}
    s = 8
    big = np.zeros((120 * s, 160 * s, 3), np.float32)
    big[:] = (118, 120, 124)                                              # grey ground
    cv2.rectangle(big, (40 * s, 30 * s), (120 * s, 60 * s), (3, 253, 254), -1)    # the blown top face
    cv2.rectangle(big, (40 * s, 60 * s), (120 * s, 90 * s), (8, 150, 190), -1)    # its side face in the sun
    cv2.circle(big, (80 * s, 45 * s), 6 * s, (20, 25, 150), -1)                  # a red mark on the top face
    image = cv2.resize(big, (160, 120), interpolation=cv2.INTER_AREA).astype(np.uint8)
    for scorer in ("bars", "shipped"):   # the hand-set bars and the context model (noise-free: vision.mark_scorer.Z_LIMIT)
        found = detect_contrast_marks(image, husky, MarkPrior((4.0, 8.0)), body=(20, 195, 240), look=None,
                                      scorer=scorer)
        pairs = match_to_truth(found.points, np.array([[79.5, 44.5]]), 3.0)[0]
        assert len(pairs) == 1 and found.colours()[pairs[0][0]] == "red", scorer


def test_two_peaks_are_one_spot_exactly_when_the_rule_says_so_however_many_and_wherever():
    """vision.mark_selection.same_spots (pairs found by sorting along u) against its rule over every pair: within the
    larger radius, or a peak at least 1.8 times the other's radius within 1.3 times their sum (hundreds of peaks,
    ties in u, radii from 0.5 to 9 px)."""
    from vision.mark_selection import same_spots

    rng = np.random.default_rng(8)
    for k, spread in ((0, 10.0), (1, 10.0), (2, 0.5), (60, 40.0), (700, 150.0)):
        pts = rng.uniform(0, spread, (k, 2))
        pts[: k // 5, 0] = np.round(pts[: k // 5, 0])
        radius = rng.choice([0.5, 1.0, 1.6, 2.5, 4.0, 9.0], k)
        d = np.hypot(*(pts[:, None, :] - pts[None, :, :]).transpose(2, 0, 1))
        big, small = np.maximum.outer(radius, radius), np.minimum.outer(radius, radius)
        rule = (d <= np.maximum(big, 1.0)) | ((big >= 1.8 * small) & (d < 1.3 * (big + small)))
        assert np.array_equal(same_spots(pts, radius), rule), k
