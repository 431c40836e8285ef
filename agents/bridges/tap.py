"""A raw tap on every data key of a fleet: the Zenoh callback copies (key, payload, receive time) into a bounded
queue, one worker thread hands them to the bridge (docs/design.md §4: no slow work inside a callback).

The tap does not announce itself (no liveliness token): it is an observer, not a team-mate.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import zenoh

from protocol.keys import Topic, fleet_selector, parse_key
from protocol.errors import ProtocolError
from protocol.limits import SIZE_LIMITS

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RawSample:
    key: str
    payload: bytes
    received_ns: int


class FleetTap:
    """Subscribe to ``evopose/<fleet>/*/*`` and call ``handle(RawSample)`` for each sample in a worker thread.

    Samples that are not data keys of the protocol, or larger than their topic's size limit, are counted in
    ``rejected`` and dropped in the callback; when the queue is full the sample is counted in ``dropped``.
    """

    def __init__(self, session: zenoh.Session, fleet: str, handle: Callable[[RawSample], None], *,
                 queue_size: int = 1024) -> None:
        self.fleet = fleet
        self.received = self.dropped = self.rejected = 0
        self._handle = handle
        self._queue: queue.Queue[RawSample | None] = queue.Queue(queue_size)
        self._done = threading.Event()
        self._worker = threading.Thread(target=self._work, name=f"tap-{fleet}", daemon=True)
        self._worker.start()
        self._subscriber = session.declare_subscriber(fleet_selector(fleet),
                                                      zenoh.handlers.Callback(self._on_sample, self._done.set))

    def _on_sample(self, sample: zenoh.Sample) -> None:  # Zenoh thread: checks and a copy, nothing more
        if sample.kind != zenoh.SampleKind.PUT:
            return
        key = str(sample.key_expr)
        try:
            topic = parse_key(key).topic
        except ProtocolError:
            self.rejected += 1
            return
        if len(sample.payload) > SIZE_LIMITS[Topic(topic)]:
            self.rejected += 1
            return
        try:
            self._queue.put_nowait(RawSample(key, sample.payload.to_bytes(), time.time_ns()))
            self.received += 1
        except queue.Full:
            self.dropped += 1

    def _work(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            try:
                self._handle(item)
            except Exception:  # a bridge bug must not stop the tap
                log.exception("error while handling %s", item.key)

    def close(self, timeout: float = 5.0) -> None:
        """Undeclare the subscriber, handle what is queued, stop the worker."""
        self._subscriber.undeclare()
        self._done.wait(timeout)
        self._queue.put(None)
        self._worker.join(timeout)

    def __enter__(self) -> "FleetTap":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
