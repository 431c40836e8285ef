"""The world tools behind ``evopose render`` (what a vehicle's camera sees, with its ground truth) and
``evopose features`` (an image file to its feature points).

Each returns plain data; input problems raise :class:`scenarios.errors.WorldError` subclasses.
"""

from __future__ import annotations

import json
from pathlib import Path

from vision.features import detect_corners
from scenarios.errors import ImageError
from scenarios.render import render_frame
from scenarios.target import load_model
from scenarios.world import load_scenario

from vision.images import detect_marks, read_image, write_image


def render_to_files(scenario: str | Path, frame: int, out: str | Path, *, vehicle: str | None = None,
                    truth_path: str | Path | None = None, clean: bool = False) -> dict:
    """Render ``frame`` of ``scenario`` as seen by ``vehicle``; write the PNG and its ground truth JSON.

    The truth goes to ``truth_path`` or beside the image (``frame.png`` -> ``frame.json``).
    Returns the truth mapping, with ``image`` and ``truth`` paths added.
    """
    world = load_scenario(scenario)
    rendered = render_frame(world, frame, vehicle, clean=clean)
    image_path = write_image(out, rendered.image)
    truth_path = Path(truth_path) if truth_path is not None else image_path.with_suffix(".json")
    truth = rendered.truth.to_dict()
    k = rendered.camera
    truth["camera"] = {"fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy, "width": k.width, "height": k.height,
                       "distortion": k.distortion.tolist(), "world_from_camera": truth["camera_pose"]}
    truth["model"] = world.model.name
    try:
        truth_path.write_text(json.dumps(truth, indent=1), encoding="utf-8")
    except OSError as err:
        raise ImageError(f"{truth_path}: cannot write: {err.strerror or err}") from None
    return {**truth, "image": str(image_path), "truth": str(truth_path)}


def image_features(image_path: str | Path, *, model: str | Path | None = None, colours: list[str] | None = None,
                   corners: bool = False, max_corners: int = 200) -> dict:
    """The feature points of an image file: colour marks or corners.

    Marks of ``colours`` (hue names such as ``blue``), else of ``model``'s palette, else of any saturated hue.
    Returns ``{"image", "width", "height", "method", "count", "points": [[u, v], ...], "colours": [...],
    "touching": [...]}`` (``touching``: the mark was split from, or merged with, a neighbour).
    """
    image = read_image(image_path)
    out: dict = {"image": str(image_path), "width": int(image.shape[1]), "height": int(image.shape[0])}
    if corners:
        pts = detect_corners(image, max_corners=max_corners)
        return {**out, "method": "corners", "count": len(pts), "points": pts.tolist()}
    wanted = colours if colours else (load_model(model).palette if model is not None else None)
    det = detect_marks(image, wanted)
    return {**out, "method": "colour-marks", "count": len(det), "points": det.points.tolist(),
            "colours": det.colours(), "touching": [bool(v) for v in det.touching]}
