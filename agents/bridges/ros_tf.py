"""``/tf`` as a camera's pose (``evopose agent --camera-pose ros2:/tf --camera-frame H1/camera_optical``).

A :class:`TfFeed` follows a ``tf2_msgs/msg/TFMessage`` topic (``/tf``) and its static sibling (``/tf_static``) in
the rmw_zenoh format (:class:`~agents.bridges.ros_sources.TopicFeed`, a bounded queue: every message counts, each
may carry other frames) and keeps, per child frame, the recent transforms from its parent by header stamp
(:class:`TfTree`, :class:`~agents.bridges.stamped.StampedTransforms`; a ``/tf_static`` link: its one transform).
``world_from_camera`` is then ``map -> ... -> <camera frame>`` composed from each link's transform at the image's
header stamp (:meth:`TfTree.lookup_at`: tf2's ``lookupTransform("map", frame, stamp)``, each link at that instant,
interpolated between its two transforms around it), or from the newest transforms (:meth:`TfTree.lookup`:
``TimePointZero``).

Everything received is untrusted: a transform with a non-finite field, a quaternion whose norm is not 1 within
1e-3 (as a hint's), an empty or over-long frame id, or a child equal to its parent is counted by reason and
dropped (the message's other transforms are kept). At most :data:`MAX_FRAMES` child frames are kept: a transform
of a new frame beyond them is dropped and counted (``frames``). A chain longer than :data:`MAX_DEPTH` links or with
a loop is no chain.

The age of a composed pose is that of its oldest *dynamic* link (since its sample arrived, on this process's
monotonic clock); links from ``/tf_static`` do not age.
"""

from __future__ import annotations

import math
import threading
from collections import Counter
from dataclasses import dataclass
from functools import partial

import numpy as np
import zenoh

from agents.bridges import ros_msgs
from agents.bridges.names import MAP_FRAME
from agents.bridges.ros_hints import QUATERNION_NORM_TOLERANCE
from agents.bridges.ros_sources import SCHEME, TopicFeed, header_stamp_ns
from agents.bridges.stamped import StampedTransforms

#: Child frames kept (a tree of a few robots has tens); transforms of further new frames are dropped.
MAX_FRAMES = 256
#: Longest chain composed (links from ``map``).
MAX_DEPTH = 32
#: Longest frame id taken, characters.
MAX_NAME = 256
#: Largest TFMessage read, bytes (a transform is ~100 bytes with its frame ids).
TF_BYTES = 64 * 1024
#: TFMessages waiting for the worker per topic; when full the oldest is dropped (``superseded``).
TF_QUEUE = 32


def normalize(frame_id: str) -> str:
    """A frame id as tf2 compares it: without a leading ``/``."""
    return str(frame_id).lstrip("/")


