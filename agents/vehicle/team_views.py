"""What team-mates shared, turned into EvoPose inputs: views (eq. 4), hints, attitude knowledge (eq. 3).

:class:`TeamViews` keeps the last few feature sets (or raw frames, whose marks are extracted here, in
the agent's loop, never in a Zenoh callback) of each team-mate and pairs them with the own frame by
acquisition stamp: for frame ``n`` it waits, up to a deadline, for every live team-mate that has been
sharing to deliver frame ``n``; a team-mate that left, or has sent nothing fresh, is not waited for.
"""

from __future__ import annotations

import io
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import cv2
import numpy as np

from evopose import Camera, View
from evopose.cooperative import Knowledge
from geometry import matrix_from_pose, pose_from_matrix
from protocol import Attitude, CameraInfo, FeatureSet, ImageFrame

#: Frames kept per team-mate while waiting to pair them with the own frame.
KEEP_PER_MATE = 8
#: Fewest image points that make a view worth adding.
MIN_VIEW_POINTS = 3


def camera_info(camera: Camera) -> CameraInfo:
    """The wire form of a calibrated camera (``world_from_camera`` as six numbers)."""
    pose = pose_from_matrix(camera.world_from_camera)
    return CameraInfo(fx=camera.fx, fy=camera.fy, cx=camera.cx, cy=camera.cy, width=camera.width,
                      height=camera.height, distortion=tuple(float(d) for d in camera.distortion),
                      world_from_camera=tuple(float(v) for v in pose))


def camera_from_info(info: CameraInfo) -> Camera:
    """Inverse of :func:`camera_info`."""
    return Camera(info.fx, info.fy, info.cx, info.cy, info.width, info.height, np.array(info.distortion, float),
                  matrix_from_pose(np.array(info.world_from_camera, float)))


#: Most pixels a team-mate's compressed image may decode to (a 1 MB PNG can claim 1.2 GB of pixels).
MAX_DECODED_PIXELS = 4096 * 4096


def image_of(frame: ImageFrame) -> np.ndarray:
    """The pixels of a raw, JPEG or PNG frame as uint8 BGR (or mono), shape (H, W[, 3]).

    A compressed frame is decoded only after its file header was read and found to hold the frame's own
    size, within :data:`MAX_DECODED_PIXELS` (the pixel budget: nothing is allocated for a lying header).
    """
    if frame.encoding == "raw":
        return frame.to_array()
    if frame.width * frame.height > MAX_DECODED_PIXELS:
        raise ValueError(f"{frame.width}x{frame.height} is over the budget of {MAX_DECODED_PIXELS} pixels")
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(frame.data)) as header:  # reads the header only
            size = header.size
    except (UnidentifiedImageError, OSError, ValueError, Image.DecompressionBombError) as err:  # a bomb's header
        raise ValueError(f"{frame.encoding} data has no readable header: {err}") from None
    if size != (frame.width, frame.height):
        raise ValueError(f"{frame.encoding} header says {size[0]}x{size[1]}, the frame {frame.width}x{frame.height}")
    image = cv2.imdecode(np.frombuffer(frame.data, np.uint8), cv2.IMREAD_UNCHANGED)
    if image is None or image.shape[:2] != (frame.height, frame.width):
        raise ValueError(f"{frame.encoding} data does not decode to a {frame.width}x{frame.height} image")
    return image


def encode_image(image: np.ndarray, encoding: str) -> bytes:
    """``image`` (uint8, (H, W[, 3])) as JPEG or PNG file bytes."""
    ok, data = cv2.imencode(".jpg" if encoding == "jpeg" else ".png", image,
                            [cv2.IMWRITE_JPEG_QUALITY, 90] if encoding == "jpeg" else [])
    if not ok:
        raise ValueError(f"OpenCV could not encode the image as {encoding}")
    return data.tobytes()


@dataclass(frozen=True)
class MateView:
    """One team-mate's image points at one instant, with its camera."""

    vehicle: str
    stamp_ns: int
    camera: CameraInfo
    points: np.ndarray  #: (N, 2) float32 pixels
    best: np.ndarray | None = None  #: (6,) the sender's best pose when it took the frame (feature sets)
    labels: np.ndarray | None = None  #: (N,) int64 colour classes of the points; None: untyped


def mate_view(vehicle: str, message: FeatureSet | ImageFrame,
              extract: Callable[..., tuple[np.ndarray, np.ndarray | None]], near: np.ndarray | None = None) -> MateView:
    """A team-mate's view from its feature set, or from its raw frame (marks and their colours extracted with
    ``extract``, looking near the pose ``near`` (6,) first: :class:`vision.extract.FeatureExtractor`)."""
    if isinstance(message, FeatureSet):
        best = None if message.best is None else np.array(message.best, float)
        return MateView(vehicle, message.stamp_ns, message.camera, message.points_uv, best, message.labels_array)
    points, labels = extract(image_of(message), camera_from_info(message.camera), near)
    return own_view(vehicle, message.stamp_ns, message.camera, points, labels)


