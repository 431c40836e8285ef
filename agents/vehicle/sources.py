"""Real image sources for a camera vehicle: a video file, an image sequence, a V4L2 device or a ROS 2 topic
(``--source``).

A :class:`SourceCamera` has the :class:`~agents.vehicle.frames.SimulatedCamera` interface
(``acquire(index, stamp_ns) -> Frame``, ``extract(image)``), so a vehicle runs exactly the same per-frame loop on
real images. Frames carry no ground truth (``Frame.truth`` is None). Pacing: each tick of the fleet clock takes
the source's *next* frame (a file or a sequence is played frame by frame however late the loop is; when it ends,
:class:`SourceEnded` stops the vehicle cleanly); a live device gives its *newest* frame (a reader thread keeps
only the latest). What ``--source`` may be:

- a video file (``cv2.VideoCapture``, FFmpeg);
- an image sequence: a printf pattern (``left%02d.jpg``, read by ``cv2.VideoCapture``), a glob (``'img/*.png'``)
  or a directory (its images in name order, read by ``cv2.imread``);
- a rendered dataset (docs/datasets.md): its root or one camera's folder, played in frame order with each frame's
  camera and truth from the dataset (:mod:`agents.vehicle.dataset_source`);
- a V4L2 device: ``/dev/videoN`` or its index ``N``;
- a ROS 2 topic in the rmw_zenoh format, ``ros2:/camera/image_raw`` (``sensor_msgs/msg/Image`` or
  ``CompressedImage``, on ``--ros-domain``, followed on the agent's own Zenoh session): live, like a device, each
  tick takes the newest valid frame (:mod:`agents.bridges.ros_sources`).

The camera of frame ``k``: intrinsics from ``--camera-info`` (a ROS camera_info file, or ``ros2:/topic``: the first
valid ``sensor_msgs/msg/CameraInfo``), else the scenario vehicle's; ``world_from_camera`` from ``--camera-pose`` (a
static pose file, or ``ros2:/topic``: the newest ``geometry_msgs/msg/PoseStamped`` of the optical frame in ``map``
when the frame is taken), else the scenario vehicle's at scenario frame ``k mod frames`` (what the renderer would
use for the same frame). Every bad input is one :class:`SourceError` line; a bad ROS message is counted in the
agent's traffic (``rejected``, by reason) and dropped.

Which camera a vehicle gets (the renderer, one of these, a rendered dataset or ROS 2 topics) is
:func:`agents.vehicle.cameras.open_camera`'s choice; the ROS inputs are made by :mod:`agents.vehicle.ros_camera`.
"""

from __future__ import annotations

import contextlib
import glob
import os
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np

from evopose import Camera
from scenarios.errors import WorldError
from scenarios.world import Scenario

from agents.errors import FleetError
from vision.extract import FeatureExtractor
from vision.images import read_image
from agents.vehicle.frames import Frame

#: Files a directory source plays (by suffix, lower case).
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm", ".pgm", ".webp")
#: How long a live device or ROS topic may take to deliver its first frame (a ROS topic: its first camera_info and
#: pose too), s.
FIRST_FRAME_TIMEOUT_S = 5.0
#: The spelling of a ROS 2 topic as an input (``agents.bridges.ros_sources.SCHEME``).
ROS_SCHEME = "ros2:"


class SourceError(FleetError):
    """A ``--source`` (or its camera files) that cannot be used; one line naming it."""


class SourceEnded(Exception):
    """A file source has no more frames: the vehicle stops and reports its summary."""


#: A live camera's tick without a new image since the last tick's (the same image is not estimated from twice: it
#: would count as a new measurement).
NO_NEW_IMAGE = "no new image"
#: How long a live camera's tick waits for a new image when the newest is the last tick's, in frame periods (the
#: image of this tick is due: a loaded publisher's or decoder's may come a little late).
NEW_IMAGE_WAIT_SHARE = 0.5


class FrameSkipped(Exception):
    """A live input has nothing usable at this tick (a ROS image or camera pose older than ``--source-max-age``, no
    new image since the last tick's): the frame is taken without points, so no estimate is made from it; ``reason``
    names its counter."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason, self.detail = reason, detail


_quiet_lock = threading.Lock()


@contextlib.contextmanager
def quiet_native_stderr() -> Iterator[None]:
    """Silence what OpenCV and FFmpeg print from C on file descriptor 2 (``[ WARN:0@..] can't open camera``,
    ``moov atom not found``) while a capture opens or reads: the agent's own error is one line."""
    with _quiet_lock:
        sys.stderr.flush()
        saved = os.dup(2)
        try:
            with open(os.devnull, "wb") as null:
                os.dup2(null.fileno(), 2)
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)


class CaptureReader:
    """Frames of a video file or a printf-pattern image sequence, in order, through ``cv2.VideoCapture``."""

    def __init__(self, capture: cv2.VideoCapture, name: str) -> None:
        self.capture, self.name = capture, name

    def read(self) -> np.ndarray:
        """The next frame, (H, W, 3) uint8 BGR; :class:`SourceEnded` after the last one."""
        with quiet_native_stderr():
            ok, image = self.capture.read()
        if not ok or image is None:
            raise SourceEnded(self.name)
        return image

    def close(self) -> None:
        self.capture.release()


