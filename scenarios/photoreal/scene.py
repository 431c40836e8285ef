"""A world as a Blender scene description: plain JSON that :mod:`scenarios.photoreal.blender_job` builds.

Everything is computed here, in the project's interpreter (poses, intrinsics, materials, meshes); the job
script, run by Blender's interpreter, only builds what the description says. Conventions:

- Cameras. The project's camera is OpenCV's optical frame (x right, y down, z forward) with intrinsics
  ``fx = fy, cx, cy`` in pixels, the centre of pixel (0, 0) at (0, 0). A Blender camera looks down its -z with
  +y up, so its matrix is ``world_from_camera @ diag(1, -1, -1)`` (180 deg about x). With ``sensor_fit``
  horizontal and the sensor ``width`` units wide, ``lens = fx`` makes the focal length ``fx`` pixels; Blender's
  shift moves the image window by ``shift * width`` pixels, so the principal point ``(cx, cy)`` is
  ``shift_x = (width / 2 - cx - 0.5) / width`` and ``shift_y = (cy + 0.5 - height / 2) / width``
  (:func:`project_blender` is the same mapping as formulas, checked against :meth:`evopose.Camera.project_world`).
  Lens distortion is applied afterwards to the rendered radiance (:mod:`scenarios.photoreal.develop`).
- Colours. The model's and the world's colours are sRGB BGR 0-255; materials get linear RGB albedo.
- Units. Metres, radians; the world is z up with the ground at ``z = 0`` (Blender's convention too).
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np

from geometry import matrix_from_pose

from ..errors import ScenarioError
from ..mesh import box_mesh
from ..ground import TEXTURE_SIZE, ground_texture
from ..world import Scenario
from .shapes import clutter_solid, from_mesh, join, mark_disc

FORMAT = "evopose-blender-job/1"
#: Half side of the ground plane, metres (the farthest ground a low camera sees lies well inside).
GROUND_HALF_SIZE = 2000.0
#: The sun's angular diameter, radians (soft shadow edges as outdoors).
SUN_ANGLE = math.radians(0.53)
#: Default engine settings; a dataset's manifest records the ones used.
ENGINE_DEFAULTS = {"samples": 24, "filter": "BLACKMAN_HARRIS", "filter_width": 1.5, "denoise": False,
                   "max_bounces": 4, "diffuse_bounces": 2, "glossy_bounces": 2, "transparent_bounces": 2,
                   "clamp_indirect": 10.0}
GROUND_ROUGHNESS = 0.9
OCCLUDER_ROUGHNESS = 0.7


def srgb_to_linear(bgr) -> list[float]:
    """sRGB BGR 0-255 -> linear RGB 0-1 (IEC 61966-2-1)."""
    c = np.asarray(bgr, float)[::-1] / 255.0
    lin = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return [round(float(v), 6) for v in lin]


def blender_camera(intrinsics, name: str = "camera") -> dict:
    """The Blender camera data of OpenCV intrinsics (``fx, fy, cx, cy, width, height``)."""
    k = intrinsics
    if abs(k.fx - k.fy) > 1e-6 * k.fx:
        raise ScenarioError(f"camera {name}: fx {k.fx} != fy {k.fy}: the photoreal renderer needs square pixels")
    return {"width": int(k.width), "height": int(k.height), "sensor_fit": "HORIZONTAL",
            "sensor_width": float(k.width), "lens": float(k.fx),
            "shift_x": (k.width / 2 - k.cx - 0.5) / k.width, "shift_y": (k.cy + 0.5 - k.height / 2) / k.width,
            "clip_start": 0.05, "clip_end": 10000.0, "distortion": [float(d) for d in k.distortion]}


#: OpenCV optical frame -> Blender camera frame: 180 deg about x.
CV_TO_BLENDER = np.diag([1.0, -1.0, -1.0, 1.0])


def blender_matrix(world_from_camera: np.ndarray) -> np.ndarray:
    """The Blender camera object's matrix of an OpenCV ``world_from_camera``."""
    return np.asarray(world_from_camera, float) @ CV_TO_BLENDER


