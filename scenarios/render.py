"""The renderer: what a vehicle's camera sees at a frame, with its exact ground truth.

OpenCV drawing, no per-pixel Python loops:

1. sky, and a seeded procedural ground texture warped onto the ground plane ``z = 0`` by its homography
   (:mod:`scenarios.ground`);
2. the target's body and the occluders as flat-shaded convex faces, back faces culled, far to near
   (painter's algorithm), projected through the camera's plumb_bob distortion;
3. the marks as discs on the body (their outline projected, so perspective shapes them), only where
   the mark's centre faces the camera and no face hides it; faces that hide part of a mark are drawn again over it;
4. distractor blobs in the mark colours (false positives), then blur, a lighting gain and sensor noise
   (:mod:`scenarios.sensor_noise`);
5. for a degraded camera (:mod:`scenarios.degrade`): an occluding band over part of the target, more distractors,
   heavier blur.

With a camera model (``render.camera_model``, :mod:`scenarios.camera_model`) the scene is drawn in linear light
(float32, the palette's sRGB colours made linear): faces and marks lit by the sun (ambient + Lambert diffuse + a
Blinn-Phong highlight towards the camera), polygons anti-aliased by coverage in linear light; blur and the
lighting gain act on the light, and the camera model's ``capture`` replaces the plain gain and Gaussian noise
(its own seeded stream, :data:`STREAM_CAMERA`). Without one, the 8-bit path above is unchanged.
The world's clutter objects (:mod:`scenarios.clutter`) are drawn like the body in either path and hide marks.

Ground truth: the target pose, the camera pose and, for every mark whose centre is visible, its model
index and its projected centre in pixels (``fully_visible`` tells whether its whole disc is).
Every random draw of frame N comes from a generator seeded by ``(scenario seed, vehicle, N)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from evopose import Camera
from geometry import matrix_from_pose, pose_from_matrix

from .camera_model import capture, linear_from_srgb, srgb_from_linear
from .clutter import clutter_mesh
from .degrade import (OCCLUDER_COLOUR, STREAM_DEGRADED, composed_blur, draw_band, inside_band, occluder_band,
                      target_box)
from .ground import ground_and_sky
from .mesh import Mesh, box_mesh, first_hits, hits
from .sensor_noise import gain_and_noise
from .sensors import stream_rng
from .shading import SHIFT, ellipse_linear, fill_linear, lit_linear  # SHIFT: fixed-point bits of drawing (1/16 px)
from .world import LightingSpec, RenderSpec, Scenario, Vehicle

#: Points per mark outline (its projected polygon, and the samples of the partial-visibility test).
MARK_OUTLINE = 24
#: Occlusion rays end this far (metres) above a mark, so the mark's own face never hides it.
MARK_LIFT = 0.003
#: Faces with a vertex nearer than this (metres, optical axis) are not drawn.
NEAR_CLIP = 0.05
#: A mark seen more obliquely than this (cosine between its normal and the line of sight) is a sliver,
#: not a disc: it does not count as visible in the ground truth.
MIN_FACING_COS = 0.2
#: Stream numbers of the scenario's random processes (see :func:`scenarios.sensors.stream_rng`).
STREAM_FRAME = 202
#: Stream of the camera model's sensor noise (a frame's noise does not depend on how many blobs were drawn).
STREAM_CAMERA = 404


@dataclass
class FrameTruth:
    """Exact ground truth of one rendered frame.

    Attributes
    ----------
    target_pose : array, shape (6,)
        ``world_from_target``.
    camera_pose : array, shape (6,)
        ``world_from_camera`` (optical frame).
    vehicle_pose : array, shape (6,)
        ``world_from_vehicle``.
    mark_index : int array, shape (K,)
        Model index of each visible mark.
    mark_uv : array, shape (K, 2)
        Projected centres, pixels.
    mark_colour : list of str, length K
    fully_visible : bool array, shape (K,)
        Whether the whole disc is visible (not cut by a face, an occluder or the image border).
    distractor_uv : array, shape (D, 2)
    distractor_colour : list of str
    sensors : dict
        Readings of the target's sensors at this frame (``imu_rpy`` radians, ``gps_xyz`` metres or None).
    """

    scenario: str
    frame: int
    time: float
    vehicle: str
    target_pose: np.ndarray
    camera_pose: np.ndarray
    vehicle_pose: np.ndarray
    mark_index: np.ndarray
    mark_uv: np.ndarray
    mark_colour: list[str]
    fully_visible: np.ndarray
    distractor_uv: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    distractor_colour: list[str] = field(default_factory=list)
    sensors: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """JSON-ready mapping (lists of floats; angles radians, lengths metres, pixels)."""
        names = ("x", "y", "z", "roll", "pitch", "yaw")
        pose = lambda s: {n: float(v) for n, v in zip(names, s)}  # noqa: E731
        return {
            "scenario": self.scenario, "frame": self.frame, "time": self.time, "vehicle": self.vehicle,
            "target_pose": pose(self.target_pose), "camera_pose": pose(self.camera_pose),
            "vehicle_pose": pose(self.vehicle_pose),
            "marks": [{"index": int(i), "uv": [float(u), float(v)], "colour": c, "fully_visible": bool(f)}
                      for i, (u, v), c, f in zip(self.mark_index, self.mark_uv, self.mark_colour, self.fully_visible)],
            "distractors": [{"uv": [float(u), float(v)], "colour": c}
                            for (u, v), c in zip(self.distractor_uv, self.distractor_colour)],
            "sensors": {k: (None if v is None else np.asarray(v, float).tolist()) for k, v in self.sensors.items()},
        }


@dataclass
class RenderedFrame:
    """A camera image (BGR uint8, shape (H, W, 3)), the camera that took it and its ground truth."""

    image: np.ndarray
    camera: Camera
    truth: FrameTruth


def _face_shades(normals_cam: np.ndarray, sun_cam: np.ndarray, ambient: float) -> np.ndarray:
    return ambient + (1 - ambient) * np.clip(normals_cam @ sun_cam, 0, 1)


#: The occluders and clutter of worlds whose occluders stand still, by their specification (a few worlds a process).
_STILL_OCCLUDERS: dict[str, Mesh] = {}


def _occluder_mesh(render: RenderSpec, t: float) -> Mesh:
    """The world's occluders at time ``t`` and its clutter, one mesh; built once while no occluder moves."""
    if any(np.any(occ.velocity) for occ in render.occluders):
        return _occluders_at(render, t)
    key = render.model_dump_json(include={"occluders", "clutter"})
    if key not in _STILL_OCCLUDERS:
        if len(_STILL_OCCLUDERS) >= 8:
            _STILL_OCCLUDERS.clear()
        _STILL_OCCLUDERS[key] = _occluders_at(render, 0.0)
    return _STILL_OCCLUDERS[key]