class FileListReader:
    """Frames of an image sequence given as files (a glob or a directory), in order, through ``cv2.imread``."""

    def __init__(self, paths: list[Path], name: str) -> None:
        self.paths, self.name, self.next = paths, name, 0

    def read(self) -> np.ndarray:
        if self.next >= len(self.paths):
            raise SourceEnded(self.name)
        path, self.next = self.paths[self.next], self.next + 1
        try:
            return read_image(path)
        except WorldError as err:
            raise SourceError(f"--source {self.name}: {err}") from None

    def close(self) -> None:
        pass


class LatestFrameReader:
    """A live camera: a thread reads it continuously and keeps only the newest frame, which :meth:`read` returns
    (a slow frame loop never works through a backlog), never the same frame twice: a tick without a new one (a
    camera slower than the fleet's clock) waits up to ``new_frame_wait_s`` for it, then is skipped
    (:class:`FrameSkipped` ``no new image``). Ends when the device stops delivering."""

    def __init__(self, capture: cv2.VideoCapture, name: str, first_timeout_s: float = FIRST_FRAME_TIMEOUT_S,
                 new_frame_wait_s: float = 0.0) -> None:
        self.capture, self.name, self.first_timeout_s = capture, name, first_timeout_s
        self.new_frame_wait_s = new_frame_wait_s
        self._latest: np.ndarray | None = None
        self._count = 0  # frames read from the device so far
        self._taken = 0  # the count at the frame last returned
        self._ended = False
        self._fresh = threading.Condition()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"source {name}", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            ok, image = self.capture.read()
            with self._fresh:
                if not ok or image is None:
                    self._ended = True
                else:
                    self._latest, self._count = image, self._count + 1
                self._fresh.notify_all()
            if self._ended:
                return

    @property
    def frames_read(self) -> int:
        """How many frames the device delivered (the frame loop sees only the newest of them)."""
        return self._count

    def read(self) -> np.ndarray:
        """The newest frame not returned before (waiting for the first one); :class:`SourceEnded` once the device
        stopped, :class:`FrameSkipped` when no new frame came within ``new_frame_wait_s``."""
        with self._fresh:
            wait_s = self.new_frame_wait_s if self._taken else self.first_timeout_s
            if not self._fresh.wait_for(lambda: self._count > self._taken or self._ended, wait_s):
                if not self._taken:
                    raise SourceError(f"--source {self.name}: no frame within {self.first_timeout_s:g} s")
                raise FrameSkipped(NO_NEW_IMAGE, f"no frame from {self.name} since the last tick's (waited "
                                                 f"{wait_s:g} s)")
            if self._ended:
                raise SourceEnded(self.name)
            self._taken = self._count
            return self._latest

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.capture.release()


def _device(source: str) -> int | str | None:
    """The device of ``source``: an index (``"0"``), a ``/dev/video*`` path, or None if it is not a device."""
    if source.isdigit():
        return int(source)
    return source if source.startswith("/dev/video") else None


def open_reader(source: str, new_frame_wait_s: float = 0.0) -> CaptureReader | FileListReader | LatestFrameReader:
    """A reader of ``source`` (see the module's docstring); :class:`SourceError` when it cannot be opened.
    ``new_frame_wait_s``: how long a device's tick waits for a new frame (:class:`LatestFrameReader`)."""
    device = _device(source)
    if device is not None:
        if isinstance(device, str) and not os.path.exists(device):
            raise SourceError(f"--source {source}: no such device")
        with quiet_native_stderr():
            capture = cv2.VideoCapture(device, cv2.CAP_V4L2)
        if not capture.isOpened():
            raise SourceError(f"--source {source}: the V4L2 device does not open (busy, not a camera, or no access)")
        return LatestFrameReader(capture, source, new_frame_wait_s=new_frame_wait_s)
    path = Path(source)
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise SourceError(f"--source {source}: the directory holds no images ({', '.join(IMAGE_SUFFIXES)})")
        return FileListReader(files, source)
    if glob.has_magic(source):
        files = sorted(Path(p) for p in glob.glob(source) if Path(p).is_file())
        if not files:
            raise SourceError(f"--source {source}: the pattern matches no files")
        return FileListReader(files, source)
    if "%" in source:  # a printf pattern: an image sequence read by OpenCV
        with quiet_native_stderr():
            capture = cv2.VideoCapture(source)
        if not capture.isOpened():
            raise SourceError(f"--source {source}: no image sequence matches the pattern")
        return CaptureReader(capture, source)
    if not path.exists():
        raise SourceError(f"--source {source}: no such file, directory or device")
    if not path.is_file():
        raise SourceError(f"--source {source}: not a regular file")
    with quiet_native_stderr():
        capture = cv2.VideoCapture(source)
    if not capture.isOpened():
        raise SourceError(f"--source {source}: not a video OpenCV can read")
    return CaptureReader(capture, source)


