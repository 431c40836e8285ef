"""FleetBus: one vehicle's view of the fleet over ONE Zenoh session (docs/design.md §4).

Sending: one publisher per topic with the topic's QoS (``protocol.QOS``): BLOCK for hints, features, attitude and
poses (hints also ``express``), DROP for images; every message gets the vehicle as ``sender`` and a per-topic ``seq``.

Receiving (``agents.transport.receiver``): per subscribed topic, samples land in Zenoh's ring channels (Rust, no
GIL): one ring shared by every sender and one per present team-mate. One thread per topic pulls from them only as
fast as each sender's budget allows (``agents.transport.inbox.SenderBudget``), so the excess of a flood is
overwritten inside Zenoh and never costs Python time, and a flooding sender overwrites only its own ring. A pulled
sample is checked cheaply (our own echoes dropped, size limit before any copy, the sender's budget) and its bytes
handed to a bounded inbox (images into a ring of the newest few); what does not fit is dropped and counted
(``overflow``). One worker thread decodes, checks the sender against the key, drops stale data (``stamp_ns`` older
than ``max_age_s`` before the instant the vehicle plays), counts lost messages by ``seq`` (as ``rate-limited`` when
the sender was over its budget since its previous message: they were overwritten in its ring), keeps the newest
message per team-mate and hands messages to :meth:`recv` (a bounded queue: the oldest unread one is pushed out and
counted as ``unread``) and to handlers. At close, what was already received is still handled. A bad payload is
counted under its reason, logged (rate-limited), and never stops the receiver.

Presence: the vehicle's liveliness token ``evopose/<fleet>/@alive/<vehicle>``; a liveliness subscriber (with history)
tracks which team-mates are alive. A team-mate that leaves is dropped from :meth:`teammates` and :meth:`latest`;
when it returns it is used again.

Typical agent loop::

    with stop_on_signals() as stop, FleetBus.open(options, "alpha", "uav1", max_age_s=0.5) as bus:
        bus.subscribe(Topic.HINT)
        bus.subscribe(Topic.FEATURES)
        while not stop.is_set():
            frame = camera.next()                                    # scenarios/
            bus.publish(FeatureSet.from_array(uv, cam, **bus.header(Topic.FEATURES, frame.stamp_ns)))
            for mate, rx in bus.latest(Topic.FEATURES).items(): ...  # fresh data of live team-mates
            bus.publish_hint(pose_world_from_target)
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
import zenoh

from protocol import (QOS, Message, Payload, ProtocolError, Stats, Topic, alive_key, alive_selector, check_name,
                      check_topic, decode_sample, encode, encode_hint, parse_alive_key, topic_key)
from protocol.hint import Hint

from agents.transport.inbox import BoundedSenders, Inbox, SenderBudget
from agents.transport.playback import PlaybackClock
from agents.transport.receiver import TopicReceiver
from agents.transport.traffic import RateLimitedLog, TrafficCounters
from agents.transport.session import SessionOptions, open_session

log = logging.getLogger("evopose.bus")

#: Time given to queued outgoing messages to leave at close, s.
FLUSH_S = 0.2
#: Longest time close() spends handing already received messages to the worker, s.
DRAIN_S = 2.0

#: Handler of received messages, called in the bus's worker thread (keep it short).
MessageHandler = Callable[["Received"], None]
#: Handler of a team-mate joining or leaving, called in the worker thread with its vehicle name.
PresenceHandler = Callable[[str], None]


@dataclass(frozen=True)
class Received:
    """A decoded message from a team-mate.

    Attributes
    ----------
    topic, vehicle : the key's topic and sender.
    message : the payload model (``Hint`` for hints).
    size : payload bytes on the wire.
    received_ns : local wall-clock arrival time, ns since the Unix epoch.
    """

    topic: Topic
    vehicle: str
    message: Payload
    size: int
    received_ns: int

    @property
    def stamp_ns(self) -> int:
        """Acquisition time of the data; arrival time for hints, which carry none."""
        return self.message.stamp_ns if isinstance(self.message, Message) else self.received_ns

    def age_s(self, now_ns: int | None = None) -> float:
        """Seconds since acquisition."""
        return ((time.time_ns() if now_ns is None else now_ns) - self.stamp_ns) * 1e-9


class FleetBus:
    """One vehicle on the fleet bus; see the module docstring. Use as a context manager or call :meth:`close`.

    Parameters
    ----------
    session : zenoh.Session
        The process's session (one per process).
    fleet, vehicle : str
        Names (``protocol.check_name``).
    max_age_s : float or None
        Data older than the instant played (:attr:`playback`) are rejected as ``stale``; ``None`` keeps all.
    image_ring : int
        Newest image frames kept by the receiver; older ones are dropped (counted as ``overflow``).
    queue_size : int
        Capacity of the inbox and of each topic's :meth:`recv` queue.
    announce : bool
        Declare the liveliness token (a listener that is not a team-mate, like the meter, does not).
    stats_period_s : float or None
        Publish this agent's Stats every so often (and once at close).
    owns_session : bool
        Close ``session`` in :meth:`close`.
    """

    def __init__(self, session: zenoh.Session, fleet: str, vehicle: str, *, max_age_s: float | None = 1.0,
                 image_ring: int = 4, queue_size: int = 4096, announce: bool = True,
                 stats_period_s: float | None = None, on_join: PresenceHandler | None = None,
                 on_leave: PresenceHandler | None = None, owns_session: bool = False) -> None:
        self.session = session
        self.fleet, self.vehicle = check_name(fleet, "fleet"), check_name(vehicle, "vehicle")
        self.max_age_s, self.stats_period_s = max_age_s, stats_period_s
        #: The instant the vehicle plays (set by the frame loop; the receiver's threads judge staleness on it).
        self.playback = PlaybackClock()
        self.counters = TrafficCounters()
        self._owns_session = owns_session
        self._on_join, self._on_leave = on_join, on_leave
        self._queue_size, self._image_ring = queue_size, image_ring
        self._inbox = Inbox(queue_size, image_ring)
        self._budget = SenderBudget()
        self._senders = BoundedSenders()
        self._lock = threading.Lock()
        self._alive: set[str] = set()
        self._latest: dict[Topic, dict[str, Received]] = {topic: {} for topic in Topic}
        self._delivery: dict[Topic, deque[Received]] = {}
        self._delivered = threading.Condition(self._lock)
        self._handlers: dict[Topic, list[MessageHandler]] = {}
        self._last_seq: dict[tuple[Topic, str], int] = {}
        self._seq: dict[Topic, int] = {topic: 0 for topic in Topic}
        self._publishers: dict[Topic, zenoh.Publisher] = {}
        self._receivers: dict[Topic, TopicReceiver] = {}
        self._rejections = RateLimitedLog()
        self._closed = threading.Event()
        self._closing = False
        self._token: zenoh.LivelinessToken | None = None
        if announce:
            self.announce()
        self._presence = session.liveliness().declare_subscriber(alive_selector(fleet), self._on_presence,
                                                                 history=True)
        self._worker = threading.Thread(target=self._work, name=f"fleetbus-{vehicle}", daemon=True)
        self._worker.start()

    @classmethod
    def open(cls, options: SessionOptions, fleet: str, vehicle: str, **kwargs) -> "FleetBus":
        """Open the process's session from ``options`` and a bus that closes it."""
        check_name(fleet, "fleet"), check_name(vehicle, "vehicle")
        session = open_session(options)
        try:
            return cls(session, fleet, vehicle, owns_session=True, **kwargs)
        except BaseException:
            session.close()
            raise

    # -- presence ---------------------------------------------------------------------------

    def announce(self) -> None:
        """Declare this vehicle's liveliness token: team-mates see it present from now on. An agent opens its
        bus with ``announce=False``, declares its subscriptions, then announces, so that a team-mate that
        starts on seeing it present loses none of its first messages."""
        if self._token is None:
            self._token = self.session.liveliness().declare_token(alive_key(self.fleet, self.vehicle))

    def teammates(self) -> frozenset[str]:
        """Vehicles of the fleet whose liveliness token is present now (not this one)."""
        with self._lock:
            return frozenset(self._alive)

    def wait_for_teammates(self, wanted: Iterable[str] | int, timeout: float) -> bool:
        """Wait until the named team-mates (or at least ``wanted`` of them) are alive; False on timeout."""
        deadline = time.monotonic() + timeout
        while True:
            alive = self.teammates()
            if (len(alive) >= wanted) if isinstance(wanted, int) else set(wanted) <= alive:
                return True
            if time.monotonic() >= deadline or self._closed.is_set():
                return False
            time.sleep(0.01)

    def _on_presence(self, sample: zenoh.Sample) -> None:  # Zenoh thread: set update only
        try:
            _, vehicle = parse_alive_key(str(sample.key_expr))
        except ProtocolError:
            return
        if vehicle == self.vehicle:
            return
        joined = sample.kind == zenoh.SampleKind.PUT
        with self._lock:
            if joined:
                self._alive.add(vehicle)
            else:
                self._alive.discard(vehicle)
                for by_vehicle in self._latest.values():
                    by_vehicle.pop(vehicle, None)
            receivers = list(self._receivers.values())
        for receiver in receivers:  # a ring of its own for a team-mate, on each subscribed topic
            receiver.request("join" if joined else "leave", vehicle)
        self._inbox.put(("join" if joined else "leave", vehicle), force=True)

    # -- sending ----------------------------------------------------------------------------

    def header(self, topic: Topic | str, stamp_ns: int | None = None) -> dict:
        """``sender``, the next ``seq`` of ``topic`` and ``stamp_ns`` (default now) for a new message."""
        topic = check_topic(topic)
        with self._lock:
            seq = self._seq[topic]
            self._seq[topic] = seq + 1
        return {"sender": self.vehicle, "seq": seq, "stamp_ns": time.time_ns() if stamp_ns is None else stamp_ns}

    def publish(self, message: Payload) -> int:
        """Encode and publish ``message`` on this vehicle's key of its topic; the payload size in bytes."""
        if isinstance(message, Message) and message.sender != self.vehicle:
            raise ValueError(f"message sender {message.sender!r} is not this vehicle {self.vehicle!r}")
        return self.put_raw(message.TOPIC, encode(message))

    def send(self, message: Message | Hint) -> int:
        """Publish a message built before its number was known (``seq`` 0): it goes out as this vehicle's next of
        its topic; a :class:`protocol.hint.Hint` as its 24 bytes. The payload size in bytes."""
        if isinstance(message, Hint):
            return self.put_raw(Topic.HINT, message.payload())
        return self.publish(message.model_copy(update=self.header(message.TOPIC, message.stamp_ns)))

    def publish_hint(self, pose_world_from_target: np.ndarray) -> int:
        """Publish the 24-byte hint of ``pose_world_from_target`` ``(x, y, z, roll, pitch, yaw)``."""
        return self.put_raw(Topic.HINT, encode_hint(pose_world_from_target))

    def _publisher(self, topic: Topic) -> zenoh.Publisher:
        publisher = self._publishers.get(topic)
        if publisher is None:
            qos = QOS[topic]
            publisher = self._publishers[topic] = self.session.declare_publisher(
                topic_key(self.fleet, self.vehicle, topic),
                congestion_control=zenoh.CongestionControl.BLOCK if qos.block else zenoh.CongestionControl.DROP,
                express=qos.express, priority=getattr(zenoh.Priority, qos.priority))
        return publisher

    def wait_for_subscribers(self, topic: Topic | str, timeout: float) -> bool:
        """Wait until some subscriber matches this vehicle's ``topic`` key; False on timeout.

        Only that a subscriber exists: with several, the others may not be known yet.
        """
        publisher = self._publisher(check_topic(topic))
        deadline = time.monotonic() + timeout
        # zenoh-python 1.x returns a MatchingStatus object here (its stub says bool); the object itself is
        # always truthy, so testing it instead of its ``matching`` never waited at all
        while not publisher.matching_status.matching:
            if time.monotonic() >= deadline or self._closed.is_set():
                return False
            time.sleep(0.01)
        return True

    def put_raw(self, topic: Topic | str, payload: bytes) -> int:
        """Publish ``payload`` unchecked on this vehicle's ``topic`` key (for tools and fault injection)."""
        topic = check_topic(topic)
        self._publisher(topic).put(payload)
        self.counters.count_sent(topic.value, len(payload))
        return len(payload)

    def stats_message(self) -> Stats:
        """This agent's counters as a Stats message (not yet sent)."""
        snap = self.counters.snapshot()
        return Stats(**self.header(Topic.STATS), sent=snap["sent"], received=snap["received"],
                     bytes_sent=snap["bytes_sent"], bytes_received=snap["bytes_received"], rejected=snap["rejected"])

    def publish_stats(self) -> Stats:
        """Publish :meth:`stats_message` on ``evopose/<fleet>/<vehicle>/stats`` and return it."""
        stats = self.stats_message()
        self.publish(stats)
        return stats

    # -- receiving --------------------------------------------------------------------------

    def subscribe(self, topic: Topic | str, handler: MessageHandler | None = None, *,
                  include_self: bool = False) -> None:
        """Receive ``topic`` from every team-mate (and from this vehicle if ``include_self``).

        Messages are then available from :meth:`recv` and :meth:`latest`; ``handler`` (optional,
        may be given again to add more) is called in the worker thread for each one.
        """
        topic = check_topic(topic)
        with self._lock:
            if handler is not None:
                self._handlers.setdefault(topic, []).append(handler)
            if topic in self._receivers or self._closing:
                return
            self._delivery[topic] = deque(maxlen=self._image_ring if QOS[topic].ring else self._queue_size)
            receiver = self._receivers[topic] = TopicReceiver(
                self.session, self.fleet, self.vehicle, topic, include_self=include_self, budget=self._budget,
                inbox=self._inbox, alive=self._alive.__contains__, reject=self._reject, image_ring=self._image_ring)
            present = sorted(self._alive)
        for vehicle in present:  # team-mates present already; later ones come through _on_presence
            receiver.request("join", vehicle)

    def recv(self, topic: Topic | str, timeout: float | None = None) -> Received | None:
        """The oldest undelivered message of a subscribed ``topic``, waiting up to ``timeout`` s; None if none."""
        topic = check_topic(topic)
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._delivered:
            queue = self._delivery.get(topic)
            if queue is None:
                raise ValueError(f"not subscribed to {topic.value!r}; call subscribe first")
            while not queue:
                remaining = None if deadline is None else deadline - time.monotonic()
                if self._closed.is_set() or (remaining is not None and remaining <= 0):
                    return None
                self._delivered.wait(0.1 if remaining is None else min(remaining, 0.1))
            return queue.popleft()

    def latest(self, topic: Topic | str, *, max_age_s: float | None = None) -> dict[str, Received]:
        """Newest message of ``topic`` per team-mate, without those older than ``max_age_s`` (default the bus's)."""
        topic = check_topic(topic)
        max_age_s = self.max_age_s if max_age_s is None else max_age_s
        now_ns = self.playback.now_ns()
        with self._lock:
            return {vehicle: rx for vehicle, rx in self._latest[topic].items()
                    if max_age_s is None or rx.age_s(now_ns) <= max_age_s}

    def _reject(self, topic: Topic, reason: str, message: str) -> None:
        self.counters.count_rejected(topic.value, reason)
        self._rejections.warning(reason, message)

    # -- the worker ---------------------------------------------------------------------------

    def _work(self) -> None:
        next_stats = time.monotonic() + (self.stats_period_s or 0)
        while True:
            item = self._inbox.get(timeout=0.1)
            if item is None and self._closed.is_set():
                return  # closing, and everything received before is handled
            if item is not None:
                try:
                    self._handle(item)
                except Exception:  # a handler bug must not kill the receiver
                    log.exception("error while handling %s", item[:2])
            if self.stats_period_s and not self._closed.is_set() and time.monotonic() >= next_stats:
                next_stats = time.monotonic() + self.stats_period_s
                try:
                    self.publish_stats()
                except Exception as err:  # session closing
                    log.debug("stats not published: %s", err)

    def _handle(self, item: tuple) -> None:
        kind = item[0]
        if kind in ("join", "leave"):
            handler = self._on_join if kind == "join" else self._on_leave
            log.info("team-mate %s %s", item[1], "joined" if kind == "join" else "left")
            if handler is not None:
                handler(item[1])
            return
        _, topic, key, payload, received_ns, throttled = item
        try:
            key_parts, message = decode_sample(key, payload)
        except ProtocolError as err:
            self._reject(topic, err.reason, f"{key}: {err}")
            return
        rx = Received(topic, key_parts.vehicle, message, len(payload), received_ns)
        if isinstance(message, Message):
            now_ns = self.playback.now_ns(received_ns)
            if self.max_age_s is not None and rx.age_s(now_ns) > self.max_age_s:
                self._reject(topic, "stale", f"{key}: acquired {rx.age_s(now_ns):.3f} s ago (max {self.max_age_s} s)")
                return
            last = self._last_seq.get((topic, rx.vehicle))
            if last is not None and message.seq > last + 1:
                if throttled:  # overwritten in its ring while it sent over its budget: a flood, not the network
                    self.counters.count_rejected(topic.value, "rate-limited", message.seq - last - 1)
                else:
                    self.counters.count_lost(topic.value, message.seq - last - 1)
            self._last_seq[(topic, rx.vehicle)] = message.seq
        self.counters.count_received(topic.value, rx.size)
        with self._delivered:
            for gone in self._senders.seen(rx.vehicle):  # per-sender state is bounded: the longest silent goes
                for per_topic in self._latest.values():
                    per_topic.pop(gone, None)
                for seq_key in [k for k in self._last_seq if k[1] == gone]:
                    del self._last_seq[seq_key]
            self._latest[topic][rx.vehicle] = rx
            queue = self._delivery[topic]
            if len(queue) == queue.maxlen:  # the oldest is pushed out before recv() returned it
                self.counters.count_unread(topic.value)
            queue.append(rx)
            self._delivered.notify_all()
            handlers = list(self._handlers.get(topic, ()))
        for handler in handlers:
            handler(rx)

    # -- shutdown ---------------------------------------------------------------------------

    def close(self) -> None:
        """Publish final Stats (if periodic), stop receiving, handle what was received, undeclare the rest.

        Messages that reached this process before close are decoded, counted and delivered (to handlers
        and :meth:`recv`) before the worker stops, within :data:`DRAIN_S`.
        """
        if self._closed.is_set():
            return
        if self.stats_period_s:
            try:
                self.publish_stats()
            except Exception as err:
                log.debug("final stats not published: %s", err)
        if self._publishers:
            time.sleep(FLUSH_S)  # Zenoh has no flush: let the last messages leave before undeclaring
        self._undeclare(self._presence)
        deadline = time.monotonic() + DRAIN_S
        with self._lock:
            receivers = list(self._receivers.values())
            self._closing = True  # no more subscriptions
        for receiver in receivers:  # each hands what it holds to the inbox and undeclares its subscribers
            receiver.request("close")
        for receiver in receivers:
            receiver.join(max(deadline - time.monotonic(), 0.0))
        self._closed.set()  # the worker stops once the inbox is empty
        self._inbox.wake()
        with self._delivered:
            self._delivered.notify_all()
        if self._worker is not threading.current_thread():
            self._worker.join(timeout=max(deadline - time.monotonic(), 0.1))
        self._undeclare(*self._publishers.values(), self._token)
        self._publishers.clear()
        if self._owns_session:
            self.session.close()

    @staticmethod
    def _undeclare(*entities) -> None:
        for entity in entities:
            if entity is not None:
                try:
                    entity.undeclare()
                except Exception as err:  # already undeclared by a closed session
                    log.debug("undeclare: %s", err)

    def __enter__(self) -> "FleetBus":
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()