def project_blender(camera: dict, matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Pixel coordinates (OpenCV convention) of world points seen by a Blender camera, by Blender's own
    view-plane formulas (``BKE_camera_params_compute_viewplane``, horizontal sensor fit), shape (K, 2)."""
    p = np.asarray(points, float).reshape(-1, 3)
    cam = (p - matrix[:3, 3]) @ matrix[:3, :3]  # camera-local coordinates, looking down -z
    w, h = camera["width"], camera["height"]
    scale = camera["lens"] / camera["sensor_width"] * w      # pixels per unit of x / -z
    x_win = cam[:, 0] / -cam[:, 2] * scale                   # window coordinates, pixels, origin on the axis
    y_win = cam[:, 1] / -cam[:, 2] * scale
    dx, dy = camera["shift_x"] * w, camera["shift_y"] * w    # the window's shift (viewfac = width)
    u_edge = x_win - (-w / 2 + dx)                           # from the left edge
    v_edge = (h / 2 + dy) - y_win                            # from the top edge
    return np.column_stack([u_edge - 0.5, v_edge - 0.5])    # pixel centres at integers


def write_ground_texture(scenario: Scenario, path: Path) -> dict:
    """The renderer's procedural ground texture as a PNG for Blender (rows flipped: Blender's image origin is the
    bottom left, so texel (col, row) lies at ground (x, y) = (col, row) * texel as in :mod:`scenarios.render`)."""
    ground = scenario.render.ground
    tex = ground_texture(scenario.seed, tuple(ground.colour), float(ground.contrast))
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), np.ascontiguousarray(tex[::-1]))
    return {"texture": str(path), "tile": TEXTURE_SIZE * float(ground.texel)}


def _material(bgr, roughness: float, **extra) -> dict:
    return {"base_colour": srgb_to_linear(bgr), "roughness": float(roughness), **extra}


def describe_scene(scenario: Scenario, work_dir: Path, *, target: bool = True, engine: dict | None = None,
                   cameras: list[str] | None = None) -> dict:
    """The static scene: materials, objects (target parts and marks under the ``target`` parent, occluders as
    movers, clutter), the ground, sun and sky, the cameras. ``work_dir`` receives the ground texture."""
    render = scenario.render
    light = render.lighting
    model = scenario.model
    materials: dict[str, dict] = {}
    objects: list[dict] = []
    if target:
        for i, part in enumerate(model.parts):
            materials[f"part{i}"] = _material(part.colour, part.roughness)
            smooth = part.ellipsoid is not None
            objects.append({"name": f"part{i}", "parent": "target", "material": f"part{i}",
                            **from_mesh(part.mesh(), smooth).to_json()})
        for name, bgr in model.palette.items():
            discs = [mark_disc(p, n, model.mark_radius) for p, n, c in
                     zip(model.mark_points, model.mark_normals, model.mark_colours) if c == name]
            if not discs:
                continue
            materials[f"mark-{name}"] = _material(bgr, model.mark_roughness)
            objects.append({"name": f"marks-{name}", "parent": "target", "material": f"mark-{name}",
                            **join(discs).to_json()})
    for i, occ in enumerate(render.occluders):
        materials[f"occluder{i}"] = _material(occ.colour, OCCLUDER_ROUGHNESS)
        box = from_mesh(box_mesh([0.0, 0.0, 0.0], occ.size, (0, 0, 0)))
        objects.append({"name": f"occluder{i}", "parent": "mover", "material": f"occluder{i}", **box.to_json()})
    for i, item in enumerate(render.clutter):
        materials[f"clutter{i}"] = _material(item.colour, item.roughness)
        objects.append({"name": f"clutter{i}", "parent": None, "material": f"clutter{i}",
                        **clutter_solid(item).to_json()})
    ground = write_ground_texture(scenario, Path(work_dir) / "ground.png")
    materials["ground"] = _material(render.ground.colour, GROUND_ROUGHNESS, **ground)
    sun = np.asarray(light.sun, float)
    if np.linalg.norm(sun) < 1e-9:
        raise ScenarioError(f"{scenario.path or scenario.name}: render.lighting.sun: a zero vector has no direction")
    sun = sun / np.linalg.norm(sun)
    names = cameras if cameras is not None else [v.name for v in scenario.vehicles]
    return {
        "format": FORMAT,
        "world": scenario.name,
        "engine": {**ENGINE_DEFAULTS, **(engine or {})},
        "materials": materials,
        "objects": objects,
        "ground": {"half_size": GROUND_HALF_SIZE, "material": "ground"},
        "lighting": {"sky": light.sky, "sun_direction": sun.round(9).tolist(), "sun_strength": light.sun_strength,
                     "sun_angle": SUN_ANGLE, "sky_strength": light.sky_strength,
                     "sun_elevation": math.asin(float(np.clip(sun[2], -1, 1))),
                     "sun_azimuth": math.atan2(sun[1], sun[0])},
        "cameras": {n: blender_camera(scenario.vehicle(n).camera.intrinsics, n) for n in names},
    }


def render_seed(scenario: Scenario, frame: int, vehicle_index: int) -> int:
    """Cycles' sampling seed of one image: fixed per world, frame and camera (reproducible renders)."""
    return (scenario.seed * 1_000_003 + frame * 101 + vehicle_index) % (2**31 - 1)


def describe_frame(scenario: Scenario, frame: int, renders: dict[str, Path], *, target: bool = True) -> dict:
    """One frame: the target's and the moving occluders' matrices, and the images to render (camera -> EXR path)."""
    t = scenario.time(frame)
    movers = {f"occluder{i}": _translation(np.asarray(o.centre) + t * np.asarray(o.velocity))
              for i, o in enumerate(scenario.render.occluders)}
    jobs = []
    for name, path in renders.items():
        veh = scenario.vehicle(name)
        jobs.append({"camera": name, "matrix": _rows(blender_matrix(veh.world_from_camera(t))),
                     "path": str(path), "seed": render_seed(scenario, frame, veh.index)})
    return {"frame": frame, "time": t,
            "target": _rows(matrix_from_pose(scenario.target_pose(frame))) if target else None,
            "movers": {k: _rows(v) for k, v in movers.items()}, "renders": jobs}


def _translation(p) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = p
    return T


def _rows(T: np.ndarray) -> list[list[float]]:
    return np.round(np.asarray(T, float), 10).tolist()
