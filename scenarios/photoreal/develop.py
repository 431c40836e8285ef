"""Radiance -> the camera's image: the lens's distortion, then the camera model (:mod:`scenarios.camera_model`).

Blender renders a pinhole image (its pixel filter is the anti-aliasing); a world camera with plumb_bob distortion
gets it by resampling: each output (distorted) pixel takes the pinhole image at its undistorted position, which
OpenCV's iterated ``undistortPoints`` computes (to 1e-6 px). ``initUndistortRectifyMap`` is the other way
round (for each undistorted pixel its distorted source: what undistorting a photograph needs) and would move each
point away from where the camera model projects it. The world's ``blur_sigma`` blurs the light as the lens does.
The camera model then exposes, mosaics, adds sensor noise, demosaics, tones and encodes, seeded per world, camera
and frame. The OpenCV renderer's ``noise_sigma`` and lighting gain are not used: the camera model's sensor noise
and auto exposure stand for them.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from evopose import Camera

from ..camera_model import CameraModelSpec, Captured, capture, linear_from_srgb
from ..sensors import stream_rng
from ..world import Scenario
from .exr import read_exr

#: Iterations and tolerance (pixels) of inverting the lens for each output pixel (:func:`distort`).
UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-6)
#: Stream of the camera model's draws for a dataset's images (the OpenCV renderer's own is 404).
STREAM_DATASET_CAMERA = 505


def distort(radiance: np.ndarray, camera: Camera) -> np.ndarray:
    """The pinhole image ``radiance`` (H, W[, C], intrinsics of ``camera``) as the distorted lens sees it: a point
    projected by the pinhole to ``p`` shows where ``camera`` (plumb_bob) projects it."""
    if not np.any(camera.distortion):
        return radiance
    w, h = camera.width, camera.height
    grid = np.stack(np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64)), axis=-1)
    points = grid.reshape(-1, 1, 2)
    if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4.x; 5.x folded it into undistortPoints
        undistorted = cv2.undistortPointsIter(points, camera.matrix, camera.distortion, None, camera.matrix,
                                              UNDISTORT_CRITERIA)
    else:
        undistorted = cv2.undistortPoints(points, camera.matrix, camera.distortion, R=None, P=camera.matrix,
                                          criteria=UNDISTORT_CRITERIA)
    undistorted = undistorted.reshape(h, w, 2).astype(np.float32)
    return cv2.remap(radiance, undistorted[..., 0], undistorted[..., 1], cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)


def camera_model_of(scenario: Scenario) -> CameraModelSpec:
    """The world's camera model, or the default one (a small industrial colour camera streaming JPEG)."""
    return scenario.render.camera_model or CameraModelSpec()


def camera_rng(scenario: Scenario, vehicle_index: int, frame: int) -> np.random.Generator:
    return stream_rng(scenario.seed, STREAM_DATASET_CAMERA, vehicle_index, frame)


def develop_radiance(radiance: np.ndarray, camera: Camera, spec: CameraModelSpec, rng: np.random.Generator,
                     blur_sigma: float = 0.0) -> Captured:
    """Linear BGR radiance of the pinhole render -> the captured (encoded and decoded) image; ``blur_sigma``
    (the world's ``render.blur_sigma``, pixels) blurs the light as the lens does, before the sensor."""
    light = distort(np.asarray(radiance, np.float32), camera)
    if blur_sigma > 0:
        light = cv2.GaussianBlur(light, (0, 0), blur_sigma)
    return capture(light, spec, rng)


def radiance_of_srgb(image: np.ndarray) -> np.ndarray:
    """An 8-bit sRGB image as linear light (the OpenCV renderer's output before a camera model)."""
    return linear_from_srgb(image)


def develop_exr(scenario: Scenario, exr: Path, k: int, camera: str,
                spec: CameraModelSpec | None = None) -> tuple[bytes, str]:
    """``camera``'s frame ``k`` of ``scenario`` from its radiance ``exr`` (the engine's ``raw/`` image): encoded bytes
    and file suffix, through the world's camera model or ``spec``, seeded per world, camera and frame (the same
    sensor noise whatever ``spec`` encodes)."""
    veh = scenario.vehicle(camera)
    cam = veh.camera_at(scenario.time(k))
    captured = develop_radiance(read_exr(exr), cam, spec or camera_model_of(scenario),
                                camera_rng(scenario, veh.index, k), scenario.render.blur_sigma)
    return captured.encoded, captured.suffix
