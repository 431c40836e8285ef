"""A degraded camera (issue 13): what a vehicle's bad lens, a smudge or a near obstacle does to its image.

Three nuisances of one camera, on top of the world's (``camera: {degraded: ...}`` in a world file,
:class:`scenarios.world.DegradedCameraSpec`):

* **heavy blur** — a Gaussian of ``blur_sigma`` pixels composed with the world's (sigmas add in quadrature): marks
  spread, merge with their neighbours and lose contrast, so their centroids move and some vanish;
* **an occluder** over ``occluded_fraction`` of the target: an opaque band in front of the camera, a share of the
  target's image box wide (the whole box height), from its left side: the marks behind it are not seen;
* **distractors** — ``distractors`` more blobs in the mark colours near the target (false image points).

The draws come from their own stream (:data:`STREAM_DEGRADED`), so a degraded camera's frame has the same noise,
lighting and world distractors as the healthy camera's frame of the same seed: the comparison of a healthy and a
degraded fleet is on the same seeded frames, the degradation alone differing.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from evopose import Camera

#: Stream number of the degradation's random draws (:func:`scenarios.sensors.stream_rng`).
STREAM_DEGRADED = 303
#: Colour of the occluding band (BGR): a dull grey, unlike any mark's paint.
OCCLUDER_COLOUR = (70, 75, 80)


def composed_blur(world_sigma: float, camera_sigma: float) -> float:
    """One Gaussian equal to blurring by ``world_sigma`` then by ``camera_sigma`` (pixels)."""
    return math.sqrt(world_sigma ** 2 + camera_sigma ** 2)


def target_box(camera: Camera, vertices_world: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The image box ``(lo, hi)`` (2,) each, pixels, of the target's body vertices (K, 3) in front of the camera."""
    uv, front = camera.project_world(vertices_world)
    if not np.any(front):
        return None
    uv = uv[front]
    return uv.min(axis=0), uv.max(axis=0)


def occluder_band(box: tuple[np.ndarray, np.ndarray], fraction: float, margin: float = 2.0) -> np.ndarray:
    """The band hiding ``fraction`` of the target's image ``box``: ``(u0, v0, u1, v1)`` pixels, from the box's left."""
    lo, hi = box
    width = float(hi[0] - lo[0])
    return np.array([lo[0] - margin, lo[1] - margin, lo[0] + fraction * width, hi[1] + margin])


def draw_band(image: np.ndarray, band: np.ndarray) -> None:
    """Paint the occluding ``band`` (u0, v0, u1, v1) into ``image`` (H, W, 3) in place."""
    u0, v0, u1, v1 = (int(round(c)) for c in band)
    cv2.rectangle(image, (u0, v0), (u1, v1), OCCLUDER_COLOUR, -1)


def inside_band(uv: np.ndarray, band: np.ndarray | None) -> np.ndarray:
    """Whether pixels (..., 2) lie behind the ``band`` (all False without one)."""
    if band is None:
        return np.zeros(uv.shape[:-1], bool)
    return (uv[..., 0] >= band[0]) & (uv[..., 0] <= band[2]) & (uv[..., 1] >= band[1]) & (uv[..., 1] <= band[3])
