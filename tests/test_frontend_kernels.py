"""The contrast front-end's fast kernels (docs/design.md, "The feature front-end") give what the plain operations
they replace give, to the bit: the same image in, the same pixels, points and shares out."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from vision.body_paint import dilate_disc, paint_around, pixel_box
from vision.spot_colour import ring_colours


@pytest.mark.parametrize("seed", range(4))
def test_dilating_and_closing_by_a_disc_match_opencv_at_any_radius_and_density(seed):
    rng = np.random.default_rng(seed)
    for _ in range(60):
        h, w = (int(n) for n in rng.integers(1, 90, 2))
        r = int(rng.integers(1, 40))
        mask = rng.random((h, w)) < rng.choice([0.002, 0.02, 0.1, 0.5, 0.95])
        disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
        assert np.array_equal(dilate_disc(mask, disc), cv2.dilate(mask.astype(np.uint8), disc) > 0)
        closed = cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_CLOSE, disc) > 0
        assert np.array_equal(~dilate_disc(~dilate_disc(mask, disc), disc), closed)


def test_dilating_a_mask_too_wide_for_16_bit_coordinates_matches_opencv():
    rng = np.random.default_rng(11)
    mask = rng.random((5, 16500)) < 0.01   # 2 w + r + 4 past 16 bits: the coordinates are taken in 32
    mask[[0, 4]] = False                   # a row without a pixel: its distance to one is past 16 bits
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (9, 9))
    assert np.array_equal(dilate_disc(mask, disc), cv2.dilate(mask.astype(np.uint8), disc) > 0)


def test_a_mask_box_is_the_box_of_its_pixels_and_none_for_an_empty_mask():
    rng = np.random.default_rng(7)
    for _ in range(50):
        mask = rng.random(tuple(int(n) for n in rng.integers(1, 40, 2))) < rng.choice([0.0, 0.01, 0.3])
        ys, xs = np.nonzero(mask)
        expected = None if not len(ys) else (ys.min(), ys.max(), xs.min(), xs.max())
        assert pixel_box(mask) == expected


def test_ring_colours_are_the_median_of_each_rings_pixels_inside_the_image():
    rng = np.random.default_rng(8)
    image = rng.normal(size=(40, 50, 3))
    points = np.column_stack([rng.uniform(0, 49, 60), rng.uniform(0, 39, 60)])
    radius = rng.choice([1.0, 2.5, 4.7], 60)
    yy, xx = np.mgrid[:40, :50]
    expected = [np.median(image[(np.hypot(xx - u, yy - v) >= r + 1.5) & (np.hypot(xx - u, yy - v) <= r + 3.0)], axis=0)
                for (u, v), r in zip(points, radius)]
    assert np.array_equal(ring_colours(image, points, radius), np.array(expected))


def test_paint_rings_count_the_paint_pixels_of_each_ring_as_one_ring_at_a_time_does():
    rng = np.random.default_rng(9)
    paint = rng.random((60, 80)) < 0.5
    points = np.column_stack([rng.uniform(-4, 84, 200), rng.uniform(-4, 64, 200)])
    radius = rng.choice([1.0, 2.9, 4.7, 9.4], 200)
    for gap in (1.0, 2.0, 3.0):
        expected = []
        for (u, v), r in zip(points, radius):   # one ring at a time
            reach = int(np.ceil(r + gap + 1))
            yy, xx = np.mgrid[-reach:reach + 1, -reach:reach + 1]
            cu, cv = int(round(u)), int(round(v))
            d = np.hypot(xx + cu - u, yy + cv - v)
            ring = (d >= r + gap) & (d <= r + gap + 1)
            ys, xs = yy[ring] + cv, xx[ring] + cu
            inside = (ys >= 0) & (ys < 60) & (xs >= 0) & (xs < 80)
            expected.append(np.count_nonzero(paint[ys[inside], xs[inside]]) / max(int(ring.sum()), 1))
        assert np.array_equal(paint_around(paint, points, radius, gap), np.array(expected))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_a_median_by_one_sort_is_numpys_median_to_the_bit(dtype):
    from vision.order_stats import median
    rng = np.random.default_rng(10)
    for _ in range(300):
        shape = (int(rng.integers(1, 9)), int(rng.integers(1, 400)))
        a = (rng.standard_normal(shape) ** 3).astype(dtype)
        if rng.random() < 0.3:   # ties
            a = np.round(a, 1).astype(dtype)
        for axis in (0, 1, -1):
            got, want = median(a, axis=axis), np.median(a, axis=axis)
            assert got.dtype == want.dtype and np.array_equal(got, want)
        assert median(a.reshape(-1)) == np.median(a)


def test_the_pixels_a_ring_can_reach_hold_every_rings_pixels_and_none_far_from_it():
    from vision.ring_pixels import ring_pixels
    rng = np.random.default_rng(12)
    for _ in range(300):
        first, size = int(rng.integers(-30, 1)), int(rng.integers(3, 60))
        lo = float(rng.choice([0.0, -0.5]))
        hi = lo + 1.0
        inner = float(rng.uniform(0, 10))
        outer = inner + float(rng.uniform(0.5, 8))
        rows, cols = ring_pixels(first, size, lo, hi, inner, outer)
        kept = np.zeros((size, size), bool)
        kept[rows, cols] = True
        k = first + np.arange(size)
        for cy, cx in rng.uniform(lo, hi, (20, 2)):   # a centre anywhere in its range: its ring is kept
            d = np.hypot(k[None, :] - cx, k[:, None] - cy)
            assert kept[(d >= inner) & (d <= outer)].all()
        centre = (lo + hi) / 2                          # a pixel no centre can bring within the ring: left out
        d = np.hypot(k[None, :] - centre, k[:, None] - centre)
        assert not kept[(d > outer + 1.5) | (d < inner - 1.5)].any()
