"""The visibility benchmark's measure of a mark (benchmarks/bench_mark_visibility.py): what the image holds of it."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from benchmarks.bench_mark_visibility import mark_contrast, mark_masks

GREY, RED = (128, 128, 128), (60, 60, 200)   # BGR


def disc(centre: tuple[float, float], radius: float, points: int = 24) -> np.ndarray:
    a = np.linspace(0, 2 * np.pi, points, endpoint=False)
    return np.stack([centre[0] + radius * np.cos(a), centre[1] + radius * np.sin(a)], axis=1)


def lab_difference(a: tuple[int, int, int], b: tuple[int, int, int]) -> float:
    pair = cv2.cvtColor(np.array([[a, b]], np.float32) / 255.0, cv2.COLOR_BGR2Lab)[0]
    return float(np.linalg.norm(pair[0] - pair[1]))


def test_a_sharp_mark_on_a_flat_ground_differs_by_its_paints_difference():
    image = np.full((60, 60, 3), GREY, np.uint8)
    cv2.circle(image, (30, 30), 6, RED, -1)
    contrast = mark_contrast(image, disc((30, 30), 5.5)[None])
    assert abs(contrast[0] - lab_difference(RED, GREY)) < 1.0


def test_a_blur_takes_most_of_a_small_marks_contrast_and_little_of_a_large_ones():
    image = np.full((80, 120, 3), GREY, np.uint8)
    cv2.circle(image, (25, 40), 1, RED, -1)
    cv2.circle(image, (80, 40), 12, RED, -1)
    blurred = cv2.GaussianBlur(image, (0, 0), 1.5)
    sharp = mark_contrast(image, np.stack([disc((25, 40), 1.4), disc((80, 40), 12.4)]))
    soft = mark_contrast(blurred, np.stack([disc((25, 40), 1.4), disc((80, 40), 12.4)]))
    assert soft[0] < 0.5 * sharp[0]       # a 3 px mark under a 1.5 px blur: less than half its contrast is left
    assert soft[1] > 0.8 * sharp[1]       # a 25 px one keeps most of it


def test_the_marks_around_a_mark_are_not_counted_in_its_ring():
    image = np.full((60, 60, 3), GREY, np.uint8)
    cv2.circle(image, (30, 30), 3, RED, -1)
    angles = np.linspace(0, 2 * np.pi, 6, endpoint=False)
    around = [(30 + 7 * np.cos(a), 30 + 7 * np.sin(a)) for a in angles]   # six marks ring it 7 px away
    for u, v in around:
        cv2.circle(image, (int(round(u)), int(round(v))), 3, RED, -1)
    listed = mark_contrast(image, np.stack([disc((30, 30), 2.5)] + [disc(c, 2.5) for c in around]))
    alone = mark_contrast(image, disc((30, 30), 2.5)[None])
    assert abs(listed[0] - lab_difference(RED, GREY)) < 1.0
    assert alone[0] < 0.75 * listed[0]         # unlisted, their paint is much of its ring


def test_a_mark_under_a_pixel_keeps_the_pixel_at_its_centre():
    masks = mark_masks(disc((10.2, 7.8), 0.3)[None], (20, 20))
    assert masks.sum() == 1 and masks[0, 8, 10]


@pytest.mark.parametrize("args, says", [(["--looks", "camera,nope"], "unknown look(s) nope"),
                                        (["--looks", "camera"], "no raw/*.exr")])
def test_a_bad_look_or_a_dataset_without_its_radiance_is_one_line_and_exit_2(tmp_path, capsys, args, says):
    from benchmarks.bench_mark_visibility import main

    (tmp_path / "H1").mkdir()
    with pytest.raises(SystemExit) as stop:
        main([str(tmp_path), *args, "--out", str(tmp_path / "out.md")])
    assert stop.value.code == 2
    assert says in capsys.readouterr().err
    assert not (tmp_path / "out.md").exists()


def test_on_a_committed_camera_frame_each_marks_outline_is_centred_on_its_truth_and_stands_clear():
    from benchmarks.bench_mark_visibility import outlines_in
    from scenarios.dataset import open_dataset
    from tests.fleet_procs import ROOT

    dataset = open_dataset(ROOT / "tests" / "data" / "photoreal" / "telephoto")
    marks = [m for m in dataset.truth(0).cameras["H1"].marks if m.fully_visible]
    outlines = outlines_in(dataset, "H1", 0, np.array([m.index for m in marks]))
    centres = outlines.mean(axis=1)   # a disc's outline's mean lies within a fraction of a pixel of its centre's image
    assert np.abs(centres - np.array([m.uv for m in marks])).max() < 0.05
    image = cv2.imread(str(dataset.image_path("H1", 0)), cv2.IMREAD_COLOR)
    contrast = mark_contrast(image, outlines)
    assert len(marks) >= 8 and np.all(contrast >= 10.0)   # the reference look: every telephoto mark plain
    dim = cv2.GaussianBlur((image * 0.25).astype(np.uint8), (0, 0), 4.0)
    assert np.median(mark_contrast(dim, outlines)) < 0.5 * np.median(contrast)