def _occluders_at(render: RenderSpec, t: float) -> Mesh:
    mesh = Mesh.empty()
    for occ in render.occluders:
        centre = np.asarray(occ.centre) + t * np.asarray(occ.velocity)
        mesh = mesh + box_mesh(centre, occ.size, tuple(occ.colour))
    if render.clutter:
        mesh = mesh + clutter_mesh(render.clutter)
    return mesh


class _SceneFaces:
    """The faces of one frame in the camera frame: culled, shaded, sorted far to near, projected."""

    def __init__(self, mesh: Mesh, camera: Camera, sun_world: np.ndarray, ambient: float,
                 light: LightingSpec | None = None) -> None:
        R, t = camera.camera_from_world[:3, :3], camera.camera_from_world[:3, 3]
        v_cam = mesh.vertices @ R.T + t
        self.uv, _ = camera.project_camera_points(v_cam)
        normals = mesh.normals @ R.T
        centres = np.array([v_cam[f].mean(axis=0) for f in mesh.faces]).reshape(-1, 3)
        facing = np.sum(normals * centres, axis=1) < 0
        normals = np.where(facing[:, None], normals, -normals)  # two-sided faces lit from the seen side
        near_ok = np.array([v_cam[f, 2].min() > NEAR_CLIP for f in mesh.faces], bool)
        keep = near_ok & (facing | mesh.two_sided)
        sun_cam = R @ (sun_world / np.linalg.norm(sun_world))
        shades = _face_shades(normals, sun_cam, ambient)
        self.mesh = mesh
        self.visible = np.nonzero(keep)[0]
        self.order = self.visible[np.argsort(-centres[self.visible, 2], kind="stable")]
        self.colours = mesh.colours * shades[:, None]
        if light is not None:  # linear light, with the highlight
            self.colours = lit_linear(mesh.colours, normals, centres, sun_cam, light)
        # triangles that can hide something: the kept faces (seen from the camera)
        tris, owner = [], []
        for i in self.visible:
            f = mesh.faces[i]
            for k in range(1, len(f) - 1):
                tris.append(mesh.vertices[[f[0], f[k], f[k + 1]]])
                owner.append(i)
        self.triangles = np.array(tris).reshape(-1, 3, 3)
        self.triangle_face = np.array(owner, int)

    def draw(self, image: np.ndarray, faces) -> None:
        for i in faces:
            pts = np.round(self.uv[self.mesh.faces[i]] * (1 << SHIFT)).astype(np.int32)
            if np.abs(pts).max() > (1 << 28):
                continue
            if image.dtype == np.uint8:
                cv2.fillConvexPoly(image, pts, tuple(float(c) for c in self.colours[i]), cv2.LINE_AA, SHIFT)
            else:
                fill_linear(image, pts, self.colours[i])


