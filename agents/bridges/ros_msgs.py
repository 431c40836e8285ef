"""ROS 2 messages through ``rosbags``: the types (Jazzy's definitions), CDR bytes, RIHS01 type hashes, ``.msg``
schemas for MCAP, and builders of the messages the fleet is mirrored as.

The type hashes of the messages used here are the same in Jazzy, Kilted and Rolling (checked with rosbags'
stores); ``rosbags`` computes them per REP-2011 (``Typestore.hash_rihs01``). CDR is little-endian XCDR1 with the
4-byte encapsulation header ``00 01 00 00``, as rmw_zenoh_cpp puts it on the wire.
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np

from geometry import quaternion_from_rotation, rotation_from_euler

POSE_WITH_COVARIANCE_STAMPED = "geometry_msgs/msg/PoseWithCovarianceStamped"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
IMU = "sensor_msgs/msg/Imu"
#: The types the bridges publish or record.
TYPES = (POSE_WITH_COVARIANCE_STAMPED, POSE_STAMPED, TF_MESSAGE, CAMERA_INFO, IMAGE, COMPRESSED_IMAGE, IMU)


@cache
def store():
    """The rosbags type store of ROS 2 Jazzy."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def _t(name: str):
    return store().types[name]


@cache
def type_hash(msgtype: str) -> str:
    """``RIHS01_<64 hex>`` of ``msgtype`` (e.g. ``geometry_msgs/msg/PoseWithCovarianceStamped``)."""
    return store().hash_rihs01(msgtype)


@cache
def msgdef(msgtype: str) -> str:
    """The ``.msg`` text of ``msgtype`` with its dependencies (MCAP schema encoding ``ros2msg``)."""
    return store().generate_msgdef(msgtype, ros_version=2)[0]


def serialize(message) -> bytes:
    """CDR bytes (encapsulation header included, little-endian) of a rosbags message."""
    return bytes(store().serialize_cdr(message, message.__msgtype__))


def deserialize(data: bytes | memoryview, msgtype: str):
    return store().deserialize_cdr(bytes(data), msgtype)


# -- geometry (geometry, docs/design.md §2: R = Rz(yaw) Ry(pitch) Rx(roll)) -------------------------------------------

def matrix_from_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    return rotation_from_euler((roll, pitch, yaw))


def quaternion_from_matrix(r: np.ndarray) -> tuple[float, float, float, float]:
    """``(x, y, z, w)`` of a rotation matrix, ``w >= 0``."""
    return tuple(float(c) for c in quaternion_from_rotation(r))  # type: ignore[return-value]


