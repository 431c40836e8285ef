"""The front-end's mark scorer (vision/mark_scorer.py): fitting, its file, and `evopose train-scorer`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from vision import mark_scorer
from vision.mark_context import CONTEXT_FEATURES
from vision.mark_scorer import FEATURES, MarkScorer, fit, load, shipped
from scenarios.target import load_model
from tests.cli_run import run_cli

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "tests" / "data" / "photoreal" / "paper"


def _xor(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    # marks where the first two measures agree in sign: no linear rule separates them, a quadratic one does
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, 3))
    return x, (x[:, 0] * x[:, 1] > 0)


def test_the_quadratic_model_separates_what_no_single_measure_does():
    x, y = _xor(600, 0)
    scorer = fit(x, y, ("a", "b", "c"), l2=0.1)
    test_x, test_y = _xor(400, 1)
    right = np.mean(scorer.marks(test_x) == test_y)
    single = max(max(np.mean((test_x[:, i] > 0) == test_y), np.mean((test_x[:, i] <= 0) == test_y)) for i in range(3))
    assert right > 0.9 and single < 0.6, (right, single)


def test_a_feature_far_past_the_fitted_data_scores_as_at_the_limit(monkeypatch):
    # a quadratic model extrapolated turns over: a spot far brighter than any fitted one must not read as no mark
    scorer = shipped()
    far, limit = scorer.mean.copy(), scorer.mean.copy()
    far[0] += 50 * scorer.scale[0]
    limit[0] += mark_scorer.Z_LIMIT * scorer.scale[0]
    p_far, p_limit = scorer.probability(np.stack([far, limit]))
    assert p_far == p_limit
    monkeypatch.setattr(mark_scorer, "Z_LIMIT", np.inf)   # without the limit the far row is scored otherwise
    assert scorer.probability(far[None])[0] != p_limit


def test_a_saved_scorer_reads_back_the_same(tmp_path):
    x, y = _xor(200, 2)
    scorer = fit(x, y, ("a", "b", "c"), fitted_on="xor")
    scorer.save(tmp_path / "s.json")
    again = load(tmp_path / "s.json")
    assert again.names == ("a", "b", "c") and again.threshold == scorer.threshold and again.fitted_on == "xor"
    np.testing.assert_array_equal(again.probability(x), scorer.probability(x))


@pytest.mark.parametrize("change, expected", [
    (lambda d: d.update(format="other/1"), "format must be 'evopose-mark-scorer/1'"),
    (lambda d: d.pop("weights"), "missing field 'weights'"),
    (lambda d: d.update(weights=[1.0, 2.0]), "weights (5,)"),
    (lambda d: d.update(threshold=1.5), "threshold must lie in (0, 1)"),
    (lambda d: d.update(mean="x"), "field mean: expected 2 numbers"),
])
def test_a_malformed_scorer_file_is_one_clear_error(tmp_path, change, expected):
    doc = MarkScorer(("a", "b"), np.zeros(2), np.ones(2), np.zeros(5), 0.0, 0.5).to_dict()
    change(doc)
    (tmp_path / "bad.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError) as error:
        load(tmp_path / "bad.json")
    assert expected in str(error.value)


def test_fit_refuses_one_class():
    with pytest.raises(ValueError, match="both classes"):
        fit(np.zeros((20, 2)), np.zeros(20, bool), ("a", "b"))


def test_the_shipped_scorer_reads_no_palette_and_was_fitted_on_the_training_worlds():
    scorer = shipped()
    palette = load_model(ROOT / "scenarios" / "models" / "pioneer.yaml").palette
    husky = load_model(ROOT / "scenarios" / "models" / "husky.yaml").palette
    # palette-relative features: one scorer for any palette (the Husky's was never fitted on)
    assert scorer.names == FEATURES == mark_scorer.feature_names(tuple(palette)) == mark_scorer.feature_names(
        tuple(husky))
    assert not set(scorer.names) & {f"label_{c}" for c in (*palette, *husky)}   # no palette one-hot
    # fitted on benchmarks/photoreal_worlds.py --set train, never on the benchmark's worlds it is measured on
    assert "photoreal-paper-t" in scorer.fitted_on and "-g1-" not in scorer.fitted_on
    assert 0.0 < scorer.threshold < 1.0


def _first_frame(directory: Path):
    """A committed dataset's first camera's first image, its world and the marks' prior there."""
    import cv2

    from scenarios.dataset import open_dataset
    from vision.blobs import mark_prior

    data = open_dataset(directory)
    world, area, cam = data.world(), data.world().bounds(), data.cameras[0]
    prior = mark_prior(data.camera(cam, 0), world.model.mark_radius, world.model.size, area.lo[:3], area.hi[:3])
    return cv2.imread(str(data.image_path(cam, 0))), world, prior




