"""The contrast front-end's fast kernels (docs/design.md, "The feature front-end") give what the plain operations
they replace give, to the bit: the same image in, the same pixels, points and shares out."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from vision.body_paint import dilate_disc


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