def quaternion_from_rpy(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    return quaternion_from_matrix(matrix_from_rpy(roll, pitch, yaw))  # through the matrix, as the golden files


def camera_rig(world_from_camera: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split a camera pose into ``world_from_base`` and ``base_from_camera`` rotations and the position.

    The wire carries only the camera's pose, not the vehicle's, so ``<vehicle>/base_link`` is defined from it
    (docs/ros2.md): at the camera's position, z up, x along the optical axis's horizontal heading (the camera's
    up direction when it looks straight down). Returns ``(position (3,), R_world_base (3, 3), R_base_camera)``.
    """
    position = np.asarray(world_from_camera[:3], dtype=float)
    r_world_camera = matrix_from_rpy(*world_from_camera[3:6])
    heading = r_world_camera[:2, 2]
    if math.hypot(*heading) < 1e-6:
        heading = -r_world_camera[:2, 1]
    r_world_base = matrix_from_rpy(0.0, 0.0, math.atan2(heading[1], heading[0]))
    return position, r_world_base, r_world_base.T @ r_world_camera


# -- messages ---------------------------------------------------------------------------------------

def header(stamp_ns: int, frame_id: str):
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return _t("std_msgs/msg/Header")(stamp=_t("builtin_interfaces/msg/Time")(sec=sec, nanosec=nanosec),
                                     frame_id=frame_id)


def _pose(position, quaternion):
    return _t("geometry_msgs/msg/Pose")(position=_t("geometry_msgs/msg/Point")(*map(float, position)),
                                        orientation=_t("geometry_msgs/msg/Quaternion")(*map(float, quaternion)))


def pose_with_covariance_stamped(pose6, stamp_ns: int, frame_id: str, covariance=None):
    """A ``world_from_target`` pose ``(x, y, z, roll, pitch, yaw)`` with its 6x6 covariance in ROS order
    ``(x, y, z, rot X, rot Y, rot Z)`` (36 floats, row-major; zeros when unknown)."""
    cov = np.zeros(36) if covariance is None else np.asarray(covariance, dtype=np.float64).reshape(36)
    pose = _pose(pose6[:3], quaternion_from_rpy(*pose6[3:6]))
    return _t(POSE_WITH_COVARIANCE_STAMPED)(
        header=header(stamp_ns, frame_id),
        pose=_t("geometry_msgs/msg/PoseWithCovariance")(pose=pose, covariance=cov))


def pose_stamped(pose6, stamp_ns: int, frame_id: str):
    return _t(POSE_STAMPED)(header=header(stamp_ns, frame_id),
                            pose=_pose(pose6[:3], quaternion_from_rpy(*pose6[3:6])))


def transform_stamped(parent: str, child: str, stamp_ns: int, translation, quaternion):
    transform = _t("geometry_msgs/msg/Transform")(
        translation=_t("geometry_msgs/msg/Vector3")(*map(float, translation)),
        rotation=_t("geometry_msgs/msg/Quaternion")(*map(float, quaternion)))
    return _t("geometry_msgs/msg/TransformStamped")(header=header(stamp_ns, parent), child_frame_id=child,
                                                    transform=transform)


def tf_message(transforms: list):
    return _t(TF_MESSAGE)(transforms=list(transforms))


def camera_info(camera, stamp_ns: int, frame_id: str):
    """``sensor_msgs/CameraInfo`` of a ``protocol.messages.CameraInfo`` (plumb_bob, no rectification)."""
    k = np.array([camera.fx, 0.0, camera.cx, 0.0, camera.fy, camera.cy, 0.0, 0.0, 1.0])
    p = np.array([camera.fx, 0.0, camera.cx, 0.0, 0.0, camera.fy, camera.cy, 0.0, 0.0, 0.0, 1.0, 0.0])
    roi = _t("sensor_msgs/msg/RegionOfInterest")(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    return _t(CAMERA_INFO)(header=header(stamp_ns, frame_id), height=camera.height, width=camera.width,
                           distortion_model="plumb_bob", d=np.asarray(camera.distortion, dtype=np.float64),
                           k=k, r=np.eye(3).reshape(9), p=p, binning_x=0, binning_y=0, roi=roi)


def image(frame, stamp_ns: int, frame_id: str):
    """``sensor_msgs/Image`` (``bgr8`` or ``mono8``) of a raw ``ImageFrame``."""
    return _t(IMAGE)(header=header(stamp_ns, frame_id), height=frame.height, width=frame.width,
                     encoding="mono8" if frame.channels == 1 else "bgr8", is_bigendian=0,
                     step=frame.width * frame.channels, data=np.frombuffer(frame.data, dtype=np.uint8))


def compressed_image(frame, stamp_ns: int, frame_id: str):
    """``sensor_msgs/CompressedImage`` of a JPEG or PNG ``ImageFrame``."""
    return _t(COMPRESSED_IMAGE)(header=header(stamp_ns, frame_id), format=frame.encoding,
                                data=np.frombuffer(frame.data, dtype=np.uint8))


def imu(attitude, stamp_ns: int, frame_id: str):
    """``sensor_msgs/Imu`` with the attitude only: the rates and accelerations are marked unknown (-1)."""
    sigma = np.asarray(attitude.sigma, dtype=float)
    unknown = np.zeros(9)
    unknown[0] = -1.0
    zero = _t("geometry_msgs/msg/Vector3")(0.0, 0.0, 0.0)
    return _t(IMU)(header=header(stamp_ns, frame_id),
                   orientation=_t("geometry_msgs/msg/Quaternion")(
                       *quaternion_from_rpy(attitude.roll, attitude.pitch, attitude.yaw)),
                   orientation_covariance=np.diag(sigma ** 2).reshape(9), angular_velocity=zero,
                   angular_velocity_covariance=unknown, linear_acceleration=zero,
                   linear_acceleration_covariance=unknown.copy())