def mark_outlines(points: np.ndarray, normals: np.ndarray, radius: float) -> np.ndarray:
    """Disc outlines of the marks (target frame), shape (M, MARK_OUTLINE, 3)."""
    helper = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    e1 = np.cross(normals, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(normals, e1)
    a = np.linspace(0, 2 * np.pi, MARK_OUTLINE, endpoint=False)
    return (points[:, None, :] + radius * (np.cos(a)[None, :, None] * e1[:, None, :]
                                           + np.sin(a)[None, :, None] * e2[:, None, :]))


def _draw_distractors(image: np.ndarray, rng: np.random.Generator, render: RenderSpec, palette: dict,
                      marks_uv: np.ndarray, shade: float) -> tuple[np.ndarray, list[str]]:
    """Blobs in the palette's colours, lit by ``shade`` (in linear light for a float ``image``)."""
    spec = render.distractors
    h, w = image.shape[:2]
    if spec.count == 0:
        return np.zeros((0, 2)), []
    names = list(palette)
    if len(marks_uv):
        lo, hi = marks_uv.min(axis=0), marks_uv.max(axis=0)
        span = np.maximum(hi - lo, 40.0)
        lo, hi = np.maximum(lo - span, 0), np.minimum(hi + span, [w - 1, h - 1])
    else:
        lo, hi = np.zeros(2), np.array([w - 1.0, h - 1.0])
    uv_out, colours = [], []
    r_lo, r_hi = sorted(spec.radius_px)
    for _ in range(spec.count):
        for _attempt in range(20):
            near = rng.random() < spec.near_target
            uv = rng.uniform(lo, hi) if near else rng.uniform([0, 0], [w - 1, h - 1])
            r = rng.uniform(r_lo, r_hi)
            clear = len(marks_uv) == 0 or np.min(np.linalg.norm(marks_uv - uv, axis=1)) > 2.5 * r + 6
            if clear:
                break
        else:
            continue
        name = names[int(rng.integers(len(names)))]
        axes = (r * (1 << SHIFT), r * rng.uniform(0.5, 1.0) * (1 << SHIFT))
        centre = tuple(int(round(c * (1 << SHIFT))) for c in uv)
        if image.dtype == np.uint8:
            colour = tuple(float(c) * shade for c in palette[name])
            cv2.ellipse(image, centre, tuple(int(a) for a in axes), float(rng.uniform(0, 180)), 0, 360, colour,
                        -1, cv2.LINE_AA, SHIFT)
        else:
            ellipse_linear(image, uv, r, centre, tuple(int(a) for a in axes), float(rng.uniform(0, 180)),
                            linear_from_srgb(np.asarray(palette[name], float)) * shade)
        uv_out.append(uv)
        colours.append(name)
    return np.array(uv_out).reshape(-1, 2), colours


def render_frame(scenario: Scenario, frame: int, vehicle: str | None = None, *, clean: bool = False) -> RenderedFrame:
    """Render what ``vehicle`` (default: the first) sees at ``frame``.

    Parameters
    ----------
    clean : bool
        Leave out every nuisance (noise, blur, lighting changes, distractors, occluders, clutter): the
        geometry only, for checking the feature extraction against the truth. With a camera model, the
        linear scene is only sRGB-encoded (a perfect camera: no exposure, sensor or encoder).

    Raises
    ------
    FrameError
        The frame or the vehicle is not in the scenario.
    """
    t = scenario.time(frame)
    veh: Vehicle = scenario.vehicle(vehicle)
    camera = veh.camera_at(t)
    render = scenario.render
    light = render.lighting
    rng = stream_rng(scenario.seed, STREAM_FRAME, veh.index, frame)
    gain = 1.0 if clean else light.gain * (1 + light.gain_amplitude * np.sin(2 * np.pi * t / light.gain_period)
                                           + light.gain_jitter * rng.standard_normal())
    sun = np.asarray(light.sun, float)
    ground_shade = light.ambient + (1 - light.ambient) * max(sun[2] / np.linalg.norm(sun), 0)
    linear = render.camera_model is not None
    image = ground_and_sky(camera, render.ground, scenario.seed, ground_shade, linear)

    model = scenario.model
    world_from_target = matrix_from_pose(scenario.target_pose(frame))
    mesh = model.body.transformed(world_from_target)
    if not clean:
        mesh = mesh + _occluder_mesh(render, t)
    faces = _SceneFaces(mesh, camera, sun, light.ambient, light if linear else None)
    faces.draw(image, faces.order)

    # marks: centre and outline in the world, visibility by normal, image bounds and occlusion rays
    R, p = world_from_target[:3, :3], world_from_target[:3, 3]
    normals_w = model.mark_normals @ R.T
    centres_w = model.mark_points @ R.T + p
    outlines_w = mark_outlines(centres_w, normals_w, model.mark_radius)
    eye = camera.center_world
    sight = eye - centres_w
    facing = np.sum(normals_w * sight, axis=1) > MIN_FACING_COS * np.linalg.norm(sight, axis=1)
    uv_c, in_front = camera.project_world(centres_w)
    uv_o, front_o = camera.project_world(outlines_w.reshape(-1, 3))
    uv_o = uv_o.reshape(len(centres_w), MARK_OUTLINE, 2)
    candidates = np.nonzero(facing & in_front & camera.in_image(uv_c))[0]
    # occlusion rays end a little above the surface, so the mark's own face never blocks them
    lift = MARK_LIFT * normals_w[candidates, None, :]
    samples = np.concatenate([centres_w[candidates, None, :], outlines_w[candidates]], axis=1) + lift
    if len(candidates):
        blocked = first_hits(eye, samples.reshape(-1, 3), faces.triangles).reshape(len(candidates), -1)
    else:  # no mark in view (a camera looking away): nothing to test
        blocked = np.zeros((0, 1 + MARK_OUTLINE), bool)
    shown = candidates[~blocked[:, 0]]
    whole = ~blocked[~blocked[:, 0]].any(axis=1)
    whole &= np.all(camera.in_image(uv_o[shown], margin=-0.5), axis=1) & front_o.reshape(-1, MARK_OUTLINE)[shown].all(1)
    R_cw = camera.camera_from_world[:3, :3]
    mark_shades = _face_shades(normals_w[shown] @ R_cw.T, R_cw @ (sun / np.linalg.norm(sun)), light.ambient)
    if linear:
        mark_radiance = lit_linear(np.array([model.palette[model.mark_colours[i]] for i in shown]).reshape(-1, 3),
                                    normals_w[shown] @ R_cw.T, centres_w[shown] @ R_cw.T + camera.camera_from_world[:3, 3],
                                    R_cw @ (sun / np.linalg.norm(sun)), light)
    for k, i in enumerate(shown):
        pts = np.round(uv_o[i] * (1 << SHIFT)).astype(np.int32)
        if linear:
            fill_linear(image, pts, mark_radiance[k])
            continue
        colour = tuple(float(c) * mark_shades[k] for c in model.palette[model.mark_colours[i]])
        cv2.fillConvexPoly(image, pts, colour, cv2.LINE_AA, SHIFT)
    # faces hiding part of a drawn mark go over it again
    partial = candidates[~blocked[:, 0]][~whole] if len(shown) else np.zeros(0, int)
    if len(partial) and len(faces.triangles):
        lifted = outlines_w[partial] + MARK_LIFT * normals_w[partial, None, :]
        crossed = hits(eye, lifted.reshape(-1, 3), faces.triangles).any(axis=0)
        hiders = set(faces.triangle_face[crossed].tolist())
        faces.draw(image, [f for f in faces.order if f in hiders])

    degraded = None if clean else veh.camera.degraded
    if degraded is not None and degraded.occluded_fraction > 0:
        box = target_box(camera, model.body.transformed(world_from_target).vertices)
        if box is not None:
            band = occluder_band(box, degraded.occluded_fraction)
            if linear:  # the band's paint, lit like the ground
                u0, v0, u1, v1 = (int(round(c)) for c in band)
                cv2.rectangle(image, (u0, v0), (u1, v1),
                              tuple(float(c) for c in linear_from_srgb(np.asarray(OCCLUDER_COLOUR, float))
                                    * ground_shade), -1)
            else:
                draw_band(image, band)
            behind = inside_band(uv_c[shown], band)
            whole = whole[~behind] & ~inside_band(uv_o[shown[~behind]], band).any(axis=1)
            shown = shown[~behind]

    distractor_uv, distractor_colour = np.zeros((0, 2)), []
    if not clean:
        distractor_uv, distractor_colour = _draw_distractors(image, rng, render, model.palette, uv_c[shown],
                                                             ground_shade)
        blur = render.blur_sigma
        if degraded is not None:
            extra = render.model_copy(update={"distractors": render.distractors.model_copy(
                update={"count": degraded.distractors, "near_target": 1.0})})
            more_uv, more_colour = _draw_distractors(image, stream_rng(scenario.seed, STREAM_DEGRADED, veh.index, frame),
                                                     extra, model.palette, uv_c[shown], ground_shade)
            distractor_uv, distractor_colour = np.concatenate([distractor_uv, more_uv]), distractor_colour + more_colour
            blur = composed_blur(blur, degraded.blur_sigma)
        if blur > 0:
            image = cv2.GaussianBlur(image, (0, 0), blur)
        if linear:  # the lighting's gain is on the light; the camera model's sensor replaces the Gaussian noise
            if gain != 1.0:
                image *= np.float32(gain)
            image = capture(image, render.camera_model, stream_rng(scenario.seed, STREAM_CAMERA, veh.index, frame)).image
        elif gain != 1.0 or render.noise_sigma > 0:
            image = gain_and_noise(image, gain, render.noise_sigma, int(rng.integers(1, 2**31)))
    if linear and clean:
        image = srgb_from_linear(image)

    sensors = {}
    target_pose = scenario.target_pose(frame)
    if scenario.target_imu is not None:
        sensors["imu_rpy"] = scenario.target_imu.read(target_pose[3:], scenario.seed, 1000, frame)
    if scenario.target_gps is not None:
        sensors["gps_xyz"] = scenario.target_gps.read(target_pose[:3], t, scenario.seed, 1001, frame)
    for v in scenario.vehicles:
        pose_v = v.trajectory.pose(t)
        if v.imu is not None:
            sensors[f"{v.name}.imu_rpy"] = v.imu.read(pose_v[3:], scenario.seed, 2000 + v.index, frame)
        if v.gps is not None:
            sensors[f"{v.name}.gps_xyz"] = v.gps.read(pose_v[:3], t, scenario.seed, 3000 + v.index, frame)

    truth = FrameTruth(
        scenario.name, frame, t, veh.name, target_pose, pose_from_matrix(camera.world_from_camera),
        veh.trajectory.pose(t), shown.astype(int), uv_c[shown], [model.mark_colours[i] for i in shown], whole,
        distractor_uv, distractor_colour, sensors)
    return RenderedFrame(image, camera, truth)
