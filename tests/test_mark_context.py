"""The telephoto context model (vision/mark_context.py): its measures, the shipped model, what it changes on
committed frames, and `evopose train-scorer --scale telephoto`."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from vision.mark_context import CONTEXT_FEATURES, context_features, is_context_model, shipped_context
from vision.mark_scorer import load, shipped
from tests.cli_run import run_cli

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "photoreal"


def test_a_spot_on_a_painted_face_and_one_beside_the_body_measure_as_such():
    # a grey image with a 60 x 60 px painted square (the body) and three 4 px dark discs: two on it, one beside it
    bgr = np.full((100, 140, 3), 128, np.uint8)
    bgr[20:80, 20:80] = (40, 40, 200)
    points = np.array([[40.0, 40.0], [60.0, 60.0], [110.0, 50.0]])
    for u, v in points:
        cv2.circle(bgr, (int(u), int(v)), 4, (20, 160, 20), -1)
    lab = cv2.cvtColor(bgr.astype(np.float32) / 255.0, cv2.COLOR_BGR2Lab)
    paint = np.zeros(bgr.shape[:2], bool)
    paint[20:80, 20:80] = True
    paint[np.hypot(*np.mgrid[:100, :140][::-1] - points[:2, :, None, None]).min(axis=0) <= 4] = False  # the marks' holes
    silhouette = np.zeros_like(paint)
    silhouette[20:80, 20:80] = True
    depth = cv2.distanceTransform(silhouette.astype(np.uint8), cv2.DIST_L2, 3)
    f = context_features(lab, paint, depth, points, np.array([4.0, 4.0, 4.0]), np.array([6.0, 6.0, 3.0]),
                         np.array([0.05, 0.05, 0.05]), np.array([0.5, 0.5, 0.5]), (1.0, 2.0, 3.0), 60.0)
    col = {name: f[:, i] for i, name in enumerate(CONTEXT_FEATURES)}
    assert f.shape == (3, len(CONTEXT_FEATURES))
    np.testing.assert_allclose(col["paint_around"], [1.0, 1.0, 0.0])
    assert col["surrounded"][0] == col["surrounded"][1] == 1.0
    assert col["depth_radii"][0] == 5.0 and col["depth_radii"][1] > 4.5 and col["depth_radii"][2] == 0.0  # 5: capped
    np.testing.assert_allclose(col["log_scale_ratio"], 0.0)                  # one scale
    assert col["log_contrast_ratio"][2] < col["log_contrast_ratio"][0] == col["log_contrast_ratio"][1]
    np.testing.assert_allclose(col["nearest_radii"][:2], np.hypot(20, 20) / 4.0)
    assert context_features(lab, paint, depth, np.zeros((0, 2)), np.zeros(0), np.zeros(0), np.zeros(0),
                            np.zeros(0), (1.0,), 60.0).shape == (0, len(CONTEXT_FEATURES))


def test_the_shipped_context_model_was_fitted_on_training_worlds_only():
    model = shipped_context()
    assert model is not None and is_context_model(model) and not is_context_model(shipped())
    assert 0.0 < model.threshold < 1.0
    # the Pioneer's telephoto training worlds and the random robots, never a benchmark world or the second robot
    fitted = model.fitted_on.split()
    worlds = [w for w in fitted if w.startswith("photoreal")]
    assert worlds and all(w.startswith(("photoreal-telephoto-t", "photoreal-bodies-telephoto-t")) for w in worlds)
    assert "--scale" in fitted and "telephoto" in fitted
    # keep 0.99, not the recall bar of 0.98: chosen on the development robots t1-t3 (never a judged world),
    # where it raised recall 0.9-2.3 points at precision 0.955 and more (BENCHMARKS.md, "context rings")
    assert fitted[fitted.index("--keep") + 1] == "0.99"


def _contrast(name: str, scorer) -> dict:
    from benchmarks.bench_photoreal_features import evaluate, pooled

    return pooled(evaluate(DATA / name, scorer), "contrast")


def test_through_a_flat_cold_camera_the_context_model_drops_what_the_bars_kept():
    # the Pioneer's g2 telephoto frames through flat-cool (never fitted on): the hand-set bars kept lit-paint
    # specks (precision 0.82 measured), the context model none of them (1.00), the same marks found (0.97)
    with_model = _contrast("telephoto-flat-cool", shipped_context())
    bars = _contrast("telephoto-flat-cool", "bars")
    assert _contrast("telephoto-flat-cool", "shipped") == with_model   # the default is the shipped model
    assert with_model["recall"] >= bars["recall"] - 0.01 and with_model["recall"] >= 0.95, (with_model, bars)
    assert with_model["precision"] >= bars["precision"] + 0.1, (with_model, bars)


def test_train_scorer_fits_a_context_model_and_names_a_bad_scale(tmp_path):
    out = tmp_path / "context.json"
    result = run_cli("train-scorer", DATA / "telephoto", DATA / "husky-telephoto", "--scale", "telephoto", "--out", out,
                     "--json")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["candidates"] > summary["marks"] > 0
    model = load(out)
    assert is_context_model(model) and model.fitted_on.endswith("--scale telephoto")
    bad = run_cli("train-scorer", DATA / "telephoto", "--scale", "huge", "--out", tmp_path / "x.json")
    assert bad.returncode == 2 and "--scale" in bad.stderr and "Traceback" not in bad.stderr, bad.stderr


def test_the_agents_extraction_uses_a_context_model_it_is_given():
    # by default, or as --mark-scorer (a small-spot scorer's feature check does not refuse it): on the flat-cool
    # telephoto frames, each camera's frames in order as a vehicle extracts them, the bars (--mark-scorer bars) keep
    # lit-paint specks the model drops and misses marks it keeps (measured: 114 points with the bars, 85 marks
    # found; 106 with the shipped model, 88 found)
    from scenarios.dataset import open_dataset
    from vision.extract import feature_extractor
    from vision.features import match_to_truth

    data = open_dataset(DATA / "telephoto-flat-cool")
    world = data.world()
    counts = {}
    for name, model in (("bars", "bars"), ("model", shipped_context()), ("default", None)):
        points = found = 0
        for cam in data.cameras:
            extract = feature_extractor("contrast", world.model, world.bounds(), model)
            for k in range(data.frames):
                got, _ = extract(cv2.imread(str(data.image_path(cam, k))), data.camera(cam, k))
                whole = np.array([m.uv for m in data.truth(k).cameras[cam].marks if m.fully_visible])
                points, found = points + len(got), found + len(match_to_truth(got, whole, 3.0)[0])
        counts[name] = (points, found)
    assert counts["model"][0] <= counts["bars"][0] - 5 and counts["model"][1] > counts["bars"][1], counts
    assert counts["default"] == counts["model"], counts
