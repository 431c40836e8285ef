"""A spot's outline as an ellipse: the disc of its scale-space radius, drawn out along its blob's long axis.

A mark seen at a grazing angle is an ellipse up to four times as long as wide (a robot's sides from a helicopter
20-30 deg above them). Its scale-space radius is about the short half-axis, so a ring a few pixels beyond that radius
crosses the mark itself along its length: the rings that measure its context (:func:`vision.body_paint.paint_around`,
:func:`vision.mark_selection.surrounded`) read the mark's own colour there and take it for no paint. The outline
here keeps the radius across the blob and its half-length along it (:func:`vision.spot_position.blob_centroids`
measures the blob's second moments), so a ring follows it. Shapes: ``long_axis`` (K, 2) px, a vector along the long
axis as long as its half-length (zeros: no blob of its own; one no longer than the radius leaves the circle).
"""

from __future__ import annotations

import numpy as np


def half_length(cov: np.ndarray) -> np.ndarray:
    """The long half-axis (K, 2) px of blobs whose coverage has the second moments ``cov`` (K, 2, 2) px^2: along
    the largest eigenvector, 2 sqrt(eigenvalue) long (a uniform ellipse's moments are its half-axes squared over 4)."""
    values, vectors = np.linalg.eigh(np.asarray(cov, float))          # ascending
    return vectors[:, :, 1] * (2.0 * np.sqrt(np.maximum(values[:, 1], 0.0)))[:, None]


def outline_radius(directions: np.ndarray, radius: np.ndarray, long_axis: np.ndarray | None) -> np.ndarray:
    """How far (K, D) px the outline of each spot reaches along ``directions`` (K, D, 2) (any length, not zero):
    ``radius`` (K,) across, the long axis's length (at least the radius) along it. No ``long_axis``: the radius."""
    radius = np.asarray(radius, float).reshape(-1)
    shape = np.asarray(directions).shape[:2]
    if long_axis is None:
        return np.broadcast_to(radius[:, None], shape).copy()
    long_axis = np.asarray(long_axis, float).reshape(-1, 2)
    length = np.hypot(long_axis[:, 0], long_axis[:, 1])
    along_len = np.maximum(length, radius)                                           # (K,)
    drawn = along_len > radius
    unit = long_axis / np.where(length > 0, length, 1.0)[:, None]
    d = np.asarray(directions, float)
    cos = np.einsum("kdc,kc->kd", d, unit) / np.maximum(np.linalg.norm(d, axis=2), 1e-12)
    sin2 = np.maximum(1.0 - cos * cos, 0.0)
    ellipse = 1.0 / np.sqrt(cos * cos / along_len[:, None] ** 2 + sin2 / radius[:, None] ** 2)
    return np.where(drawn[:, None], ellipse, radius[:, None])


__all__ = ["half_length", "outline_radius"]
