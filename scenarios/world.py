"""Scenario files: the target, the vehicles with their camera rigs and sensors, the renderer settings.

A scenario (YAML) is validated strictly: an unknown key, a wrong type or a bad value is a
:class:`~scenarios.errors.ScenarioError` whose one-line message names the file and the field.
The world frame is z up with the ground at ``z = 0`` (metres, radians, seconds).

```yaml
name: exp2
seed: 7                       # every random process derives from it (and the frame index)
fps: 10
frames: 50
target:
  name: pioneer
  model: models/pioneer.yaml  # relative to this file, or a shipped model name
  trajectory: {start: {x: 0, y: 0, z: 0, roll: 0, pitch: 0, yaw: 0.6}}
  sensors: {imu: {bias_sigma_deg: 0.7, noise_sigma_deg: 0.1}}   # optional
vehicles:
  - name: H1
    role: uav                 # optional: uav, ground-station, airship, target
    trajectory: {start: {...}, rate: {...}, sway: {...}, period: 5}
    camera:
      intrinsics: {fx: 8000, fy: 8000, cx: 640, cy: 480, width: 1280, height: 960, distortion: [...]}
      mount: {x: 0, y: 0, z: -0.2, roll: -1.5708, pitch: 0, yaw: -1.5708}  # vehicle_from_camera
      look_at: [0, 0, 0.1]    # optional gimbal: the camera points at this world point (or: target)
      degraded: {blur_sigma: 3, occluded_fraction: 0.4, distractors: 6}   # optional: a bad camera
render: {noise_sigma: 2, blur_sigma: 0.7, distractors: {count: 4}, occluders: [...]}
search: {x: [-3, 3], y: [-3, 3], z: [-0.2, 0.5]}   # the operating area, for solving
```
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, model_validator

from evopose import Bounds, Camera
from geometry import PARAM_NAMES, matrix_from_pose

from .camera_model import CameraModelSpec
from .clutter_spec import ClutterSpec
from .documents import Strict, validate
from .errors import FrameError, ModelFileError, ScenarioError
from .extends import read_world_document
from .sensors import GpsModel, ImuModel
from .target import TargetModel, load_model, resolve_model_path
from .trajectory import Trajectory, look_at_rotation

#: Directory of the shipped scenarios (``exp1-airship.yaml``, ``exp2.yaml``).
SCENARIOS_DIR = Path(__file__).resolve().parent
#: Optical frame of a camera looking along the vehicle's +x (x forward, y left, z up): vehicle_from_camera angles.
FORWARD_MOUNT = {"x": 0.0, "y": 0.0, "z": 0.0, "roll": -math.pi / 2, "pitch": 0.0, "yaw": -math.pi / 2}

Role = Literal["uav", "ground-station", "airship", "target"]
Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]
BGR = Annotated[list[Annotated[int, Field(ge=0, le=255)]], Field(min_length=3, max_length=3)]
Range = Annotated[list[float], Field(min_length=2, max_length=2)]


class PoseSpec(Strict):
    """``(x, y, z, roll, pitch, yaw)``, metres and radians; omitted values are 0."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0

    def vector(self) -> np.ndarray:
        return np.array([getattr(self, n) for n in PARAM_NAMES], float)


class DriveSpec(Strict):
    """A ground vehicle driving forward along its heading at ``speed`` (m/s) while turning at ``turn_rate`` (rad/s)."""

    speed: Annotated[float, Field(ge=0, le=50)]
    turn_rate: Annotated[float, Field(ge=-3, le=3)] = 0.0


class TrajectorySpec(Strict):
    start: PoseSpec
    rate: PoseSpec = PoseSpec()
    sway: PoseSpec = PoseSpec()
    period: Annotated[float, Field(gt=0)] = 4.0
    drive: DriveSpec | None = None

    def build(self) -> Trajectory:
        speed, turn = (0.0, 0.0) if self.drive is None else (self.drive.speed, self.drive.turn_rate)
        return Trajectory(self.start.vector(), self.rate.vector(), self.sway.vector(), self.period,
                          speed=speed, turn_rate=turn)