def matrix_from_transform(translation, quaternion) -> np.ndarray:
    """``parent_from_child`` (4, 4) of a translation ``(x, y, z)`` and a unit quaternion ``(x, y, z, w)``."""
    x, y, z, w = quaternion
    m = np.eye(4)
    m[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                 [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                 [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    m[:3, 3] = translation
    return m


def parse_transforms(message) -> tuple[list[tuple[str, str, int, np.ndarray]], list[tuple[str, str]]]:
    """The transforms of a TFMessage: ``[(parent, child, stamp_ns, parent_from_child)]`` of the valid ones and
    ``[(reason, detail)]`` of the others."""
    good, bad = [], []
    for t in message.transforms:
        parent, child = normalize(t.header.frame_id), normalize(t.child_frame_id)
        if not parent or not child or parent == child or max(len(parent), len(child)) > MAX_NAME:
            bad.append(("frame", f"transform {parent[:40]!r} -> {child[:40]!r}: frame ids must be non-empty, "
                                 f"distinct, at most {MAX_NAME} characters"))
            continue
        tr, q = t.transform.translation, t.transform.rotation
        values = (tr.x, tr.y, tr.z, q.x, q.y, q.z, q.w)
        if not all(math.isfinite(v) for v in values):
            bad.append(("non-finite", f"transform {parent[:40]!r} -> {child[:40]!r}: a field is not finite"))
            continue
        norm = math.sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w)
        if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
            bad.append(("quaternion", f"transform {parent[:40]!r} -> {child[:40]!r}: rotation norm {norm:.6g}, "
                                      "expected 1"))
            continue
        quaternion = (q.x / norm, q.y / norm, q.z / norm, q.w / norm)
        good.append((parent, child, header_stamp_ns(t), matrix_from_transform((tr.x, tr.y, tr.z), quaternion)))
    return good, bad


class NoTransformAtStamp(LookupError):
    """A complete chain, but a link without a transform near the stamp looked up (its stream stopped or lags)."""


@dataclass
class Link:
    parent: str
    parent_from_child: np.ndarray   #: the newest transform
    arrived: float   #: time.monotonic() when the newest's sample arrived
    static: bool     #: from /tf_static: does not age, holds at every instant
    stamped: StampedTransforms | None = None   #: a /tf link's recent transforms by stamp


class TfTree:
    """The recent transforms to each child frame (at most ``max_frames`` of them); thread-safe."""

    def __init__(self, max_frames: int = MAX_FRAMES) -> None:
        self.max_frames = max_frames
        self._links: dict[str, Link] = {}
        self._changed = threading.Condition()

    def __len__(self) -> int:
        with self._changed:
            return len(self._links)

    def add(self, transforms, arrived: float, *, static: bool = False) -> list[tuple[str, str]]:
        """Keep each ``(parent, child, stamp_ns, parent_from_child)``; the ``(reason, detail)`` of those dropped
        (new frames beyond ``max_frames``). A child given a new parent starts its history again."""
        dropped = []
        with self._changed:
            for parent, child, stamp_ns, matrix in transforms:
                link = self._links.get(child)
                if link is None and len(self._links) >= self.max_frames:
                    dropped.append(("frames", f"frame {child[:40]!r} is over the {self.max_frames} frames kept"))
                    continue
                if link is None or link.parent != parent or link.static != static:
                    link = self._links[child] = Link(parent, matrix, arrived, static,
                                                     None if static else StampedTransforms())
                link.parent_from_child, link.arrived = matrix, arrived
                if link.stamped is not None:
                    link.stamped.add(stamp_ns, matrix)
            self._changed.notify_all()
        return dropped

    def _chain(self, root: str, frame: str) -> list[tuple[str, Link]]:
        chain, at = [], normalize(frame)
        while at != root:
            link = self._links.get(at)
            if link is None:
                raise LookupError(f"no transform to {at!r}, so no chain {root} -> {frame}")
            if len(chain) >= MAX_DEPTH:
                raise LookupError(f"the chain {root} -> {frame} is over {MAX_DEPTH} links (a loop?)")
            chain.append((at, link))
            at = link.parent
        return chain

    def _lookup(self, root: str, frame: str, stamp_ns: int | None = None) -> tuple[np.ndarray, float | None]:
        chain = self._chain(root, frame)
        matrix = np.eye(4)
        for child, link in reversed(chain):
            step = link.parent_from_child if stamp_ns is None or link.stamped is None else link.stamped.at(stamp_ns)
            if step is None:
                raise NoTransformAtStamp(f"no transform {link.parent} -> {child} within "
                                         f"{link.stamped.max_gap_ns / 1e9:g} s of stamp {stamp_ns} ns")
            matrix = matrix @ step
        dynamic = [link.arrived for _, link in chain if not link.static]
        return matrix, (min(dynamic) if dynamic else None)

    def lookup(self, frame: str, root: str = MAP_FRAME, timeout: float = 0.0) -> tuple[np.ndarray, float | None]:
        """``root_from_frame`` (4, 4) composed from the newest transforms, and when its oldest dynamic link arrived
        (None: all static); waits up to ``timeout`` s for a complete chain.

        Raises
        ------
        LookupError
            No complete chain (a link missing, or over :data:`MAX_DEPTH` links).
        """
        with self._changed:
            error: LookupError | None = None

            def found() -> bool:
                nonlocal error
                try:
                    self._chain(root, frame)
                except LookupError as err:
                    error = err
                    return False
                return True

            if not self._changed.wait_for(found, timeout):
                raise error or LookupError(f"no chain {root} -> {frame}")
            return self._lookup(root, frame)

    def lookup_at(self, frame: str, stamp_ns: int, root: str = MAP_FRAME, wait_s: float = 0.0) -> np.ndarray:
        """``root_from_frame`` (4, 4) at ``stamp_ns``: each dynamic link's transform at that instant
        (:meth:`StampedTransforms.at`), each static one as it is; waits up to ``wait_s`` for every dynamic link of
        the chain to have a transform at or after the stamp.

        Raises
        ------
        NoTransformAtStamp
            A link without a transform within the gap of the stamp.
        LookupError
            No complete chain.
        """
        def caught_up() -> bool:
            try:
                chain = self._chain(root, frame)
            except LookupError:
                return True   # no waiting for a chain: the lookup says why
            return all(link.stamped is None or (link.stamped.stamps and link.stamped.stamps[-1] >= stamp_ns)
                       for _, link in chain)

        with self._changed:
            self._changed.wait_for(caught_up, wait_s)
            return self._lookup(root, frame, stamp_ns)[0]


class TfFeed:
    """Follow ``topic`` (``/tf``) and ``<topic>_static`` on ``session`` into a :class:`TfTree`.

    ``on_received(label, size)`` and ``on_rejected(label, reason)`` count as for a
    :class:`~agents.bridges.ros_sources.TopicFeed` (reasons ``ros2 <reason>``, label ``ros2:<topic>``).
    """

    def __init__(self, session: zenoh.Session, domain: int, topic: str, *, max_frames: int = MAX_FRAMES,
                 on_received=None, on_rejected=None) -> None:
        self.topic, self.label = topic, SCHEME + topic
        self.tree = TfTree(max_frames)
        self.rejected: Counter[str] = Counter()
        self._on_rejected = on_rejected
        self.feeds = [TopicFeed(session, domain, name, (ros_msgs.TF_MESSAGE,), lambda _, m: parse_transforms(m),
                                max_bytes=TF_BYTES, keep=TF_QUEUE, on_received=on_received,
                                on_rejected=on_rejected, sink=partial(self._take, name, static))
                      for name, static in ((topic, False), (topic + "_static", True))]

    def _take(self, topic: str, static: bool, value, arrived: float) -> None:
        good, bad = value
        for reason, detail in bad + self.tree.add(good, arrived, static=static):
            self.rejected[reason] += 1
            if self._on_rejected is not None:
                self._on_rejected(SCHEME + topic, f"ros2 {reason}")

    def describe(self) -> str:
        parts = [f"{feed.label}: {feed.describe()}" for feed in self.feeds]
        if self.rejected:
            parts.append("transforms rejected: " + ", ".join(f"{r} {n}" for r, n in sorted(self.rejected.items())))
        return f"{'; '.join(parts)}; {len(self.tree)} frames known"

    def close(self) -> None:
        for feed in self.feeds:
            feed.close()


__all__ = ["Link", "MAX_DEPTH", "MAX_FRAMES", "NoTransformAtStamp", "TfFeed", "TfTree", "matrix_from_transform",
           "normalize", "parse_transforms"]
