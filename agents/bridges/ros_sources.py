"""ROS 2 topics in the rmw_zenoh format as a camera vehicle's inputs (``evopose agent --source ros2:/topic``).

A :class:`TopicFeed` follows one ROS 2 topic and keeps the *newest* valid message, decoded: images from
``sensor_msgs/msg/Image`` or ``sensor_msgs/msg/CompressedImage`` (:func:`decode_image`), the camera pose from
``geometry_msgs/msg/PoseStamped`` (:func:`camera_pose`), or whatever the caller's decoder makes of a message
(``sensor_msgs/msg/CameraInfo``: :mod:`agents.problem.camera_info` validates it as it validates a calibration file).

How it subscribes: rmw_zenoh puts every sample of ``/camera/image_raw`` on ``<domain>/camera/image_raw/<pkg>::msg::
dds_::<Type>_/<RIHS01 hash>`` (:mod:`agents.bridges.rmw_zenoh`), so one Zenoh subscriber on ``<domain>/camera/
image_raw/*/*`` receives every publisher of the topic at once, whatever its type hash (the four types used here
hash the same in Jazzy, Kilted and Rolling), and the key's type chunk says what the payload is. Not through
:class:`~agents.bridges.listener.Ros2Listener`: a camera needs only the newest frame, and the listener queues every
sample (up to 4096 whole images) for its worker and waits for the publishers' liveliness tokens first.

Everything received is untrusted. In Zenoh's thread only the key is parsed and the payload's size checked (over
``max_bytes``: refused before it is copied); the sample then replaces the one waiting in a one-sample slot, so a
flood costs one decode per worker turn, never a queue. The worker deserializes the CDR (``rosbags``) and decodes;
each message that fails is counted by reason (``rejected``) and dropped, and the newest valid value is kept.
Nothing raised by a message leaves the worker.
"""

from __future__ import annotations

import io
import threading
import time
import warnings
from collections import Counter, deque
from collections.abc import Callable
from typing import Generic, TypeVar

import cv2
import numpy as np
import zenoh

from agents.bridges import ros_msgs
from agents.bridges.rmw_zenoh import ros_type_name
from agents.bridges.ros_hints import RefusedPose, pose_from_pose_stamped

T = TypeVar("T")

#: The spelling of a ROS 2 topic as an agent's input: ``ros2:/camera/image_raw``.
SCHEME = "ros2:"
#: The image types an image topic may carry.
IMAGE_TYPES = (ros_msgs.IMAGE, ros_msgs.COMPRESSED_IMAGE)
#: The ``Image`` encodings taken (sensor_msgs/image_encodings.hpp): bytes per pixel, and OpenCV's conversion to BGR
#: (None: taken as is; ``mono8`` stays grey). Bayer mosaics are named by their top-left 2 x 2 block (``rggb``: red
#: first), as OpenCV's ``COLOR_BayerRGGB2BGR`` is; ``yuv422`` is UYVY and ``yuv422_yuy2`` YUYV, 2 bytes a pixel.
ENCODINGS: dict[str, tuple[int, int | None]] = {
    "bgr8": (3, None), "rgb8": (3, cv2.COLOR_RGB2BGR), "mono8": (1, None),
    "bgra8": (4, cv2.COLOR_BGRA2BGR), "rgba8": (4, cv2.COLOR_RGBA2BGR),
    "bayer_rggb8": (1, cv2.COLOR_BayerRGGB2BGR), "bayer_bggr8": (1, cv2.COLOR_BayerBGGR2BGR),
    "bayer_gbrg8": (1, cv2.COLOR_BayerGBRG2BGR), "bayer_grbg8": (1, cv2.COLOR_BayerGRBG2BGR),
    "yuv422": (2, cv2.COLOR_YUV2BGR_UYVY), "yuv422_yuy2": (2, cv2.COLOR_YUV2BGR_YUY2)}
#: The most bytes a pixel of a taken encoding has (4: ``bgra8``, ``rgba8``).
MAX_BYTES_PER_PIXEL = max(size for size, _ in ENCODINGS.values())
#: CDR bytes of a message other than its image data (header, strings): a payload larger than the image data
#: the pixel budget allows plus this is refused before it is read.
HEADER_BYTES = 64 * 1024
#: Largest payload of a small message (CameraInfo, PoseStamped): both are a few hundred bytes.
SMALL_MESSAGE_BYTES = 64 * 1024