class ImuSpec(Strict):
    bias_sigma_deg: Annotated[float, Field(ge=0)] = 0.7
    noise_sigma_deg: Annotated[float, Field(ge=0)] = 0.1

    def build(self) -> ImuModel:
        return ImuModel(math.radians(self.bias_sigma_deg), math.radians(self.noise_sigma_deg))


class DegradedSpec(Strict):
    start: float
    end: float
    factor: Annotated[float, Field(ge=1)]


class GpsSpec(Strict):
    noise_sigma: Annotated[float, Field(ge=0)] = 1.5
    degraded: list[DegradedSpec] = []
    outages: list[Range] = []

    def build(self) -> GpsModel:
        return GpsModel(self.noise_sigma, tuple((d.start, d.end, d.factor) for d in self.degraded),
                        tuple((a, b) for a, b in self.outages))


class SensorsSpec(Strict):
    imu: ImuSpec | None = None
    gps: GpsSpec | None = None


class IntrinsicsSpec(Strict):
    fx: Annotated[float, Field(gt=0)]
    fy: Annotated[float, Field(gt=0)]
    cx: float
    cy: float
    width: Annotated[int, Field(gt=0, le=8192)]
    height: Annotated[int, Field(gt=0, le=8192)]
    distortion: Annotated[list[float], Field(min_length=5, max_length=5)] = [0.0] * 5


class DegradedCameraSpec(Strict):
    """A degraded camera (:mod:`scenarios.degrade`): heavy blur, an occluder over part of the target, distractors."""

    blur_sigma: Annotated[float, Field(ge=0, le=50)] = 0.0
    occluded_fraction: Annotated[float, Field(ge=0, le=1)] = 0.0
    distractors: Annotated[int, Field(ge=0, le=200)] = 0


class CameraRigSpec(Strict):
    intrinsics: IntrinsicsSpec
    mount: PoseSpec = PoseSpec(**FORWARD_MOUNT)
    look_at: Vec3 | Literal["target"] | None = None
    degraded: DegradedCameraSpec | None = None


class TargetSpec(Strict):
    name: str = "target"
    role: Role | None = None
    model: str
    trajectory: TrajectorySpec
    sensors: SensorsSpec = SensorsSpec()


class VehicleSpec(Strict):
    name: Annotated[str, Field(min_length=1)]
    role: Role | None = None
    trajectory: TrajectorySpec
    camera: CameraRigSpec
    sensors: SensorsSpec = SensorsSpec()


class DistractorSpec(Strict):
    """Blobs in the target's mark colours drawn in the image (false positives for the detector)."""

    count: Annotated[int, Field(ge=0, le=200)] = 0
    radius_px: Range = [3.0, 10.0]
    near_target: Annotated[float, Field(ge=0, le=1)] = 0.7


class OccluderSpec(Strict):
    """A box in the world (a pole, a crate, a passing vehicle) that hides what is behind it."""

    centre: Vec3
    size: Annotated[list[Annotated[float, Field(gt=0)]], Field(min_length=3, max_length=3)]
    colour: BGR = [90, 110, 120]
    velocity: Vec3 = [0.0, 0.0, 0.0]


class LightingSpec(Strict):
    gain: Annotated[float, Field(gt=0)] = 1.0
    gain_amplitude: Annotated[float, Field(ge=0, lt=1)] = 0.0
    gain_period: Annotated[float, Field(gt=0)] = 10.0
    gain_jitter: Annotated[float, Field(ge=0, lt=1)] = 0.0
    ambient: Annotated[float, Field(ge=0, le=1)] = 0.55
    sun: Vec3 = [0.3, 0.4, 1.0]
    #: With a camera model, the OpenCV renderer's Blinn-Phong sun highlight on paint (strength, exponent).
    specular: Annotated[float, Field(ge=0, le=10)] = 0.25
    shininess: Annotated[float, Field(ge=1, le=10000)] = 60.0
    #: Photoreal renderer: the sun's irradiance (W/m^2), a clear sky (the sun at ``sun``) or overcast (no sun).
    sun_strength: Annotated[float, Field(ge=0, le=100)] = 4.0
    sky: Literal["clear", "overcast"] = "clear"
    sky_strength: Annotated[float, Field(ge=0, le=100)] = 1.0