def test_train_scorer_fits_a_scorer_the_front_end_takes(tmp_path):
    from benchmarks.bench_photoreal_features import evaluate, pooled

    out = tmp_path / "scorer.json"
    result = run_cli("train-scorer", PAPER, "--out", out, "--json")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["candidates"] > summary["marks"] > 0 and summary["out"] == str(out)
    scorer = load(out)
    assert scorer.fitted_on == "evopose train-scorer paper"
    # fitted and measured on the same frames: it keeps most marks and drops most of the rest
    rows = evaluate(PAPER, scorer)
    fitted, bars = pooled(rows, "contrast"), pooled(rows, "bars")
    assert fitted["precision"] > bars["precision"] + 0.1 and fitted["recall"] > 0.7, (fitted, bars)


def test_train_scorer_on_a_missing_dataset_is_one_line_and_exit_2(tmp_path):
    result = run_cli("train-scorer", tmp_path / "nowhere", "--out", tmp_path / "s.json")
    assert result.returncode == 2 and "Traceback" not in result.stderr, result.stderr
    assert len(result.stderr.splitlines()) == 1 and result.stderr.startswith("error: "), result.stderr
    assert not (tmp_path / "s.json").exists()


def test_the_scorer_only_acts_on_spots_under_three_pixels():
    # at telephoto (marks of 3 px and more) a small-spot scorer that would refuse every candidate changes nothing:
    # the context model decides there (vision.mark_context)
    from dataclasses import replace

    from vision.blobs import detect_contrast_marks

    image, world, prior = _first_frame(ROOT / "tests" / "data" / "photoreal" / "telephoto")
    refuses_all = replace(shipped(), bias=-1e6)
    a = detect_contrast_marks(image, world.model.palette, prior, body=world.model.body_colour)
    b = detect_contrast_marks(image, world.model.palette, prior, body=world.model.body_colour, scorer=refuses_all)
    assert len(a) > 5 and a.features.shape == (len(a), len(CONTEXT_FEATURES))   # the context model decided
    np.testing.assert_array_equal(a.points, b.points)


def test_an_unknown_scorer_name_is_refused():
    from vision.blobs import detect_contrast_marks

    with pytest.raises(ValueError, match="scorer must be"):
        detect_contrast_marks(np.zeros((10, 10, 3), np.uint8), {"yellow": (0, 255, 255)}, scorer="best")


def test_the_module_names_what_it_ships():
    assert mark_scorer.SHIPPED.name == "mark_scorer.json" and mark_scorer.SHIPPED.exists()


def test_the_threshold_is_where_the_marks_kept_and_the_precision_meet():
    rng = np.random.default_rng(3)
    y = rng.random(2000) < 0.3
    p = np.clip(np.where(y, rng.normal(0.7, 0.2, 2000), rng.normal(0.3, 0.2, 2000)), 0, 1)
    t = mark_scorer.break_even(p, y)
    kept, precision = np.mean(p[y] >= t), np.mean(y[p >= t])
    assert abs(kept - precision) < 0.03, (t, kept, precision)


