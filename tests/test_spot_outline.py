"""A spot's outline drawn out along its blob's long axis (vision.spot_outline), and the context rings that follow it."""

import numpy as np

from vision.body_paint import paint_around
from vision.mark_selection import surrounded
from vision.spot_outline import half_length, outline_radius


def _oblique_mark(angle: float = 0.6) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A 12 x 3 px (half-axes) ellipse at (40.3, 40.6) inside a face of paint, 80 x 80: the paint mask, the image in
    Lab and the ellipse's long half-axis."""
    ys, xs = np.mgrid[0:80, 0:80].astype(float)
    c, s = np.cos(angle), np.sin(angle)
    du, dv = xs - 40.3, ys - 40.6
    mark = ((c * du + s * dv) / 12.0) ** 2 + ((-s * du + c * dv) / 3.0) ** 2 <= 1
    lab = np.zeros((80, 80, 3), np.float32)
    lab[...] = (60.0, 10.0, 40.0)          # the body's paint
    lab[mark] = (50.0, 60.0, -20.0)        # the mark
    return ~mark, lab, np.array([[12.0 * c, 12.0 * s]])


def test_a_blobs_half_length_is_twice_the_root_of_its_largest_second_moment_along_its_axis():
    c, s = np.cos(0.3), np.sin(0.3)
    rotate = np.array([[c, -s], [s, c]])
    cov = rotate @ np.diag([36.0, 2.25]) @ rotate.T     # a uniform 12 x 3 ellipse's moments: half-axes^2 / 4
    axis = half_length(cov[None])[0]
    assert abs(np.hypot(*axis) - 12.0) < 1e-9 and abs(abs(axis @ (c, s)) - 12.0) < 1e-9


def test_the_outline_reaches_its_half_length_along_the_axis_and_its_radius_across_it_and_a_round_spot_is_its_radius():
    directions = np.array([[[1.0, 0.0], [0.0, 2.0], [1.0, 1.0]]] * 3)
    axes = np.array([[10.0, 0.0], [0.0, 0.0], [1.0, 0.0]])    # drawn out; none; shorter than the radius
    reach = outline_radius(directions, np.array([3.0, 3.0, 3.0]), axes)
    np.testing.assert_allclose(reach[0, :2], [10.0, 3.0])
    assert 3.0 < reach[0, 2] < 10.0
    np.testing.assert_array_equal(reach[1:], 3.0)
    np.testing.assert_array_equal(outline_radius(directions, np.array([3.0, 4.0, 5.0]), None)[:, 0], [3.0, 4.0, 5.0])


def test_an_oblique_marks_rings_follow_its_blob_and_read_the_paint_around_it():
    # a circle ring 1-2 px beyond its 3 px radius crosses the mark along its length (reads it as no paint, and in the
    # mark's own colour in those directions); following the blob's long axis they ring the mark in the face's paint
    paint, lab, axis = _oblique_mark()
    centre, radius = np.array([[40.3, 40.6]]), np.array([3.0])
    round_share = paint_around(paint, centre, radius, 1.0)[0]
    drawn_share = paint_around(paint, centre, radius, 1.0, axis)[0]
    assert round_share < 0.7 and drawn_share > 0.97, (round_share, drawn_share)
    assert surrounded(lab, centre, radius)[0] < 0.7 and surrounded(lab, centre, radius, long_axis=axis)[0] == 1.0
    # a round spot (no long axis, or one under its radius) keeps the circle's rings exactly
    assert paint_around(paint, centre, radius, 1.0, np.zeros((1, 2)))[0] == round_share
    # several gaps: the best of their rings, as each alone gives it
    gaps = (1.0, 2.0, 3.0)
    assert paint_around(paint, centre, radius, gaps, axis)[0] == max(paint_around(paint, centre, radius, g, axis)[0]
                                                                   for g in gaps)


def test_the_hand_set_bars_ring_an_oblique_mark_along_its_blob_through_the_front_end():
    # the bars (--mark-scorer bars) read the same rings: on the second robot's committed telephoto frames they find
    # 45 of its 48 marks with the rings along each blob, 44 with circles (measured); its five benchmark worlds gain
    # recall 1.2-7.5 points in every named look (BENCHMARKS.md, "context rings along an oblique mark")
    from pathlib import Path

    from benchmarks.bench_photoreal_features import evaluate, pooled

    rows = evaluate(Path(__file__).parent / "data" / "photoreal" / "husky-telephoto", scorer="bars")
    found = pooled(rows, "contrast")
    assert found["recall"] >= 0.93 and found["precision"] >= 0.95 and found["labels"] == 1.0, found