def own_view(vehicle: str, stamp_ns: int, camera: Camera | CameraInfo, points: np.ndarray,
             labels: np.ndarray | None = None) -> MateView:
    """The own frame in the same form as a team-mate's (float32 points, uint8 labels, the wire camera), so that
    every vehicle that pairs the same frames builds exactly the same problem."""
    points = np.asarray(points, float).reshape(-1, 2).astype(np.float32)
    if labels is not None:  # as the wire carries them
        labels = np.asarray(labels, np.int64).clip(0, 255)
    info = camera if isinstance(camera, CameraInfo) else camera_info(camera)
    return MateView(vehicle, stamp_ns, info, points, labels=labels)


def build_views(views: Iterable[MateView]) -> tuple[list[View], list[str]]:
    """EvoPose views ordered by vehicle name, equally weighted (W_k = 1/V, eq. 4); and their vehicles.

    Views with fewer than :data:`MIN_VIEW_POINTS` points are left out.
    """
    usable = sorted((v for v in views if len(v.points) >= MIN_VIEW_POINTS), key=lambda v: v.vehicle)
    w = 1.0 / max(len(usable), 1)
    return ([View(camera_from_info(v.camera), v.points.astype(float), weight=w, labels=v.labels) for v in usable],
            [v.vehicle for v in usable])


class TeamViews:
    """The last :data:`KEEP_PER_MATE` views of each team-mate; pairing with the own frame by stamp."""

    def __init__(self) -> None:
        self._by_mate: dict[str, deque[MateView]] = {}

    def add(self, view: MateView) -> None:
        self._by_mate.setdefault(view.vehicle, deque(maxlen=KEEP_PER_MATE)).append(view)

    def keep_only(self, vehicles: Iterable[str]) -> None:
        """Forget the views of every team-mate not in ``vehicles`` (those that left)."""
        keep = set(vehicles)
        for mate in [m for m in self._by_mate if m not in keep]:
            del self._by_mate[mate]

    def sharing(self, alive: Iterable[str], now_ns: int, max_age_s: float) -> set[str]:
        """Live team-mates whose newest view is fresh: those worth waiting for."""
        alive = set(alive)
        return {m for m, views in self._by_mate.items()
                if m in alive and views and (now_ns - views[-1].stamp_ns) * 1e-9 <= max_age_s}

    def at(self, stamp_ns: int, mates: Iterable[str], *, tolerance_ns: int = 1_000_000) -> dict[str, MateView]:
        """The view of each of ``mates`` acquired at ``stamp_ns`` (within ``tolerance_ns``), where there is one."""
        found = {}
        for mate in mates:
            for view in reversed(self._by_mate.get(mate, ())):
                if abs(view.stamp_ns - stamp_ns) <= tolerance_ns:
                    found[mate] = view
                    break
        return found

    def newest_stamp_ns(self, mate: str) -> int | None:
        """The stamp of ``mate``'s newest view kept (None when none is)."""
        views = self._by_mate.get(mate)
        return views[-1].stamp_ns if views else None

    def on_clock(self, mates: Iterable[str], is_frame_stamp: Callable[[int], bool]) -> set[str]:
        """Those of ``mates`` whose newest view is stamped on the fleet clock (``is_frame_stamp``): the only ones
        worth waiting for at a frame. Views stamped off it (a member flooding feature sets at arbitrary instants, a
        wrong ``--fps`` or ``--epoch-ns``) never pair with a frame, so a wait for them would only cost the frame
        (issue 12: a flooding member took the victim to 0.57-0.74 of its frame rate this way)."""
        return {m for m in mates if (stamp := self.newest_stamp_ns(m)) is not None and is_frame_stamp(stamp)}

    def newest(self, mates: Iterable[str], now_ns: int, max_age_s: float) -> dict[str, MateView]:
        """The newest fresh view of each of ``mates``."""
        out = {}
        for mate in mates:
            views = self._by_mate.get(mate)
            if views and (now_ns - views[-1].stamp_ns) * 1e-9 <= max_age_s:
                out[mate] = views[-1]
        return out


@dataclass(frozen=True)
class Staleness:
    """Which live team-mates' data went stale (frozen, or a cut link: nothing newer than ``--max-age`` and the frame
    in progress): such a team-mate is no longer waited for, and that is said once, and again when it is fresh."""

    sharing: frozenset[str] = frozenset()  #: team-mates that ever sent views
    stale: frozenset[str] = frozenset()  #: of those, the live ones whose data are stale now

    def update(self, alive: Iterable[str], fresh: Iterable[str]) -> tuple["Staleness", list[str], list[str]]:
        """The next value, the team-mates that went stale now and those fresh again now."""
        fresh = frozenset(fresh)
        stale = frozenset(alive) & (self.sharing - fresh)
        return Staleness(self.sharing | fresh, stale), sorted(stale - self.stale), sorted(self.stale & fresh)


def attitude_knowledge(attitude: Attitude, sigmas: float) -> list[Knowledge]:
    """Eq. (3) from an IMU attitude: roll, pitch and yaw each within ``sigmas`` times its 1-sigma."""
    return [Knowledge(name, float(getattr(attitude, name)), sigmas * float(s))
            for name, s in zip(("roll", "pitch", "yaw"), attitude.sigma)]


def wait_until(condition: Callable[[], bool], deadline_s: float, poll: Callable[[float], None]) -> bool:
    """Call ``poll(timeout)`` until ``condition()`` holds or the monotonic ``deadline_s`` passes."""
    while not condition():
        remaining = deadline_s - time.monotonic()
        if remaining <= 0:
            return False
        poll(min(remaining, 0.005))
    return True
