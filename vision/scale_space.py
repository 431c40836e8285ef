"""The contrast front-end's scale space (:mod:`vision.blobs`, step 1): blurs of an L*a*b* image at the scales the
marks can have, their differences (the scale-normalised Laplacian per channel) and its magnitude; on the image
halved where the target is large (:data:`HALVE_FROM_EXTENT_PX`)."""

from __future__ import annotations

import cv2
import numpy as np

from .mark_prior import MarkPrior
from .spot_position import SMALL_SPOT_PX

#: Scale steps per octave of the scale space.
STEPS_PER_OCTAVE = 3
#: Least difference sigma (px) a scale-space level is blurred from the one below by (:func:`contrast_responses`).
INCREMENTAL_SIGMA = 1.5
#: Weight of the chroma axes against lightness in the response (CIE Lab units).
CHROMA_WEIGHT = 1.0
#: Least margin of ground kept around the body, pixels (the response's spread is the ground's texture, not the
#: body's outline).
MIN_MARGIN_PX = 48
#: Where the target's image is this many pixels across or more (the prior's extent), the scale space is built on the
#: image halved (cv2.INTER_AREA; its pixel (u, v) is the full image's (2 u + 0.5, 2 v + 0.5)) with the mark radii
#: halved: the same response on a quarter of the pixels, at the scale the front-end was built at (the Pioneer's
#: telephoto image, 200-220 px across with marks 2.5-12 px in radius). Positions, colours and context are then taken
#: at full resolution (:mod:`vision.blobs`). The second robot's telephoto image is 456-500 px across: its frames
#: took 2.4-3.1 times the Pioneer's (benchmarks/results/frontend_speed.md), more than a 10 fps clock allows. Chosen
#: from that scale argument, not fitted; measured on the second robot's telephoto worlds (BENCHMARKS.md).
HALVE_FROM_EXTENT_PX = 400.0


def scales(prior: MarkPrior) -> np.ndarray:
    """The blur sigmas of the scale space, pixels: one step below the smallest mark's sigma = r / sqrt(2) to one
    above the largest (a DoG between levels i and i + 1 is centred between them)."""
    step = 2 ** (1 / STEPS_PER_OCTAVE)
    lo = max(0.5, prior.radius_px[0] / np.sqrt(2) / step)
    hi = max(lo * step ** 2, prior.radius_px[1] / np.sqrt(2) * step)
    return lo * step ** np.arange(int(np.ceil(np.log(hi / lo) / np.log(step))) + 2)


def crop_margin(prior: MarkPrior) -> int:
    """Pixels of ground kept around the body's box for the scale space: three of the largest blur sigmas, at least
    :data:`MIN_MARGIN_PX` (a window of the image must keep as much around the body to give the same marks)."""
    return max(int(np.ceil(3 * scales(prior)[-1])) + 2, MIN_MARGIN_PX)


def halved(prior: MarkPrior) -> bool:
    """Whether the scale space of a target seen with ``prior`` is built on the image halved: it is
    :data:`HALVE_FROM_EXTENT_PX` or more across, with marks of 2 :data:`vision.spot_position.SMALL_SPOT_PX` and more
    (still 3 px and more halved)."""
    return (prior.extent_px is not None and prior.extent_px >= HALVE_FROM_EXTENT_PX
            and prior.radius_px[1] >= 2 * SMALL_SPOT_PX)


def halved_image(image: np.ndarray) -> np.ndarray:
    """``image`` (H, W) or (H, W, C) halved: each 2 x 2 block's mean (cv2.INTER_AREA; an odd last row or column
    dropped), its pixel (u, v) the full image's (2 u + 0.5, 2 v + 0.5)."""
    h, w = image.shape[:2]
    return cv2.resize(image[:h // 2 * 2, :w // 2 * 2], (w // 2, h // 2), interpolation=cv2.INTER_AREA)


def halved_prior(prior: MarkPrior) -> MarkPrior:
    """``prior`` for the image halved: its radii (at least 0.5 px) and extent halved."""
    return MarkPrior((max(prior.radius_px[0] / 2, 0.5), prior.radius_px[1] / 2),
                     None if prior.extent_px is None else prior.extent_px / 2)


def scale_space_image(lab: np.ndarray, prior: MarkPrior, region: np.ndarray | None
                      ) -> tuple[np.ndarray, MarkPrior, np.ndarray | None]:
    """The image the scale space is built on, its prior and its region where marks can be (bool (H', W') or None):
    ``lab`` (H, W, 3) float32 itself, ``prior`` and ``region`` (H, W), or all three halved (:func:`halved`; the
    region where half or more of a 2 x 2 block's pixels are: the uint8 block mean rounds 0.25 to 0)."""
    h, w = lab.shape[:2]
    if not halved(prior) or min(h, w) < 20:
        return lab, prior, region
    return (halved_image(lab), halved_prior(prior),
            None if region is None else halved_image(region.astype(np.uint8)) > 0)


def contrast_responses(lab: np.ndarray, sigmas: np.ndarray) -> np.ndarray:
    """Difference-of-Gaussian stack of an L*a*b* image (H, W, 3) float32, shape (S - 1, H, W, 3): the
    scale-normalised Laplacian per channel between the blurs at ``sigmas[i]`` and ``sigmas[i + 1]`` (divided by
    ``k - 1``)."""
    # a coarse level blurred from the one before by the difference sigma (Gaussians compose: s_i+1^2 = s_i^2 + d^2),
    # a kernel 0.6 the size of blurring the image at s_i+1 itself; where d is under INCREMENTAL_SIGMA px a sampled
    # kernel is no Gaussian, and the image is blurred directly
    levels = np.empty((len(sigmas), *lab.shape), np.float32)
    for i, s in enumerate(sigmas):   # each level blurred straight into the stack (no copy)
        d = float(np.sqrt(s ** 2 - sigmas[i - 1] ** 2)) if i else 0.0
        if d >= INCREMENTAL_SIGMA:
            cv2.GaussianBlur(levels[i - 1], (0, 0), d, dst=levels[i])
        else:
            cv2.GaussianBlur(lab, (0, 0), float(s), dst=levels[i])
    k = sigmas[1] / sigmas[0]
    dog = np.subtract(levels[1:], levels[:-1])
    dog /= np.float32(k - 1)
    return dog


def magnitude(dog: np.ndarray) -> np.ndarray:
    """sqrt(L^2 + w^2 (a^2 + b^2)) of a (..., 3) stack, (...): the same operations, in place."""
    w = np.float32(CHROMA_WEIGHT)
    out = np.square(dog[..., 1])
    out += np.square(dog[..., 2])
    out *= w * w
    out += np.square(dog[..., 0])
    return np.sqrt(out, out=out)


__all__ = ["CHROMA_WEIGHT", "HALVE_FROM_EXTENT_PX", "INCREMENTAL_SIGMA", "MIN_MARGIN_PX", "STEPS_PER_OCTAVE",
           "contrast_responses", "crop_margin", "halved", "halved_image", "halved_prior", "magnitude",
           "scale_space_image", "scales"]