class GroundSpec(Strict):
    colour: BGR = [95, 110, 120]
    contrast: Annotated[float, Field(ge=0, le=127)] = 25.0
    texel: Annotated[float, Field(gt=0)] = 0.01
    sky: BGR = [215, 195, 175]


class RenderSpec(Strict):
    noise_sigma: Annotated[float, Field(ge=0)] = 0.0
    blur_sigma: Annotated[float, Field(ge=0)] = 0.0
    lighting: LightingSpec = LightingSpec()
    ground: GroundSpec = GroundSpec()
    distractors: DistractorSpec = DistractorSpec()
    occluders: list[OccluderSpec] = []
    clutter: Annotated[list[ClutterSpec], Field(max_length=200)] = []
    #: Sensor, processing and encoder (:mod:`scenarios.camera_model`); None: plain gain and Gaussian noise.
    camera_model: CameraModelSpec | None = None


class SearchSpec(Strict):
    x: Range
    y: Range
    z: Range
    roll: Range = [-math.pi, math.pi]
    pitch: Range = [-math.pi, math.pi]
    yaw: Range = [-math.pi, math.pi]

    @model_validator(mode="after")
    def _ordered(self) -> "SearchSpec":
        for name in PARAM_NAMES:
            lo, hi = getattr(self, name)
            if lo > hi:
                raise ValueError(f"{name}: lo {lo} > hi {hi}")
        return self

    def bounds(self) -> Bounds:
        return Bounds.from_dict({n: tuple(getattr(self, n)) for n in PARAM_NAMES})


class ScenarioSpec(Strict):
    name: str
    description: str = ""
    seed: Annotated[int, Field(ge=0)] = 0
    fps: Annotated[float, Field(gt=0)] = 10.0
    frames: Annotated[int, Field(ge=1)] = 1
    target: TargetSpec
    vehicles: Annotated[list[VehicleSpec], Field(min_length=1)]
    render: RenderSpec = RenderSpec()
    search: SearchSpec | None = None

    @model_validator(mode="after")
    def _unique_names(self) -> "ScenarioSpec":
        names = [self.target.name] + [v.name for v in self.vehicles]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ValueError(f"vehicle names must be unique (and differ from the target's); repeated: {sorted(dup)}")
        return self


@dataclass(frozen=True, eq=False)
class Vehicle:
    """A camera-carrying vehicle of a scenario."""

    index: int
    name: str
    role: str | None
    trajectory: Trajectory
    camera: CameraRigSpec
    imu: ImuModel | None
    gps: GpsModel | None
    #: The target's motion, for a gimbal that follows the target (``look_at: target``).
    target_trajectory: Trajectory | None = None

    def world_from_camera(self, t: float) -> np.ndarray:
        """Camera extrinsic at time ``t``, shape (4, 4): the vehicle pose, the mount, the gimbal."""
        world_from_camera = self.trajectory.matrix(t) @ matrix_from_pose(self.camera.mount.vector())
        look_at = self.camera.look_at
        if look_at == "target":
            look_at = self.target_trajectory.pose(t)[:3]
        if look_at is not None:
            world_from_camera[:3, :3] = look_at_rotation(world_from_camera[:3, 3], look_at)
        return world_from_camera

    def camera_at(self, t: float) -> Camera:
        k = self.camera.intrinsics
        return Camera(k.fx, k.fy, k.cx, k.cy, k.width, k.height, np.array(k.distortion), self.world_from_camera(t))


