"""The fleet's messages as pydantic models: one class per topic, a common header (docs/design.md §4).

Units and frames follow docs/design.md §2: metres, radians, seconds, pixels; a pose is six numbers
``(x, y, z, roll, pitch, yaw)`` with ``R = Rz(yaw) Ry(pitch) Rx(roll)``; cameras use the OpenCV
optical frame. Models are built leniently from Python and validated strictly off the wire
(:func:`protocol.codec.decode`); unknown fields are ignored so that fields can be added without
a version bump (docs/protocol.md, "Versioning").
"""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal

import numpy as np
import geometry
from pydantic import BaseModel, ConfigDict, Field, computed_field, field_validator, model_validator

from .keys import Topic, check_name
from .limits import FEATURE_POINT_SIZE, MAX_FEATURE_POINTS

#: Version of the message schema; a receiver rejects any other (SchemaMismatch) but the previous one.
SCHEMA_VERSION = 3
#: The previous version, still decoded for one version (:func:`protocol.codec.upgraded`): docs/protocol.md §6.
PREVIOUS_SCHEMA_VERSION = 2

Float = Annotated[float, Field(allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Uint64 = Annotated[int, Field(ge=0, lt=2**64)]
#: ``(x, y, z, roll, pitch, yaw)``: metres, radians.
Pose6 = tuple[Float, Float, Float, Float, Float, Float]
ZERO_POSE: Pose6 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

JPEG_MAGIC = b"\xff\xd8\xff"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _name(value: str) -> str:
    return check_name(value, "name")


class Payload(BaseModel):
    """Anything sent on a data key; ``TOPIC`` says which."""

    model_config = ConfigDict(frozen=True, extra="ignore", allow_inf_nan=False)
    TOPIC: ClassVar[Topic]


class Message(Payload):
    """A msgpack message: the common header, then the topic's fields.

    Attributes
    ----------
    version : int
        Schema version, :data:`SCHEMA_VERSION`.
    sender : str
        Vehicle name; must equal the ``<vehicle>`` chunk of the key it was published on.
    seq : int
        Per sender and topic, +1 per message from 0; a jump tells the receiver how many were lost.
    stamp_ns : int
        Acquisition time, nanoseconds since the Unix epoch (UTC); data older than the receiver's
        ``max_age`` is ignored.
    """

    version: Literal[3] = SCHEMA_VERSION
    sender: str
    seq: Uint64
    stamp_ns: Annotated[int, Field(ge=0, lt=2**63)]

    _check_sender = field_validator("sender")(classmethod(lambda cls, v: _name(v)))


class CameraInfo(BaseModel):
    """A calibrated camera: pinhole intrinsics (pixels), plumb_bob distortion, extrinsic pose.

    ``world_from_camera`` is ``(x, y, z, roll, pitch, yaw)`` of the OpenCV optical frame
    (x right, y down, z forward) in the world frame; all zeros when the world is this camera's frame.
    """

    model_config = ConfigDict(frozen=True, extra="ignore", allow_inf_nan=False)

    fx: Annotated[float, Field(gt=0, allow_inf_nan=False)]
    fy: Annotated[float, Field(gt=0, allow_inf_nan=False)]
    cx: Float
    cy: Float
    width: Annotated[int, Field(gt=0, le=65535)]
    height: Annotated[int, Field(gt=0, le=65535)]
    distortion: tuple[Float, Float, Float, Float, Float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    world_from_camera: Pose6 = ZERO_POSE


class ImageFrame(Message):
    """One camera image.

    ``data`` holds, for ``encoding="raw"``, ``height * width * channels`` bytes of uint8 pixels,
    row-major, shape ``(height, width, channels)``, channels 1 (mono) or 3 (BGR, OpenCV order);
    for ``"jpeg"`` / ``"png"`` the compressed file's bytes.
    """

    TOPIC: ClassVar[Topic] = Topic.IMAGE

    camera: CameraInfo
    encoding: Literal["raw", "jpeg", "png"]
    width: Annotated[int, Field(gt=0, le=65535)]
    height: Annotated[int, Field(gt=0, le=65535)]
    channels: Literal[1, 3]
    data: bytes

    @model_validator(mode="after")
    def _consistent(self) -> "ImageFrame":
        if (self.width, self.height) != (self.camera.width, self.camera.height):
            raise ValueError(f"image is {self.width}x{self.height} but its camera is "
                             f"{self.camera.width}x{self.camera.height}")
        if self.encoding == "raw":
            expected = self.width * self.height * self.channels
            if len(self.data) != expected:
                raise ValueError(f"raw {self.width}x{self.height}x{self.channels} image needs {expected} bytes "
                                 f"of data, got {len(self.data)}")
        elif self.encoding == "jpeg" and not self.data.startswith(JPEG_MAGIC):
            raise ValueError("jpeg data does not start with the JPEG marker FF D8 FF")
        elif self.encoding == "png" and not self.data.startswith(PNG_MAGIC):
            raise ValueError("png data does not start with the PNG signature")
        return self

    @classmethod
    def from_array(cls, image: np.ndarray, camera: CameraInfo, *, sender: str, seq: int,
                   stamp_ns: int) -> "ImageFrame":
        """A raw frame from a uint8 array of shape ``(height, width)`` or ``(height, width, 3)`` (BGR)."""
        image = np.asarray(image)
        if image.dtype != np.uint8 or image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] != 3):
            raise ValueError(f"expected a uint8 image of shape (H, W) or (H, W, 3), got {image.dtype} {image.shape}")
        channels = 1 if image.ndim == 2 else 3
        return cls(sender=sender, seq=seq, stamp_ns=stamp_ns, camera=camera, encoding="raw",
                   width=image.shape[1], height=image.shape[0], channels=channels,
                   data=np.ascontiguousarray(image).tobytes())

    def to_array(self) -> np.ndarray:
        """The raw pixels, uint8 of shape ``(height, width)`` or ``(height, width, 3)``; raw frames only."""
        if self.encoding != "raw":
            raise ValueError(f"to_array needs a raw frame; decode {self.encoding} data with OpenCV (cv2.imdecode)")
        shape = (self.height, self.width) if self.channels == 1 else (self.height, self.width, 3)
        return np.frombuffer(self.data, dtype=np.uint8).reshape(shape)


def pack_points(points_uv: np.ndarray) -> bytes:
    """Pack image points, shape ``(N, 2)`` pixels, as ``N`` pairs of little-endian float32 ``(u, v)``."""
    points_uv = np.asarray(points_uv, dtype=float)
    if points_uv.ndim != 2 or points_uv.shape[1] != 2:
        raise ValueError(f"expected image points of shape (N, 2), got {points_uv.shape}")
    with np.errstate(over="ignore", invalid="ignore"):
        packed = points_uv.astype("<f4")
    if not np.all(np.isfinite(packed)):
        raise ValueError("image points must be finite float32 values")
    return packed.tobytes()


def unpack_points(data: bytes) -> np.ndarray:
    """Inverse of :func:`pack_points`: float32 array of shape ``(N, 2)``, read-only."""
    if len(data) % FEATURE_POINT_SIZE:
        raise ValueError(f"packed points need a multiple of {FEATURE_POINT_SIZE} bytes, got {len(data)}")
    return np.frombuffer(data, dtype="<f4").reshape(-1, 2)


class FeatureSet(Message):
    """Image feature points seen by ``camera``: ``points`` is :func:`pack_points` of an ``(N, 2)`` array, pixels.

    ``best`` (optional, our extension of the paper's Experiment 2(a)) is the sender's best pose of the target
    when it took the frame; receivers weigh it against their own on the shared eq. (4), so that team-mates
    with the same views agree on one pose even when their stochastic searches did not.
    """

    TOPIC: ClassVar[Topic] = Topic.FEATURES

    camera: CameraInfo
    points: bytes
    best: Pose6 | None = None
    labels: bytes | None = None

    @field_validator("points")
    @classmethod
    def _packed(cls, data: bytes) -> bytes:
        points = unpack_points(data)
        if len(points) > MAX_FEATURE_POINTS:
            raise ValueError(f"{len(points)} points exceed the limit of {MAX_FEATURE_POINTS}")
        if not np.all(np.isfinite(points)):
            raise ValueError("points must be finite")
        return data

    @model_validator(mode="after")
    def _one_label_per_point(self) -> "FeatureSet":
        if self.labels is not None and len(self.labels) != len(self.points) // FEATURE_POINT_SIZE:
            raise ValueError(f"labels: {len(self.labels)} bytes for {len(self.points) // FEATURE_POINT_SIZE} "
                             "points, expected one per point")
        return self

    @property
    def points_uv(self) -> np.ndarray:
        """The points as float32, shape ``(N, 2)``, pixels."""
        return unpack_points(self.points)

    @property
    def labels_array(self) -> np.ndarray | None:
        """Each point's colour class (an index into the target model's colours), int64 shape ``(N,)``; None when
        the sender's points are untyped."""
        return None if self.labels is None else np.frombuffer(self.labels, np.uint8).astype(np.int64)

    @classmethod
    def from_array(cls, points_uv: np.ndarray, camera: CameraInfo, *, sender: str, seq: int,
                   stamp_ns: int, labels: np.ndarray | None = None) -> "FeatureSet":
        """A feature set from image points of shape ``(N, 2)``, pixels, and their colour classes ``(N,)`` (0-255)."""
        packed = None if labels is None else np.asarray(labels, np.int64).clip(0, 255).astype(np.uint8).tobytes()
        return cls(sender=sender, seq=seq, stamp_ns=stamp_ns, camera=camera, points=pack_points(points_uv),
                   labels=packed)


class Attitude(Message):
    """Attitude of ``body`` from an IMU: ``world_from_body`` roll, pitch, yaw and their 1-sigma, radians."""

    TOPIC: ClassVar[Topic] = Topic.ATTITUDE

    body: str
    roll: Float
    pitch: Float
    yaw: Float
    sigma: tuple[NonNegative, NonNegative, NonNegative]

    _check_body = field_validator("body")(classmethod(lambda cls, v: _name(v)))


def quaternion_from_euler(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """``(x, y, z, w)`` of ``R = Rz(yaw) Ry(pitch) Rx(roll)``, with ``w >= 0`` (:func:`geometry.quaternion_from_euler`)."""
    return tuple(float(c) for c in geometry.quaternion_from_euler((roll, pitch, yaw)))  # type: ignore[return-value]


class PoseEstimate(Message):
    """An estimate of the pose of ``target``, ``world_from_target``, and how it was found.

    ``quaternion`` is derived from the Euler angles and sent for convenience; receivers ignore
    the one on the wire. ``mismatch`` is in [0, 1] (0 best: :attr:`evopose.fitness.Match.mismatch`, the
    fitness over its value when nothing matches); ``inputs`` names the team-mates whose
    data (images, features, hints, attitude) went into the estimate. ``good``: the sender's verdict is good
    (:attr:`evopose.trust.Trust.good`: converged, confident, precise and not held back by its published track;
    version 2 called this field ``confident``); ``covariance``: the 6x6
    covariance in the convention of ROS ``PoseWithCovariance`` (docs/protocol.md, "Covariance": position, then
    small rotations about the fixed axes), row-major, metres and radians, absent when it could
    not be computed.
    """

    TOPIC: ClassVar[Topic] = Topic.POSE

    target: str = "target"
    pose: Pose6
    fitness: NonNegative
    mismatch: Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)]
    converged: bool
    generations: Annotated[int, Field(ge=0, lt=2**32)]
    seconds: NonNegative
    from_hint: bool = False
    inputs: Annotated[tuple[str, ...], Field(max_length=32)] = ()
    good: bool = False
    covariance: Annotated[tuple[Float, ...], Field(min_length=36, max_length=36)] | None = None

    _check_target = field_validator("target")(classmethod(lambda cls, v: _name(v)))

    @field_validator("inputs")
    @classmethod
    def _names(cls, names: tuple[str, ...]) -> tuple[str, ...]:
        return tuple(_name(n) for n in names)

    @computed_field  # type: ignore[prop-decorator]
    @property
    def quaternion(self) -> tuple[float, float, float, float]:
        """Orientation as ``(x, y, z, w)``."""
        return quaternion_from_euler(*self.pose[3:])


