"""A camera vehicle's ROS 2 inputs (``--source``, ``--camera-info``, ``--camera-pose`` given as ``ros2:/topic``), on
the fleet bus's Zenoh session.

- the image topic is a live source (:class:`TopicReader`): each tick of the fleet clock takes the newest valid frame,
  the first one waited for up to :data:`~agents.vehicle.sources.FIRST_FRAME_TIMEOUT_S`, a new one (not the last
  tick's again) up to half a frame period (none: the tick is skipped, counted ``ros2 no new image``);
- the camera_info topic gives the intrinsics: its first valid ``sensor_msgs/msg/CameraInfo``, checked as a
  calibration file is (:func:`agents.problem.camera_info.camera_from_camera_info_message`), then the topic is left;
- the pose topic gives ``world_from_camera``: the ``geometry_msgs/msg/PoseStamped`` at the image's header stamp
  (:class:`StampedPose`, :mod:`agents.bridges.stamped`: the pose of that stamp, else interpolated, else the
  nearest within 0.1 s; none: the tick is skipped, counted ``ros2 no pose``); or, with ``--camera-frame``,
  ``map -> ... -> <frame>`` composed from ``/tf`` and ``/tf_static``, each link at the image's stamp the same way
  (:mod:`agents.bridges.ros_tf`).

Staleness (``--source-max-age``, 1 s): an image or a pose whose sample *arrived* longer ago than that (measured on
this process's monotonic clock, not from the header stamp, which comes from the publisher's clock) is not used:
the tick gives a skipped frame (:class:`~agents.vehicle.sources.FrameSkipped`: no points, no estimate), counted in
the traffic as ``rejected["ros2 stale"]`` and ``rejected_by_topic["ros2:<topic>"]``.

Frames are refused over the pixel budget of team-mates' images (:data:`~agents.vehicle.team_views.MAX_DECODED_PIXELS`)
or of another size than the camera's. What each topic received and refused is counted in the bus's traffic counters
under ``ros2:<topic>`` (reasons ``ros2 step``, ``ros2 pixels``, ...). The vehicle room does not import
:mod:`agents.bridges` at module level (docs/architecture.md): the subscriber and the decoders are imported here, in
the functions that need them, when an input is a ROS topic.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from evopose import Camera
from geometry import matrix_from_pose
from scenarios.world import Scenario

from agents.problem.camera_info import camera_from_camera_info_message
from vision.extract import FeatureExtractor
from agents.transport.bus import FleetBus
from agents.vehicle.config import AgentConfig
from agents.vehicle.sources import (FIRST_FRAME_TIMEOUT_S, NEW_IMAGE_WAIT_SHARE, ROS_SCHEME, FrameSkipped,
                                    SourceCamera, SourceError, is_ros, open_reader)
from agents.vehicle.sources import NO_NEW_IMAGE as SOURCE_NO_NEW_IMAGE
from agents.vehicle.team_views import MAX_DECODED_PIXELS


STALE = "ros2 stale"
#: A tick whose image has no camera pose near its stamp (:class:`StampedPose`).
NO_POSE = "ros2 no pose"
#: A tick without a new image since the last one's (:class:`TopicReader`; :data:`sources.NO_NEW_IMAGE`).
NO_NEW_IMAGE = "ros2 " + SOURCE_NO_NEW_IMAGE
#: How long a frame waits for a pose at or after its image's stamp (s): a pose published with its image may arrive
#: just after it.
POSE_WAIT_S = 0.05
#: The agent's ROS 2 node name (namespace ``/<fleet>/<vehicle>``): it announces the subscriptions.
AGENT_NODE = "evopose_agent"


def check_age(feed, age_s: float, max_age_s: float | None, on_stale: Callable[[str, str], None] | None,
              what: str) -> None:
    """The staleness rule: a value whose sample arrived more than ``max_age_s`` ago (None: no bound) is not used;
    counted ``(label, "ros2 stale")`` and raised as :class:`FrameSkipped`."""
    if max_age_s is not None and age_s > max_age_s:
        if on_stale is not None:
            on_stale(feed.label, STALE)
        raise FrameSkipped(STALE, f"the newest {what} of {feed.label} arrived {age_s:.3f} s ago, over "
                                  f"--source-max-age {max_age_s:g} s")


class TopicReader:
    """A ROS 2 image topic as a live source: each read gives the newest valid frame not read before (the first one
    waited for up to ``first_timeout_s``, a new one up to ``new_image_wait_s``), or :class:`FrameSkipped` when it
    arrived more than ``max_age_s`` ago or none new came; never ends by itself."""

    def __init__(self, feed, name: str, domain: int, first_timeout_s: float = FIRST_FRAME_TIMEOUT_S, *,
                 max_age_s: float | None = None, on_stale: Callable[[str, str], None] | None = None,
                 new_image_wait_s: float = 0.0) -> None:
        self.feed, self.name, self.domain, self.first_timeout_s = feed, name, domain, first_timeout_s
        self.max_age_s, self.on_stale, self.new_image_wait_s = max_age_s, on_stale, new_image_wait_s
        self.stamp_ns: int | None = None   #: the header stamp of the frame last read
        self._taken = 0   # the feed's number of the frame last read (0: none yet)

    def read(self) -> np.ndarray:
        """The newest valid frame, one not read before (waited for up to ``new_image_wait_s``); its header stamp
        (ns) is then :attr:`stamp_ns`."""
        newest = self.feed.newest_with_age(self.first_timeout_s if not self._taken else self.new_image_wait_s,
                                           after=self._taken)
        if newest is None:
            raise SourceError(f"--source {self.name}: no valid sensor_msgs/msg/Image or CompressedImage within "
                              f"{self.first_timeout_s:g} s on ROS domain {self.domain}: {self.feed.describe()}")
        (image, stamp_ns), age_s, number = newest
        check_age(self.feed, age_s, self.max_age_s, self.on_stale, "image")
        if number == self._taken:   # the image of the last tick again: no new measurement (not used twice)
            if self.on_stale is not None:
                self.on_stale(self.feed.label, NO_NEW_IMAGE)
            raise FrameSkipped(NO_NEW_IMAGE, f"no image on {self.feed.label} since the last frame's (waited "
                                             f"{self.new_image_wait_s:g} s)")
        self._taken, self.stamp_ns = number, stamp_ns
        return image

    def close(self) -> None:
        self.feed.close()


class TopicValue:
    """A ROS 2 topic's first valid value (the CameraInfo: the intrinsics; then the topic is left), waited for up to
    ``first_timeout_s``."""

    def __init__(self, feed, option: str, what: str, domain: int, *,
                 first_timeout_s: float = FIRST_FRAME_TIMEOUT_S) -> None:
        self.feed, self.option, self.what, self.domain = feed, option, what, domain
        self.first_timeout_s = first_timeout_s
        self._kept = None

    def __call__(self):
        if self._kept is None:
            newest = self.feed.newest_with_age(self.first_timeout_s)
            if newest is None:
                raise SourceError(f"{self.option} {self.feed.label}: no valid {self.what} within "
                                  f"{self.first_timeout_s:g} s on ROS domain {self.domain}: {self.feed.describe()}")
            self._kept = newest[0]
            self.feed.close()
        return self._kept

    def close(self) -> None:
        self.feed.close()


class StampedPose:
    """A ``PoseStamped`` topic as a camera's pose at each image's header stamp (``history``, an
    :class:`agents.bridges.stamped.PoseHistory` fed with every valid pose by the topic's worker):
    :class:`FrameSkipped` when the newest pose arrived more than ``max_age_s`` ago, or when no pose lies near the
    image's stamp; the first pose waited for up to ``first_timeout_s``, a pose at or after the image's stamp up to
    :data:`POSE_WAIT_S`. Without an image stamp (a file ``--source``), or either stamped 0 (unstamped: tf2 reads
    time 0 as "the latest"): the newest."""

    def __init__(self, feed, history, what: str, domain: int, *, first_timeout_s: float = FIRST_FRAME_TIMEOUT_S,
                 max_age_s: float | None = None, on_stale: Callable[[str, str], None] | None = None) -> None:
        self.feed, self.history, self.what, self.domain = feed, history, what, domain
        self.first_timeout_s, self.max_age_s, self.on_stale = first_timeout_s, max_age_s, on_stale

    def __call__(self, image_stamp_ns: int | None = None) -> np.ndarray:
        newest = self.feed.newest_with_age(self.first_timeout_s)
        if newest is None:
            raise SourceError(f"--camera-pose {self.feed.label}: no valid {self.what} within "
                              f"{self.first_timeout_s:g} s on ROS domain {self.domain}: {self.feed.describe()}")
        (pose_stamp_ns, world_from_camera), age_s, _ = newest
        check_age(self.feed, age_s, self.max_age_s, self.on_stale, "pose")
        if not image_stamp_ns or not pose_stamp_ns:   # no stamp (0: "the latest", as tf2 reads time 0): the newest
            return world_from_camera
        at = self.history.at(image_stamp_ns, POSE_WAIT_S)
        if at is None:
            if self.on_stale is not None:
                self.on_stale(self.feed.label, NO_POSE)
            raise FrameSkipped(NO_POSE, f"no pose of {self.feed.label} within {self.history.max_gap_s:g} s of the "
                                        f"image's stamp {image_stamp_ns} ns")
        return at

    def close(self) -> None:
        self.feed.close()


class TfPose:
    """``world_from_camera`` from ``/tf``: ``map -> ... -> frame`` with each link at the image's header stamp
    (:meth:`agents.bridges.ros_tf.TfTree.lookup_at`; a link's transform just after the stamp waited for up to
    :data:`POSE_WAIT_S`; without a stamp or stamped 0: the newest transforms). The first complete chain is waited
    for up to ``first_timeout_s``; :class:`FrameSkipped` when the chain's oldest dynamic link arrived more than
    ``max_age_s`` ago, when the chain broke (counted ``ros2 tf chain``), or when a link has no transform near the
    image's stamp (``ros2 no pose``)."""

    def __init__(self, tf, frame: str, domain: int, *, first_timeout_s: float = FIRST_FRAME_TIMEOUT_S,
                 max_age_s: float | None = None, on_stale: Callable[[str, str], None] | None = None) -> None:
        self.tf, self.label, self.frame, self.domain = tf, tf.label, frame, domain
        self.first_timeout_s, self.max_age_s, self.on_stale = first_timeout_s, max_age_s, on_stale
        self._found = False

    def __call__(self, image_stamp_ns: int | None = None) -> np.ndarray:
        from agents.bridges.ros_tf import NoTransformAtStamp

        try:
            matrix, arrived = self.tf.tree.lookup(self.frame, timeout=0.0 if self._found else self.first_timeout_s)
            self._found = True
            check_age(self, 0.0 if arrived is None else time.monotonic() - arrived, self.max_age_s, self.on_stale,
                      f"transform chain map -> {self.frame}")
            if image_stamp_ns:   # an image stamped 0: the newest chain (tf2's time 0)
                matrix = self.tf.tree.lookup_at(self.frame, image_stamp_ns, wait_s=POSE_WAIT_S)
        except NoTransformAtStamp as err:
            if self.on_stale is not None:
                self.on_stale(self.label, NO_POSE)
            raise FrameSkipped(NO_POSE, str(err)) from None
        except LookupError as err:
            if not self._found:
                raise SourceError(f"--camera-pose {self.label}: no transform chain map -> {self.frame} within "
                                  f"{self.first_timeout_s:g} s on ROS domain {self.domain}: {err} "
                                  f"({self.tf.describe()})") from None
            if self.on_stale is not None:
                self.on_stale(self.label, "ros2 tf chain")
            raise FrameSkipped("ros2 tf chain", str(err)) from None
        return matrix

    def close(self) -> None:
        self.tf.close()


def open_ros_inputs(config: AgentConfig, bus: FleetBus, size_of_camera: Callable[[], tuple[int, int] | None],
                    frame_period_s: float):
    """The ROS 2 topics among ``config``'s inputs, followed on ``bus``'s session: ``(reader or None, intrinsics or
    None, world_from_camera or None, node)``; received and refused messages are counted in ``bus.counters``.

    ``node`` is the ROS 2 node ``/<fleet>/<vehicle>/evopose_agent`` (names mapped as the mirror maps them) that
    announces each topic followed with a subscription's liveliness token (``MS``: ``ros2 topic info`` lists it);
    each token is undeclared when its topic is left, the node's with ``node.close()``.

    ``size_of_camera()`` is the camera's ``(width, height)`` when known: a frame of another size is refused (counted
    ``ros2 size``), not fatal. ``frame_period_s``: the fleet clock's (a tick waits up to half of it for a new image).
    """
    from agents.bridges import ros_msgs
    from agents.bridges.names import ros_name
    from agents.bridges.rmw_zenoh import DEFAULT_QOS, SENSOR_QOS, TF_QOS, Node, QoS
    from agents.bridges.ros2_node import Ros2Node
    from agents.bridges.ros_sources import (HEADER_BYTES, IMAGE_TYPES, MAX_BYTES_PER_PIXEL, SMALL_MESSAGE_BYTES,
                                            Rejected, TopicFeed, camera_pose, decode_image, header_stamp_ns,
                                            ros_topic)
    from agents.bridges.stamped import PoseHistory

    domain, session, counters = config.ros_domain, bus.session, bus.counters
    node = Ros2Node(session, Node(AGENT_NODE, f"/{ros_name(config.fleet)}/{ros_name(config.vehicle)}"),
                    domain=domain)

    def announce(feed, msgtype: str, qos: QoS) -> None:
        feed.closing.append(node.subscription(feed.topic, msgtype, ros_msgs.type_hash(msgtype), qos))
    common = dict(on_received=counters.count_received, on_rejected=counters.count_rejected)
    stale = dict(max_age_s=config.source_max_age_s, on_stale=counters.count_rejected)
    reader = intrinsics = pose = None
    if is_ros(config.source):
        def image_of(msgtype: str, message) -> tuple[np.ndarray, int]:
            image = decode_image(msgtype, message, max_pixels=MAX_DECODED_PIXELS)
            size = size_of_camera()
            if size is not None and (image.shape[1], image.shape[0]) != size:
                raise Rejected("size", f"{image.shape[1]}x{image.shape[0]}, the camera is {size[0]}x{size[1]}")
            return image, header_stamp_ns(message)

        feed = TopicFeed(session, domain, ros_topic(config.source), IMAGE_TYPES, image_of,
                         max_bytes=MAX_BYTES_PER_PIXEL * MAX_DECODED_PIXELS + HEADER_BYTES, **common)
        # one type per subscription: image_transport's naming says which (a .../compressed topic is compressed)
        announce(feed, ros_msgs.COMPRESSED_IMAGE if feed.topic.endswith("/compressed") else ros_msgs.IMAGE,
                 SENSOR_QOS)
        reader = TopicReader(feed, str(config.source), domain, new_image_wait_s=NEW_IMAGE_WAIT_SHARE * frame_period_s,
                             **stale)
    if is_ros(config.camera_info):
        topic = ros_topic(config.camera_info)
        feed = TopicFeed(session, domain, topic, (ros_msgs.CAMERA_INFO,),
                         lambda _, message: camera_from_camera_info_message(message, ROS_SCHEME + topic),
                         max_bytes=SMALL_MESSAGE_BYTES, **common)
        announce(feed, ros_msgs.CAMERA_INFO, DEFAULT_QOS)
        intrinsics = TopicValue(feed, "--camera-info", ros_msgs.CAMERA_INFO, domain)
    if is_ros(config.camera_pose) and config.camera_frame is not None:
        from agents.bridges.ros_tf import TfFeed

        tf = TfFeed(session, domain, ros_topic(config.camera_pose), **common)
        # tf2's listener QoS: /tf keep last 100; /tf_static keep last 1 (announced volatile: no history is queried)
        announce(tf.feeds[0], ros_msgs.TF_MESSAGE, TF_QOS)
        announce(tf.feeds[1], ros_msgs.TF_MESSAGE, QoS(depth=1))
        pose = TfPose(tf, config.camera_frame, domain, **stale)
    elif is_ros(config.camera_pose):
        history = PoseHistory()
        # every pose into the history (keep: none superseded before the worker comes to it)
        feed = TopicFeed(session, domain, ros_topic(config.camera_pose), (ros_msgs.POSE_STAMPED,),
                         lambda msgtype, message: (header_stamp_ns(message),
                                                   matrix_from_pose(camera_pose(msgtype, message))),
                         max_bytes=SMALL_MESSAGE_BYTES, keep=history.keep,
                         sink=lambda value, _arrived: history.add(*value), **common)
        announce(feed, ros_msgs.POSE_STAMPED, DEFAULT_QOS)
        pose = StampedPose(feed, history, ros_msgs.POSE_STAMPED, domain, **stale)
    return reader, intrinsics, pose, node


def check_ros_topics(config: AgentConfig) -> None:
    """Each ``ros2:`` input must name a valid ROS 2 topic: one :class:`SourceError` line otherwise."""
    from agents.bridges.ros_sources import ros_topic

    for option, spec in (("--source", config.source), ("--camera-info", config.camera_info),
                         ("--camera-pose", config.camera_pose)):
        if is_ros(spec):
            try:
                topic = ros_topic(str(spec))
            except ValueError as err:
                raise SourceError(f"{option} {err}") from None
            if option == "--camera-pose" and topic.rsplit("/", 1)[-1] in ("tf", "tf_static") \
                    and config.camera_frame is None:
                raise SourceError(f"--camera-pose {spec}: a tf2_msgs/msg/TFMessage topic needs --camera-frame (the "
                                  "camera's optical frame, e.g. H1/camera_optical)")
    frame = config.camera_frame
    if frame is not None and (not frame.strip("/") or len(frame) > 256 or not frame.isprintable()):
        raise SourceError(f"--camera-frame {frame!r}: not a frame id (1-256 printable characters)")


def open_ros_camera(config: AgentConfig, scenario: Scenario, bus: FleetBus, extract: FeatureExtractor,
                    intrinsics: Camera | None, world_from_camera: np.ndarray | None) -> SourceCamera:
    """The camera of a source with ROS inputs; ``intrinsics`` and ``world_from_camera`` are those read from files
    (None: from a ROS topic, or the scenario's). A file ``--source`` is opened here too."""
    taken: list[Camera] = []  # the first valid CameraInfo, once taken: the size ROS frames must then have

    def size_of_camera() -> tuple[int, int] | None:
        if intrinsics is not None:
            return intrinsics.width, intrinsics.height
        if not is_ros(config.camera_info):
            scene = scenario.camera(config.vehicle, 0)
            return scene.width, scene.height
        return (taken[0].width, taken[0].height) if taken else None

    reader, ros_intrinsics, ros_pose, node = open_ros_inputs(config, bus, size_of_camera,
                                                             1.0 / (config.fps or scenario.spec.fps))
    closing = tuple(item for item in (ros_intrinsics, ros_pose, node) if item is not None)
    try:
        if reader is None:
            reader = open_reader(str(config.source), NEW_IMAGE_WAIT_SHARE / (config.fps or scenario.spec.fps))
    except BaseException:
        for item in closing:
            item.close()
        raise

    def camera_info() -> Camera:
        camera = ros_intrinsics()
        taken[:] = [camera]
        return camera

    file_intrinsics = None if intrinsics is None else (lambda: intrinsics)
    file_pose = None if world_from_camera is None else (lambda _stamp: world_from_camera)
    return SourceCamera(reader, scenario, config.vehicle, extract,
                        intrinsics=file_intrinsics if ros_intrinsics is None else camera_info,
                        world_from_camera=ros_pose or file_pose, closing=closing,
                        intrinsics_from=None if config.camera_info is None else f"--camera-info {config.camera_info}")


__all__ = ["AGENT_NODE", "NO_NEW_IMAGE", "NO_POSE", "STALE", "StampedPose", "TfPose", "TopicReader", "TopicValue",
           "check_age", "check_ros_topics", "open_ros_camera", "open_ros_inputs"]
