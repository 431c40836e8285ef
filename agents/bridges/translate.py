"""One fleet message -> the ROS 2 messages that mirror it (docs/ros2.md, "Topics").

| fleet message | ROS 2 topic | type |
|---|---|---|
| ``PoseEstimate`` of a camera vehicle V | ``/<fleet>/<V>/target_pose`` | PoseWithCovarianceStamped (``map``) |
| | ``/tf`` ``map -> <V>/target_estimate`` | tf2_msgs/TFMessage |
| ``PoseEstimate`` of the target T itself (the truth) | ``/<fleet>/<T>/true_pose``; ``/tf`` ``map -> <T>/truth`` | |
| ``FeatureSet`` or ``ImageFrame`` of V | ``/tf`` ``map -> <V>/base_link -> <V>/camera_optical`` | tf2_msgs/TFMessage |
| | ``/<fleet>/<V>/camera_info`` | sensor_msgs/CameraInfo |
| raw ``ImageFrame`` | ``/<fleet>/<V>/image_raw`` | sensor_msgs/Image |
| JPEG/PNG ``ImageFrame`` | ``/<fleet>/<V>/image_raw/compressed`` | sensor_msgs/CompressedImage |
| hint of V | ``/<fleet>/<V>/hint`` | geometry_msgs/PoseStamped (``map``; stamped on receipt: hints carry no time) |
| ``Attitude`` of V | ``/<fleet>/<V>/imu`` | sensor_msgs/Imu (attitude only, ``<body>/base_link``) |

Stats are not mirrored. The covariance is the estimate's ``covariance`` (36 floats, ROS order) when the message
has one, zeros otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass

from protocol.keys import TopicKey
from protocol.messages import Attitude, FeatureSet, Hint, ImageFrame, Payload, PoseEstimate

from agents.bridges import names
from agents.bridges import ros_msgs as ros
from agents.bridges.rmw_zenoh import DEFAULT_QOS, SENSOR_QOS, TF_QOS, QoS


@dataclass(frozen=True)
class RosMessage:
    """A ROS 2 message to publish or record."""

    topic: str       #: absolute ROS topic
    msgtype: str     #: e.g. geometry_msgs/msg/PoseWithCovarianceStamped
    message: object  #: the rosbags message
    stamp_ns: int    #: its header stamp (acquisition time)
    qos: QoS = DEFAULT_QOS

    def cdr(self) -> bytes:
        return ros.serialize(self.message)


def is_truth(message: PoseEstimate) -> bool:
    """A pose the target publishes of itself is the simulated truth (the ``target`` role)."""
    return message.target == message.sender


def estimate_messages(fleet: str, vehicle: str, message: PoseEstimate) -> list[RosMessage]:
    stamp = message.stamp_ns
    covariance = getattr(message, "covariance", None)
    truth = is_truth(message)
    leaf, child = ("true_pose", names.truth_frame(vehicle)) if truth else ("target_pose",
                                                                          names.estimate_frame(vehicle))
    pose = ros.pose_with_covariance_stamped(message.pose, stamp, names.MAP_FRAME, covariance)
    tf = ros.transform_stamped(names.MAP_FRAME, child, stamp, message.pose[:3],
                               ros.quaternion_from_rpy(*message.pose[3:]))
    return [RosMessage(names.topic_name(fleet, vehicle, leaf), ros.POSE_WITH_COVARIANCE_STAMPED, pose, stamp),
            RosMessage(names.TF_TOPIC, ros.TF_MESSAGE, ros.tf_message([tf]), stamp, TF_QOS)]


def camera_messages(fleet: str, vehicle: str, message: FeatureSet | ImageFrame) -> list[RosMessage]:
    stamp, camera = message.stamp_ns, message.camera
    position, r_world_base, r_base_camera = ros.camera_rig(camera.world_from_camera)
    base, optical = names.base_frame(vehicle), names.camera_frame(vehicle)
    tf = ros.tf_message([
        ros.transform_stamped(names.MAP_FRAME, base, stamp, position, ros.quaternion_from_matrix(r_world_base)),
        ros.transform_stamped(base, optical, stamp, (0.0, 0.0, 0.0), ros.quaternion_from_matrix(r_base_camera))])
    out = [RosMessage(names.TF_TOPIC, ros.TF_MESSAGE, tf, stamp, TF_QOS),
           RosMessage(names.topic_name(fleet, vehicle, "camera_info"), ros.CAMERA_INFO,
                      ros.camera_info(camera, stamp, optical), stamp)]
    if isinstance(message, ImageFrame):
        if message.encoding == "raw":
            out.append(RosMessage(names.topic_name(fleet, vehicle, "image_raw"), ros.IMAGE,
                                  ros.image(message, stamp, optical), stamp, SENSOR_QOS))
        else:
            out.append(RosMessage(names.topic_name(fleet, vehicle, "image_raw/compressed"), ros.COMPRESSED_IMAGE,
                                  ros.compressed_image(message, stamp, optical), stamp, SENSOR_QOS))
    return out


def translate(key: TopicKey, message: Payload, received_ns: int) -> list[RosMessage]:
    """The ROS 2 messages that mirror ``message``, received on ``key`` at ``received_ns`` (see the table)."""
    fleet, vehicle = key.fleet, key.vehicle
    if isinstance(message, PoseEstimate):
        return estimate_messages(fleet, vehicle, message)
    if isinstance(message, (FeatureSet, ImageFrame)):
        return camera_messages(fleet, vehicle, message)
    if isinstance(message, Hint):
        return [RosMessage(names.topic_name(fleet, vehicle, "hint"), ros.POSE_STAMPED,
                           ros.pose_stamped(message.pose, received_ns, names.MAP_FRAME), received_ns)]
    if isinstance(message, Attitude):
        return [RosMessage(names.topic_name(fleet, vehicle, "imu"), ros.IMU,
                           ros.imu(message, message.stamp_ns, names.base_frame(message.body)), message.stamp_ns)]
    return []