class Stats(Message):
    """An agent's own traffic counters since it started: per topic name, and rejections per reason."""

    TOPIC: ClassVar[Topic] = Topic.STATS

    sent: dict[str, Annotated[int, Field(ge=0)]] = {}
    received: dict[str, Annotated[int, Field(ge=0)]] = {}
    bytes_sent: dict[str, Annotated[int, Field(ge=0)]] = {}
    bytes_received: dict[str, Annotated[int, Field(ge=0)]] = {}
    rejected: dict[str, Annotated[int, Field(ge=0)]] = {}

    @field_validator("sent", "received", "bytes_sent", "bytes_received")
    @classmethod
    def _topics(cls, table: dict[str, int]) -> dict[str, int]:
        unknown = sorted(set(table) - {t.value for t in Topic})
        if unknown:
            raise ValueError(f"unknown topic names {unknown}")
        return table


class Hint(Payload):
    """A pose hint: ``world_from_target`` ``(x, y, z, roll, pitch, yaw)``; 24 bytes on the wire (protocol.hint)."""

    TOPIC: ClassVar[Topic] = Topic.HINT

    pose: Pose6


#: The payload class of every topic.
MESSAGE_TYPES: dict[Topic, type[Payload]] = {
    cls.TOPIC: cls for cls in (ImageFrame, FeatureSet, Hint, Attitude, PoseEstimate, Stats)}