class Rejected(ValueError):
    """A received message that is not a usable input; ``reason`` names its counter (the field at fault)."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason, self.detail = reason, detail


def is_ros_uri(text: str | None) -> bool:
    return text is not None and str(text).startswith(SCHEME)


def ros_topic(uri: str) -> str:
    """The absolute ROS topic of ``ros2:/camera/image_raw`` (a relative name is taken from the root namespace,
    as a node in ``/`` resolves it).

    Raises
    ------
    ValueError
        Not a ROS 2 topic name: tokens of ``A-Z a-z 0-9 _``, none empty or starting with a digit, no ``__``.
    """
    name = str(uri)[len(SCHEME):] if is_ros_uri(uri) else str(uri)
    topic = "/" + name.strip("/")
    tokens = topic[1:].split("/")
    for token in tokens:
        if not token or not token.replace("_", "").isalnum() or not token.isascii() or token[0].isdigit() \
                or "__" in token:
            raise ValueError(f"{uri}: {topic!r} is not a ROS 2 topic name (tokens of A-Z a-z 0-9 _, not starting "
                             "with a digit, no '__')")
    return topic


# -- decoders (pure: a rosbags message in, a value out, or Rejected) ---------------------------------------------

def _raw_image(message, max_pixels: int) -> np.ndarray:
    encoding, width, height, step = str(message.encoding), int(message.width), int(message.height), int(message.step)
    if encoding not in ENCODINGS:
        raise Rejected("encoding", f"encoding {encoding!r}, expected one of {', '.join(ENCODINGS)}")
    channels, conversion = ENCODINGS[encoding]
    if width <= 0 or height <= 0:
        raise Rejected("size", f"{width}x{height}, expected a width and a height > 0")
    if (encoding.startswith("bayer") and min(width, height) < 2) or (channels == 2 and width % 2):
        raise Rejected("size", f"{width}x{height} {encoding}: a Bayer mosaic needs 2 x 2 blocks, YUV 4:2:2 an even "
                               "width")
    if width * height > max_pixels:
        raise Rejected("pixels", f"{width}x{height} is over the budget of {max_pixels} pixels")
    if step < width * channels:
        raise Rejected("step", f"step {step} is less than width x {channels} = {width * channels} bytes")
    data = np.asarray(message.data, dtype=np.uint8).reshape(-1)
    if data.size != height * step:
        raise Rejected("length", f"{data.size} data bytes, expected height x step = {height * step}")
    rows = data.reshape(height, step)[:, :width * channels]
    image = np.ascontiguousarray(rows if channels == 1 else rows.reshape(height, width, channels))
    return image if conversion is None else cv2.cvtColor(image, conversion)


def _compressed_image(message, max_pixels: int) -> np.ndarray:
    fmt = str(message.format).lower()
    if "compresseddepth" in fmt or not any(name in fmt for name in ("jpeg", "jpg", "png")):
        raise Rejected("format", f"format {message.format!r}, expected jpeg or png")
    expected = "PNG" if "png" in fmt else "JPEG"
    data = np.asarray(message.data, dtype=np.uint8).reshape(-1)
    from PIL import Image, UnidentifiedImageError

    try:  # the header only: the pixel budget is checked before anything is decoded
        with warnings.catch_warnings():  # PIL's own bomb warning: the budget below is smaller and refuses it
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(io.BytesIO(data.tobytes())) as header:
                kind, (width, height) = header.format, header.size
    except Image.DecompressionBombError as err:  # not an OSError: a header claiming over 2**27 pixels
        raise Rejected("pixels", f"the {expected} header claims {err}") from None
    except (UnidentifiedImageError, OSError, ValueError) as err:
        raise Rejected("data", f"no readable {expected} header: {err}") from None
    if kind != expected:
        raise Rejected("format", f"format {message.format!r} but the data are {kind}")
    if width * height > max_pixels:
        raise Rejected("pixels", f"{width}x{height} is over the budget of {max_pixels} pixels")
    image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if image is None or image.shape[:2] != (height, width):
        raise Rejected("data", f"the {expected} data do not decode to the {width}x{height} image of their header")
    if image.dtype != np.uint8:
        raise Rejected("depth", f"{image.dtype} pixels, expected 8 bits per channel")
    if image.ndim == 3 and image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    return image


def decode_image(msgtype: str, message, *, max_pixels: int) -> np.ndarray:
    """The pixels of an ``Image`` (an encoding of :data:`ENCODINGS`: 8-bit colour, grey, Bayer or YUV 4:2:2) or a
    JPEG/PNG ``CompressedImage``: uint8, BGR (H, W, 3) or grey (H, W).

    Raises
    ------
    Rejected
        Another type or encoding, over ``max_pixels``, a ``step`` shorter than a row, data not ``height * step``
        bytes, compressed data that are not what ``format`` says or not of their header's size.
    """
    if msgtype == ros_msgs.IMAGE:
        return _raw_image(message, max_pixels)
    if msgtype == ros_msgs.COMPRESSED_IMAGE:
        return _compressed_image(message, max_pixels)
    raise Rejected("type", f"{msgtype}, expected {' or '.join(IMAGE_TYPES)}")


def camera_pose(msgtype: str, message) -> np.ndarray:
    """``world_from_camera`` ``(x, y, z, roll, pitch, yaw)``, shape (6,), of a ``PoseStamped`` of the camera's optical
    frame in ``map`` (what the mirror publishes as ``map -> <V>/camera_optical``, read back the same way as a hint).

    Raises
    ------
    Rejected
        Another type, another frame than ``map``, a non-finite field, a quaternion whose norm is not 1.
    """
    if msgtype != ros_msgs.POSE_STAMPED:
        raise Rejected("type", f"{msgtype}, expected {ros_msgs.POSE_STAMPED}")
    try:
        return pose_from_pose_stamped(message)
    except RefusedPose as err:
        raise Rejected(err.reason, str(err).partition(": ")[2]) from None


def header_stamp_ns(message) -> int:
    """A stamped message's ``header.stamp`` in ns (the publisher's clock)."""
    stamp = message.header.stamp
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


# -- one topic, its newest valid message ----------------------------------------------------------------------------

class TopicFeed(Generic[T]):
    """Follow ``topic`` on ``session`` and keep the newest message that ``decode(msgtype, message)`` accepts.

    Parameters
    ----------
    session : zenoh.Session
        Open; not closed here.
    domain : int
        ``ROS_DOMAIN_ID``.
    topic : str
        Absolute ROS topic (``/camera/image_raw``).
    msgtypes : tuple of str
        The types taken (others are counted as ``type`` and dropped).
    decode : callable
        ``(msgtype, rosbags message) -> value``; any exception rejects the message (``reason`` attribute, else
        ``invalid``).
    max_bytes : int
        Largest payload read.
    on_received, on_rejected : callable, optional
        ``(label, size)`` per sample taken, ``(label, reason)`` per sample refused, in Zenoh's or the worker thread
        (the agent's traffic counters).
    keep : int
        Samples waiting for the worker: 1 (the default) keeps only the newest (a camera's frames); more for a topic
        whose every message counts (``/tf`` carries different frames in different messages). When the queue is full
        the oldest waiting sample is dropped (counted ``superseded``).
    sink : callable, optional
        ``(value, received_at)`` for every valid value, in the worker thread (``received_at``: ``time.monotonic()``
        when its sample arrived); an exception it raises is counted as ``invalid``.

    The age of a value is measured from its sample's *arrival* (``time.monotonic()`` in Zenoh's callback), not from
    its header stamp: stamps come from the publisher's clock.
    """

    def __init__(self, session: zenoh.Session, domain: int, topic: str, msgtypes: tuple[str, ...],
                 decode: Callable[[str, object], T], *, max_bytes: int,
                 on_received: Callable[[str, int], None] | None = None,
                 on_rejected: Callable[[str, str], None] | None = None, keep: int = 1,
                 sink: Callable[[T, float], None] | None = None) -> None:
        self.topic, self.msgtypes, self.decode, self.max_bytes = topic, tuple(msgtypes), decode, int(max_bytes)
        self.label = SCHEME + topic
        self.key = f"{int(domain)}/{topic.strip('/')}/*/*"
        self._on_received, self._on_rejected, self._sink = on_received, on_rejected, sink
        self.received = 0       #: samples on the topic
        self.valid = 0          #: of those, decoded and kept as the newest
        self.superseded = 0     #: replaced in the slot by a newer one before the worker came to them
        self.rejected: Counter[str] = Counter()
        self.last_rejection: str | None = None
        self._newest: T | None = None
        self._newest_at = 0.0   # time.monotonic() when the newest valid value's sample arrived
        self._slot: deque[tuple[str, bytes, float]] = deque(maxlen=max(1, int(keep)))
        self._lock = threading.Condition()
        self._closed = False
        #: further things to close with the feed (its subscription's liveliness token)
        self.closing: list = []
        self._worker = threading.Thread(target=self._work, name=f"ros2 {topic}", daemon=True)
        self._worker.start()
        self._subscriber = session.declare_subscriber(self.key, self._on_sample)

    def reject(self, reason: str, detail: str) -> None:
        """Count one refusal (also for the parts of a message a ``sink`` refuses)."""
        self._reject(reason, detail)

    def _reject(self, reason: str, detail: str) -> None:
        with self._lock:
            self.rejected[reason] += 1
            self.last_rejection = f"{reason}: {detail}"[:300]
        if self._on_rejected is not None:
            self._on_rejected(self.label, f"ros2 {reason}")

    def _on_sample(self, sample: zenoh.Sample) -> None:  # Zenoh's thread: the key and the size only, never blocks
        size, arrived = len(sample.payload), time.monotonic()
        with self._lock:
            self.received += 1
        if self._on_received is not None:
            self._on_received(self.label, size)
        try:
            msgtype = ros_type_name(str(sample.key_expr).split("/")[-2])
        except ValueError:
            self._reject("type", f"key {str(sample.key_expr)[:120]!r} names no ROS type")
            return
        if msgtype not in self.msgtypes:
            self._reject("type", f"{msgtype}, expected {' or '.join(self.msgtypes)}")
            return
        if size > self.max_bytes:
            self._reject("oversized", f"{size} bytes, at most {self.max_bytes}")
            return
        with self._lock:
            if len(self._slot) == self._slot.maxlen:
                self.superseded += 1
            self._slot.append((msgtype, sample.payload.to_bytes(), arrived))
            self._lock.notify_all()

    def _work(self) -> None:
        while True:
            with self._lock:
                self._lock.wait_for(lambda: self._slot or self._closed)
                if self._closed:
                    return
                msgtype, payload, arrived = self._slot.popleft()
            try:
                message = ros_msgs.deserialize(payload, msgtype)
            except Exception as err:  # noqa: BLE001 - hostile CDR may raise anything; counted, never fatal
                self._reject("cdr", f"{msgtype} does not deserialize: {type(err).__name__}: {err}")
                continue
            try:
                value = self.decode(msgtype, message)
            except Exception as err:  # noqa: BLE001 - the decoder's refusal, or its failure on hostile fields
                self._reject(getattr(err, "reason", "invalid"), " ".join(getattr(err, "detail", str(err)).split()))
                continue
            if self._sink is not None:
                try:
                    self._sink(value, arrived)
                except Exception as err:  # noqa: BLE001 - counted, never fatal
                    self._reject("invalid", f"{type(err).__name__}: {err}")
                    continue
            with self._lock:
                self._newest, self._newest_at, self.valid = value, arrived, self.valid + 1
                self._lock.notify_all()

    def newest(self, timeout: float = 0.0) -> T | None:
        """The newest valid value, waiting up to ``timeout`` s for the first; None if there is none yet."""
        with self._lock:
            self._lock.wait_for(lambda: self._newest is not None or self._closed, timeout)
            return self._newest

    def newest_with_age(self, timeout: float = 0.0, after: int = 0) -> tuple[T, float, int] | None:
        """The newest valid value, its age in s (since its sample arrived) and its number (:attr:`valid` when it
        was kept), waiting up to ``timeout`` s for one numbered over ``after`` (0: the first); None if there is none
        yet, else the newest even if not over ``after``."""
        with self._lock:
            self._lock.wait_for(lambda: self.valid > after or self._closed, timeout)
            if self._newest is None:
                return None
            return self._newest, time.monotonic() - self._newest_at, self.valid

    def describe(self) -> str:
        """What arrived, for an error line: ``3 received, 3 rejected (step 3; last: step: ...)``."""
        with self._lock:
            if not self.received:
                return "nothing received (is a publisher up, on this domain and Zenoh network?)"
            counts = ", ".join(f"{reason} {n}" for reason, n in sorted(self.rejected.items()))
            rejected = sum(self.rejected.values())
            text = f"{self.received} received, {rejected} rejected"
            return f"{text} ({counts}; last: {self.last_rejection})" if rejected else text

    def close(self) -> None:
        """Stop following the topic (again: nothing); the newest value stays readable."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._lock.notify_all()
        for item in self.closing:
            item.close()
        self._subscriber.undeclare()
        self._worker.join(2.0)


__all__ = ["ENCODINGS", "HEADER_BYTES", "IMAGE_TYPES", "MAX_BYTES_PER_PIXEL", "Rejected", "SCHEME",
           "SMALL_MESSAGE_BYTES", "TopicFeed", "camera_pose", "decode_image", "header_stamp_ns", "is_ros_uri",
           "ros_topic"]