@dataclass(frozen=True, eq=False)
class Scenario:
    """A loaded scenario: the target model and motion, the vehicles, the renderer settings."""

    spec: ScenarioSpec
    model: TargetModel
    target_trajectory: Trajectory
    vehicles: tuple[Vehicle, ...]
    path: Path | None = None

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def seed(self) -> int:
        return self.spec.seed

    @property
    def frames(self) -> int:
        return self.spec.frames

    @property
    def render(self) -> RenderSpec:
        return self.spec.render

    def time(self, frame: int) -> float:
        """Seconds at ``frame`` (checked against the scenario's frame count)."""
        self.check_frame(frame)
        return frame / self.spec.fps

    def check_frame(self, frame: int) -> None:
        if not 0 <= frame < self.spec.frames:
            raise FrameError(f"frame {frame} out of range: scenario {self.name!r} has frames 0..{self.spec.frames - 1}")

    def vehicle(self, name: str | None = None) -> Vehicle:
        """The vehicle called ``name`` (the first one when None)."""
        if name is None:
            return self.vehicles[0]
        for v in self.vehicles:
            if v.name == name:
                return v
        raise FrameError(f"no vehicle {name!r} in scenario {self.name!r} (vehicles: "
                         f"{', '.join(v.name for v in self.vehicles)})")

    def target_pose(self, frame: int) -> np.ndarray:
        """``world_from_target`` at ``frame`` as ``(x, y, z, roll, pitch, yaw)``, shape (6,)."""
        return self.target_trajectory.pose(self.time(frame))

    def camera(self, vehicle: str | None, frame: int) -> Camera:
        """The calibrated camera of ``vehicle`` at ``frame``, with its ``world_from_camera``."""
        return self.vehicle(vehicle).camera_at(self.time(frame))

    @property
    def target_imu(self) -> ImuModel | None:
        imu = self.spec.target.sensors.imu
        return None if imu is None else imu.build()

    @property
    def target_gps(self) -> GpsModel | None:
        gps = self.spec.target.sensors.gps
        return None if gps is None else gps.build()

    def bounds(self) -> Bounds:
        """The search box of the scenario's ``search`` block."""
        if self.spec.search is None:
            raise ScenarioError(f"scenario {self.name!r} has no search block (the operating area for solving)")
        return self.spec.search.bounds()


def build_scenario(spec: ScenarioSpec, base: Path | None = None, path: Path | None = None) -> Scenario:
    """The runtime scenario of a validated spec; the model path is resolved against ``base``."""
    try:
        model = load_model(resolve_model_path(spec.target.model, base))
    except ModelFileError as err:
        raise ScenarioError(f"{path or spec.name}: target.model: {err}") from None
    target = spec.target.trajectory.build()
    vehicles = tuple(
        Vehicle(i, v.name, v.role, v.trajectory.build(), v.camera,
                v.sensors.imu.build() if v.sensors.imu else None, v.sensors.gps.build() if v.sensors.gps else None,
                target)
        for i, v in enumerate(spec.vehicles))
    return Scenario(spec, model, target, vehicles, path)


def resolve_scenario_path(name_or_path: str | Path) -> Path:
    """A path, or the name of a shipped scenario (``exp2`` -> ``scenarios/exp2.yaml``)."""
    p = Path(name_or_path)
    if p.exists() or p.suffix:
        return p
    shipped = SCENARIOS_DIR / f"{p.name}.yaml"
    return shipped if shipped.exists() else p


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario file (or a shipped scenario by name); ``extends`` takes another world as a base.

    Raises
    ------
    ScenarioError
        One line naming the file and the offending field.
    """
    path = resolve_scenario_path(path)
    document = read_world_document(path)
    spec = validate(ScenarioSpec, document, path, ScenarioError)
    return build_scenario(spec, path.parent, path)
