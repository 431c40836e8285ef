"""Images for the pose-problem contract: reading and writing image files, finding the marks in them,
a search box from one camera, and an overlay of a solution.

Input problems raise :class:`scenarios.errors.WorldError` subclasses whose one-line message the CLI
prints as ``error: ...`` with exit code 2. Nothing here renders: the simulator is not imported.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from evopose import Bounds, Camera, Model
from vision.features import MarkDetections, detect_colour_marks
from geometry import matrix_from_pose
from scenarios.errors import ImageError, WorldError
from scenarios.target import TargetModel

def read_image(path: str | Path) -> np.ndarray:
    """A BGR uint8 image from a file (PNG, JPEG, ...).

    Raises
    ------
    ImageError
        The file is missing or is not a decodable image.
    """
    path = Path(path)
    if not path.is_file():
        raise ImageError(f"{path}: cannot read: no such file")
    data = np.fromfile(str(path), dtype=np.uint8)
    image = cv2.imdecode(data, cv2.IMREAD_COLOR) if data.size else None
    if image is None:
        raise ImageError(f"{path}: cannot read: not an image OpenCV can decode")
    return image


def write_image(path: str | Path, image: np.ndarray) -> Path:
    path = Path(path)
    if path.suffix.lower() not in (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff"):
        raise ImageError(f"{path}: unsupported image type {path.suffix!r} (use .png)")
    if path.parent and not path.parent.exists():
        raise ImageError(f"{path}: cannot write: directory {path.parent} does not exist")
    if not cv2.imwrite(str(path), image):
        raise ImageError(f"{path}: cannot write the image")
    return path


def detect_marks(image: np.ndarray, colours: dict | list[str] | None = None) -> MarkDetections:
    """Colour marks in a BGR image: of a palette (name -> BGR, a model's), of hue names (``["blue", "yellow"]``),
    or, by default, of any saturated hue."""
    try:
        return detect_colour_marks(image, colours)
    except (KeyError, ValueError) as err:
        raise WorldError(f"colours: {' '.join(str(err).split())}") from None


def frustum_bounds(camera: Camera, model: Model, points: np.ndarray) -> Bounds:
    """A search box for a target seen by one camera: around where its marks are, at the depth their size gives.

    The target's apparent size is measured robustly, so that clutter does not shrink the depth: the median
    distance of the image points (shape (N, 2), pixels) to their median, against the median distance of the
    model's points to their centroid (metres); depth = f * model size / image size, searched from half to twice
    that (foreshortening of a tilted target, a quarter of the points being clutter). Laterally the box holds
    the rays through the marks' robust centre, widened by three times their robust size and the model's radius;
    angles span a full turn. The box is in the world frame (the camera's extrinsic applied).
    """
    points = np.asarray(points, float).reshape(-1, 2)
    centre = np.median(points, axis=0) if len(points) else np.array([camera.cx, camera.cy])
    image_size = float(np.median(np.linalg.norm(points - centre, axis=1))) if len(points) > 1 else 0.0
    marks = np.asarray(model.points, float)
    model_size = float(np.median(np.linalg.norm(marks - marks.mean(axis=0), axis=1)))
    f = 0.5 * (camera.fx + camera.fy)
    depth = f * max(model_size, 1e-3) / max(image_size, 0.5)
    half_px = 3.0 * max(image_size, 1.0)
    u_lo, u_hi = max(centre[0] - half_px, 0.0), min(centre[0] + half_px, float(camera.width))
    v_lo, v_hi = max(centre[1] - half_px, 0.0), min(centre[1] + half_px, float(camera.height))
    corners = [[(u - camera.cx) / camera.fx * z, (v - camera.cy) / camera.fy * z, z]
               for z in (0.5 * depth, 2.0 * depth) for u in (u_lo, u_hi) for v in (v_lo, v_hi)]
    world = np.array(corners) @ camera.world_from_camera[:3, :3].T + camera.world_from_camera[:3, 3]
    lo, hi = world.min(axis=0) - model.radius, world.max(axis=0) + model.radius
    return Bounds.from_dict({n: (float(lo[i]), float(hi[i])) for i, n in enumerate("xyz")})


def draw_overlay(image: np.ndarray | None, camera: Camera, model: Model, pose: np.ndarray,
                 points: np.ndarray, target: TargetModel | None = None) -> np.ndarray:
    """The image (or a dark canvas) with the image points (green crosses) and the model projected at
    ``pose`` (visible marks as red circles, the body outline when ``target`` is given)."""
    canvas = np.full((camera.height, camera.width, 3), 40, np.uint8) if image is None else image.copy()
    T = matrix_from_pose(np.asarray(pose, float))
    if target is not None and len(target.body.faces):
        v = target.body.vertices @ T[:3, :3].T + T[:3, 3]
        uv, front = camera.project_world(v)
        normals = target.body.normals @ T[:3, :3].T
        for face, n, two_sided in zip(target.body.faces, normals, target.body.two_sided):
            seen = two_sided or np.dot(n, camera.center_world - v[face].mean(axis=0)) > 0
            if seen and front[face].all():
                pts = np.round(uv[face] * 16).astype(np.int32)
                cv2.polylines(canvas, [pts], True, (255, 200, 0), 1, cv2.LINE_AA, 4)
    p_world = model.points @ T[:3, :3].T + T[:3, 3]
    uv, front = camera.project_world(p_world)
    visible = front.copy()
    if model.normals is not None:
        n_world = model.normals @ T[:3, :3].T
        visible &= np.sum(n_world * (camera.center_world - p_world), axis=1) > 0
    for (u, v), ok in zip(uv, visible):
        if ok and abs(u) < 1e5 and abs(v) < 1e5:
            cv2.circle(canvas, (int(round(u * 16)), int(round(v * 16))), 6 * 16, (0, 0, 255), 2, cv2.LINE_AA, 4)
    for u, v in np.asarray(points, float).reshape(-1, 2):
        cv2.drawMarker(canvas, (int(round(u)), int(round(v))), (0, 255, 0), cv2.MARKER_CROSS, 10, 1, cv2.LINE_AA)
    return canvas


__all__ = ["WorldError", "detect_marks", "draw_overlay", "frustum_bounds", "read_image",
           "write_image"]
