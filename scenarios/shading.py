"""Drawing in linear light for the OpenCV renderer with a camera model (:mod:`scenarios.render`).

Paint is lit by the sun: ambient, Lambert diffuse and a Blinn-Phong highlight (:func:`lit_linear`), computed on
linear values (the palette's sRGB colours decoded). OpenCV anti-aliases only 8-bit drawing, so a polygon or an
ellipse is drawn into a float image by its coverage: OpenCV draws the shape anti-aliased into an 8-bit mask over
its box, and the colour is blended by that mask (:func:`blend`), which is how coverage mixes light.
"""

from __future__ import annotations

import cv2
import numpy as np

from .camera_model import linear_from_srgb
from .world import LightingSpec

#: Fixed-point bits of the drawing coordinates (1/16 px), as in :mod:`scenarios.render`.
SHIFT = 4


def lit_linear(colours_srgb: np.ndarray, normals_cam: np.ndarray, points_cam: np.ndarray, sun_cam: np.ndarray,
               light: LightingSpec) -> np.ndarray:
    """Linear radiance (N, 3) of flat paint of sRGB ``colours_srgb`` (N, 3) at camera-frame ``points_cam`` with
    unit ``normals_cam``: ambient + Lambert diffuse of the sun (``1 - ambient`` of the light) + a white
    Blinn-Phong highlight where the half vector of the sun and the line of sight meets the normal."""
    albedo = linear_from_srgb(np.asarray(colours_srgb, float)).astype(float).reshape(-1, 3)
    cos_sun = normals_cam @ sun_cam
    diffuse = light.ambient + (1 - light.ambient) * np.clip(cos_sun, 0, 1)
    radiance = albedo * diffuse[:, None]
    if light.specular > 0 and len(points_cam):
        view = -points_cam / np.linalg.norm(points_cam, axis=1, keepdims=True)
        half = view + sun_cam
        half /= np.maximum(np.linalg.norm(half, axis=1, keepdims=True), 1e-12)
        lobe = np.clip(np.sum(normals_cam * half, axis=1), 0, 1) ** light.shininess
        radiance += ((1 - light.ambient) * light.specular * lobe * (cos_sun > 0))[:, None]
    return radiance


def fill_linear(image: np.ndarray, pts: np.ndarray, colour) -> None:
    """A convex polygon (fixed-point ``pts``, :data:`SHIFT` bits) into a float image, anti-aliased: OpenCV draws
    its coverage (8-bit, LINE_AA) in the polygon's box and the colour is blended by it (in linear light)."""
    h, w = image.shape[:2]
    lo = np.maximum(pts.min(axis=0) >> SHIFT, 0) - 1
    hi = np.minimum((pts.max(axis=0) >> SHIFT) + 2, [w, h])
    lo = np.maximum(lo, 0)
    if hi[0] <= lo[0] or hi[1] <= lo[1]:
        return
    mask = np.zeros((hi[1] - lo[1], hi[0] - lo[0]), np.uint8)
    cv2.fillConvexPoly(mask, pts - (lo << SHIFT).astype(np.int32), 255, cv2.LINE_AA, SHIFT)
    blend(image[lo[1]:hi[1], lo[0]:hi[0]], mask, colour)


def blend(roi: np.ndarray, mask: np.ndarray, colour) -> None:
    """``roi`` (float, in place) towards ``colour`` by the 8-bit coverage ``mask``."""
    alpha = mask.astype(np.float32) * np.float32(1 / 255)
    roi += (np.asarray(colour, np.float32) - roi) * alpha[..., None]


def ellipse_linear(image: np.ndarray, uv: np.ndarray, r: float, centre, axes, angle: float, colour) -> None:
    """An anti-aliased filled ellipse into a float image (coverage blended, as :func:`fill_linear`)."""
    h, w = image.shape[:2]
    x0, y0 = max(int(uv[0] - r) - 2, 0), max(int(uv[1] - r) - 2, 0)
    x1, y1 = min(int(uv[0] + r) + 3, w), min(int(uv[1] + r) + 3, h)
    if x1 <= x0 or y1 <= y0:
        return
    mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
    cv2.ellipse(mask, (centre[0] - (x0 << SHIFT), centre[1] - (y0 << SHIFT)), axes, angle, 0, 360, 255, -1,
                cv2.LINE_AA, SHIFT)
    blend(image[y0:y1, x0:x1], mask, colour)