def test_with_groups_the_threshold_is_the_break_even_of_each_group_scored_by_a_model_fitted_on_the_others():
    x, y = _xor(400, 5)
    groups = np.arange(400) % 4
    held_out = np.zeros(400)
    for g in range(4):
        held_out[groups == g] = fit(x[groups != g], y[groups != g], ("a", "b", "c"), l2=0.1,
                                    threshold=0.5).probability(x[groups == g])
    scorer = fit(x, y, ("a", "b", "c"), l2=0.1, groups=groups)
    assert scorer.threshold == mark_scorer.break_even(held_out, y)


def test_the_extractor_takes_the_scorer_it_is_given():
    import cv2

    from vision.extract import feature_extractor
    from scenarios.dataset import open_dataset

    data = open_dataset(PAPER)
    world = data.world()
    image, camera = cv2.imread(str(data.image_path(data.cameras[0], 0))), data.camera(data.cameras[0], 0)
    strict = MarkScorer.from_dict({**shipped().to_dict(), "threshold": 0.999})
    found = feature_extractor("contrast", world.model, world.bounds())(image, camera)[0]
    fewer = feature_extractor("contrast", world.model, world.bounds(), strict)(image, camera)[0]
    assert len(found) >= 5 and len(fewer) < len(found) / 2, (len(found), len(fewer))


def test_the_scorer_reads_the_paints_not_their_names_and_serves_a_palette_it_never_saw():
    from vision.blobs import detect_contrast_marks

    for fixture in (PAPER, PAPER.parent / "husky-paper"):   # the Pioneer's palette, and the Husky's (never fitted)
        image, world, prior = _first_frame(fixture)
        found = detect_contrast_marks(image, world.model.palette, prior, body=world.model.body_colour)
        renamed = {f"paint{i}": bgr for i, bgr in enumerate(world.model.palette.values())}  # the paints renamed
        again = detect_contrast_marks(image, renamed, prior, body=world.model.body_colour)
        bars = detect_contrast_marks(image, world.model.palette, prior, body=world.model.body_colour, scorer=None)
        assert found.features is not None and found.features.shape[1] == len(FEATURES) and len(found) > 3
        np.testing.assert_array_equal(found.points, again.points)
        assert bars.features is None and not np.array_equal(found.points, bars.points)


def test_a_blur_of_the_spots_box_is_the_whole_images_at_the_spots_and_their_neighbours():
    """candidate_features blurs only the box around its spots (mark_scorer.blur_box): at every spot and its 3 x 3
    neighbourhood the box's blurs, up to the widest (3 sigma), equal the whole crop's to the bit, also for spots at the
    image's edges (a box too small would read OpenCV's reflected border instead of the image)."""
    import cv2

    from vision.mark_scorer import blur_box

    rng = np.random.default_rng(11)
    lab = rng.uniform(0, 100, (90, 120, 3)).astype(np.float32)
    h, w = lab.shape[:2]
    px = np.array([[1, 1], [60, 45], [118, 88], [5, 70], [100, 3], [61, 44]])
    for sigma in (0.5, 0.9, 1.4, 2.0):
        x0, y0, x1, y1 = blur_box(px, 3.0 * sigma, w, h)
        assert (x1 - x0) * (y1 - y0) <= w * h
        for scale in (1.0, 1.26, 3.0):
            whole = cv2.GaussianBlur(lab, (0, 0), sigma * scale)
            boxed = cv2.GaussianBlur(lab[y0:y1, x0:x1], (0, 0), sigma * scale)
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    u, v = np.clip(px[:, 0] + dx, 1, w - 2), np.clip(px[:, 1] + dy, 1, h - 2)
                    np.testing.assert_array_equal(boxed[v - y0, u - x0], whole[v, u])
    # the box of spots in the middle of a large image is a small part of it
    x0, y0, x1, y1 = blur_box(np.array([[500, 400], [530, 420]]), 3.0, 1000, 800)
    assert (x0, y0, x1, y1) == (486, 386, 545, 435)
