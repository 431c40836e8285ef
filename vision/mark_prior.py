"""What a camera's geometry says about the marks in its image: their radius range and the target's extent in pixels
(the contrast front-end's scale space and context, :mod:`vision.blobs`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MarkPrior:
    """What the camera's geometry says about the marks in its image.

    ``radius_px``: the smallest and the largest radius a mark can have, pixels (mark radius times focal length
    over the farthest and the nearest distance of the operating area; an oblique disc is narrower). ``extent_px``:
    the target's largest extent in pixels at the nearest distance, or None (no context filter).
    """

    radius_px: tuple[float, float] = (0.7, 12.0)
    extent_px: float | None = None

    def __post_init__(self) -> None:
        lo, hi = self.radius_px
        if not (0 < lo <= hi and np.isfinite(hi)):
            raise ValueError(f"radius_px must be 0 < lo <= hi, got {self.radius_px}")


def mark_prior(camera, mark_radius: float, target_extent: float, lo: np.ndarray, hi: np.ndarray,
               min_facing: float = 0.3) -> MarkPrior:
    """The :class:`MarkPrior` of ``camera`` (a :class:`evopose.Camera` with its ``world_from_camera``) for a target
    whose marks have radius ``mark_radius`` and whose largest extent is ``target_extent`` (metres), somewhere in
    the box ``lo``..``hi`` (world x, y, z, shape (3,) each: the operating area). A disc seen at ``min_facing``
    (cosine) is that much narrower."""
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])], float)
    p_cam = corners @ camera.world_from_camera[:3, :3] - camera.world_from_camera[:3, 3] @ camera.world_from_camera[
        :3, :3]
    dist = np.linalg.norm(p_cam, axis=1)
    centre = camera.world_from_camera[:3, :3].T @ ((lo + hi) / 2 - camera.world_from_camera[:3, 3])
    near = max(float(dist.min()) if np.all(p_cam[:, 2] > 0) else float(np.linalg.norm(centre)) * 0.5, 1e-3)
    near = max(near - target_extent, 1e-3)
    far = float(dist.max()) + target_extent
    f = max(camera.fx, camera.fy)
    return MarkPrior((max(0.5, min_facing * f * mark_radius / far), f * mark_radius / near),
                     f * target_extent / near)


__all__ = ["MarkPrior", "mark_prior"]
