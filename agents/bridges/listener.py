"""A pure-Python subscriber in the rmw_zenoh format: the ROS 2 graph from the liveliness tokens of a domain, and
the samples of the publishers of chosen topics, decoded (attachment and CDR).

What ``ros2 topic list`` and ``ros2 topic echo`` do over rmw_zenoh, without ROS: a liveliness subscriber on
``@ros2_lv/<domain>/**`` (with history, so tokens declared earlier arrive too) keeps the graph; for each publisher
(``MP``) of a wanted topic, a subscriber on its data key. All decoding runs in one worker thread.
"""

from __future__ import annotations

import queue
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import zenoh

from agents.bridges import ros_msgs
from agents.bridges.rmw_zenoh import ADMIN_SPACE, Attachment, Entity, EntityKind, decode_attachment, parse_token

#: Reasons of undecodable tokens and samples kept (the count is kept whole).
ERRORS_KEPT = 100
#: Tokens and samples waiting for the worker.
EVENTS_QUEUED = 4096


@dataclass(frozen=True)
class RosSample:
    """One received ROS 2 message."""

    topic: str
    msgtype: str
    key: str
    cdr: bytes
    attachment: Attachment
    message: object
    received_ns: int


class Ros2Listener:
    """Follow the graph of ``domain`` and receive the ``topics`` asked for (all when None).

    ``on_message`` (optional) is called in the worker thread; :meth:`samples` returns the newest
    ``keep_samples`` that arrived (0 with a handler that keeps what it needs).
    Samples whose attachment or CDR does not decode are counted in ``errors`` (with the reason).
    """

    def __init__(self, session: zenoh.Session, *, domain: int = 0, topics: Iterable[str] | None = None,
                 on_message: Callable[[RosSample], None] | None = None, keep_samples: int = 10_000) -> None:
        self.session, self.domain = session, int(domain)
        self.wanted = None if topics is None else set(topics)
        #: the newest reasons of tokens and samples that did not decode (bounded: a hostile publisher may flood)
        self.errors: deque[str] = deque(maxlen=ERRORS_KEPT)
        self.error_count = 0
        self._on_message = on_message
        self._lock = threading.Condition()
        self._graph: dict[str, Entity] = {}
        self._samples: deque[RosSample] = deque(maxlen=keep_samples)  # the newest, for samples()
        self._subscribers: dict[str, tuple[zenoh.Subscriber, Entity]] = {}
        # tokens and samples for the worker: bounded, what does not fit is dropped and counted (``dropped``)
        self._events: queue.Queue = queue.Queue(maxsize=EVENTS_QUEUED)
        self.dropped = 0
        self._closed = threading.Event()
        self._worker = threading.Thread(target=self._work, name="ros2-listener", daemon=True)
        self._worker.start()
        self._tokens = session.liveliness().declare_subscriber(
            f"{ADMIN_SPACE}/{self.domain}/**", lambda sample: self._enqueue(("token", sample.kind,
                                                                                str(sample.key_expr))),
            history=True)

    # -- the graph ----------------------------------------------------------------------------------

    def entities(self, kind: EntityKind | None = None) -> list[Entity]:
        with self._lock:
            return [e for e in self._graph.values() if kind is None or e.kind is kind]

    def topics(self) -> dict[str, set[str]]:
        """Topic -> its types, from the publishers and subscriptions in the graph (``ros2 topic list -t``)."""
        found: dict[str, set[str]] = {}
        for entity in self.entities():
            if entity.topic is not None and entity.kind in (EntityKind.PUBLISHER, EntityKind.SUBSCRIPTION):
                found.setdefault(entity.topic, set()).add(entity.msgtype)
        return found

    def wait_for(self, predicate: Callable[["Ros2Listener"], bool], timeout: float) -> bool:
        """Wait until ``predicate(self)`` holds (checked whenever something arrives); False on timeout."""
        deadline = time.monotonic() + timeout
        with self._lock:
            while not predicate(self):
                remaining = deadline - time.monotonic()
                if remaining <= 0 or self._closed.is_set():
                    return False
                self._lock.wait(min(remaining, 0.2))
            return True

    def samples(self, topic: str | None = None) -> list[RosSample]:
        with self._lock:
            return [s for s in self._samples if topic is None or s.topic == topic]

    # -- the worker ---------------------------------------------------------------------------------

    def _enqueue(self, event: tuple) -> None:  # Zenoh's thread: never blocks
        try:
            self._events.put_nowait(event)
        except queue.Full:
            self.dropped += 1

    def _work(self) -> None:
        while True:
            event = self._events.get()
            if event is None:
                return
            try:
                if event[0] == "token":
                    self._on_token(event[1], event[2])
                else:
                    self._on_data(*event[1:])
            except Exception as err:  # noqa: BLE001 - a bad token or sample is recorded, never fatal
                with self._lock:
                    self.errors.append(f"{event[0]}: {type(err).__name__}: {str(err)[:200]}")
                    self.error_count += 1
            with self._lock:
                self._lock.notify_all()

    def _on_token(self, kind: zenoh.SampleKind, key: str) -> None:
        entity = parse_token(key)
        with self._lock:
            if kind == zenoh.SampleKind.PUT:
                self._graph[key] = entity
            else:
                self._graph.pop(key, None)
        wanted = self.wanted is None or entity.topic in self.wanted
        if kind == zenoh.SampleKind.PUT and entity.kind is EntityKind.PUBLISHER and wanted:
            data_key = entity.data_key
            if data_key not in self._subscribers and not self._closed.is_set():
                subscriber = self.session.declare_subscriber(
                    data_key, lambda sample: self._enqueue(("data", str(sample.key_expr), sample.payload.to_bytes(),
                                                                None if sample.attachment is None
                                                                else sample.attachment.to_bytes(), time.time_ns())))
                self._subscribers[data_key] = (subscriber, entity)

    def _on_data(self, key: str, payload: bytes, attachment: bytes | None, received_ns: int) -> None:
        entry = self._subscribers.get(key)
        if entry is None:
            return
        entity = entry[1]
        if attachment is None:
            raise ValueError(f"{key}: sample without an attachment")
        decoded = decode_attachment(attachment)
        message = ros_msgs.deserialize(payload, entity.msgtype)
        sample = RosSample(entity.topic, entity.msgtype, key, payload, decoded, message, received_ns)
        with self._lock:
            self._samples.append(sample)
        if self._on_message is not None:
            self._on_message(sample)

    def close(self) -> None:
        self._closed.set()
        self._tokens.undeclare()
        for subscriber, _ in list(self._subscribers.values()):
            subscriber.undeclare()
        self._events.put(None)
        self._worker.join(5.0)

    def __enter__(self) -> "Ros2Listener":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