class SourceCamera:
    """A vehicle's real camera: frames from a reader, the camera from files, ROS topics or the scenario, features
    extracted.

    ``intrinsics`` and ``world_from_camera`` are asked when each frame is taken (after its image was read): a file's
    are constant, a ROS topic's are its first valid CameraInfo and its pose at the image's header stamp
    (``world_from_camera(image_stamp_ns)``: the reader's ``stamp_ns`` after the read, None for a file's frames).
    ``closing`` are further inputs to close with the camera (the ROS topics followed).

    A live input may raise :class:`FrameSkipped` (a ROS image or pose is stale, no pose lies near the image's
    stamp, no new frame came since the last tick's): the tick then gives a *skipped* frame: no points (so no own
    view and no estimate from it), a black image (nothing stale is shared with team-mates) and the camera of the
    last frame taken; ``skipped`` counts them.
    """

    def __init__(self, reader, scenario: Scenario, vehicle: str, extract: FeatureExtractor, *,
                 intrinsics: Callable[[], Camera] | None = None,
                 world_from_camera: Callable[[int | None], np.ndarray] | None = None,
                 intrinsics_from: str | None = None, closing: tuple = ()) -> None:
        self.reader, self.scenario, self.extract = reader, scenario, extract
        self.vehicle = scenario.vehicle(vehicle).name
        self.intrinsics, self.world_from_camera = intrinsics, world_from_camera
        self.intrinsics_from = intrinsics_from or f"scenario {scenario.name!r} vehicle {self.vehicle}"
        self.closing = closing
        self.frames = 0  # frames taken from the source
        self.skipped = 0  # ticks without a usable frame (FrameSkipped)
        self._last_camera: Camera | None = None

    def camera(self, k: int, image_stamp_ns: int | None = None) -> Camera:
        """The camera of the source's frame ``k``, whose image is stamped ``image_stamp_ns`` (a ROS image's header
        stamp: the pose is the one at that instant; None: a file's frame)."""
        scene = self.scenario.camera(self.vehicle, k % self.scenario.frames)
        k_cam = scene if self.intrinsics is None else self.intrinsics()
        pose = (scene.world_from_camera if self.world_from_camera is None
                else self.world_from_camera(image_stamp_ns))
        return Camera(k_cam.fx, k_cam.fy, k_cam.cx, k_cam.cy, k_cam.width, k_cam.height, k_cam.distortion, pose)

    def acquire(self, index: int, stamp_ns: int, near: np.ndarray | None = None) -> Frame:
        """The source's next frame as fleet frame ``index`` (``Frame.scene_frame``: its number in the source); ``near``:
        the pose the target is expected near (the front-end looks around it first)."""
        t0 = time.perf_counter()
        try:
            image = self.reader.read()
            read_s = time.perf_counter() - t0
            camera = self.camera(self.frames, getattr(self.reader, "stamp_ns", None))
        except FrameSkipped as skip:
            return self._skipped(index, stamp_ns, time.perf_counter() - t0, skip.detail)
        k, self.frames = self.frames, self.frames + 1
        if image.ndim == 2:
            image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
        if image.shape[:2] != (camera.height, camera.width):
            raise SourceError(f"--source {self.reader.name}: frame {k} is {image.shape[1]}x{image.shape[0]}, "
                              f"the camera ({self.intrinsics_from}) is {camera.width}x{camera.height}")
        self._last_camera = camera
        t1 = time.perf_counter()
        points, labels = self.extract(image, camera, near)
        return Frame(index, k, stamp_ns, image, camera, points, None, read_s, labels,
                     extract_s=time.perf_counter() - t1, halved=getattr(self.extract, "halved", False))

    def _skipped(self, index: int, stamp_ns: int, read_s: float, why: str) -> Frame:
        """A tick without a usable frame: no points, a black image, the last camera (before any: the intrinsics
        with the scenario's pose)."""
        self.skipped += 1
        camera = self._last_camera
        if camera is None:
            scene = self.scenario.camera(self.vehicle, self.frames % self.scenario.frames)
            k_cam = scene if self.intrinsics is None else self.intrinsics()
            camera = Camera(k_cam.fx, k_cam.fy, k_cam.cx, k_cam.cy, k_cam.width, k_cam.height, k_cam.distortion,
                            scene.world_from_camera)
        image = np.zeros((camera.height, camera.width, 3), np.uint8)
        return Frame(index, self.frames, stamp_ns, image, camera, np.zeros((0, 2)), None, read_s, None, why)

    def close(self) -> None:
        self.reader.close()
        for item in self.closing:
            item.close()


def is_ros(spec: object) -> bool:
    """Whether an input (``--source``, ``--camera-info``, ``--camera-pose``) is a ROS 2 topic."""
    return spec is not None and str(spec).startswith(ROS_SCHEME)


__all__ = ["CaptureReader", "FileListReader", "FrameSkipped", "LatestFrameReader", "NEW_IMAGE_WAIT_SHARE",
           "NO_NEW_IMAGE", "SourceCamera", "SourceEnded", "SourceError", "is_ros", "open_reader", "quiet_native_stderr"]
