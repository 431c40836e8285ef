"""The receive path of one subscribed topic: samples wait in Zenoh's ring channels and one thread pulls them at the
senders' rates, so what a flood sends beyond its budget is overwritten inside Zenoh and never reaches Python.

Why (issue 12): with a Python callback, Zenoh takes the GIL for every sample; 10 kHz of valid feature sets cost the
flooded vehicle most of its frames on 2 cores although every one of them was dropped after a few lines. A
``zenoh.handlers.RingChannel`` is filled by Zenoh's own threads (Rust, no GIL; when full the oldest sample goes)
and read here with ``try_recv``/``recv`` (the blocking ``recv`` releases the GIL while it waits).

Rings of a topic:

* **shared**: the topic's selector ``evopose/<fleet>/*/<topic>``, so every sender's samples land in it. It serves
  senders without a ring of their own (no presence token; team-mates beyond :data:`MAX_MATE_RINGS`; a team-mate's
  first samples, before its ring exists), and it is the doorbell: the thread blocks on it and wakes on any
  arrival. Its pulls are paced at the topic's per-sender rate times (1 + team-mates with a ring).
* **one per present team-mate**, on its exact key, declared when its presence token appears and undeclared when it
  goes. A team-mate's ring is pulled only while it has budget (``SenderBudget``), so a flooding team-mate
  overwrites its own ring and nobody else's: the others' messages wait in theirs.

A team-mate with a ring has its samples in both rings; the shared copy is skipped. The hand-over is marked in the
rings themselves: right after declaring the team-mate's ring the thread puts a session-local DELETE on its key,
with an attachment no remote sender can forge (a random nonce), which lands in both rings behind what was already
there: shared copies before it are handed on, after it skipped; the team-mate's ring is read once the shared ring
passed the marker, from its marker on. When the team-mate goes, another marker after its ring is undeclared ends
the skipping.

Zenoh dispatches a sample to matching subscribers one after the other, and the marker too, from another thread: a
sample dispatched while the marker is (this thread may be descheduled between the two rings for milliseconds) can
sit before the marker in one ring and after it in the other. The join is made exact by the samples pulled from the shared
ring since the team-mate's ring was declared, handed on or refused (their hashes, :attr:`_MateRing.handed`):
samples before the marker in the team-mate's ring that were not pulled (skipped in the shared ring) are handed on
from it, and its first samples after the marker that were pulled already are skipped (a refused one is counted
once). At a leave, a sample arriving in the
same instant may still be lost.

Counting: a sample pulled and refused is counted at once (``oversized``, ``rate-limited``, ``overflow``). Samples
overwritten in a team-mate's ring while it was over its budget are never seen; the first sample pulled after that
is flagged, and the worker counts its gap in ``seq`` as ``rate-limited`` instead of ``lost`` (likewise the first
sample admitted from the shared ring after it was left unread for want of pace). Hints carry no sequence number,
and a sender that changes its name on every message has no gap to show: their overwritten samples are not
counted.

The thread is the one writer of this receive path's state (its rings, the hand-over, the pacing); other threads
ask it to act (a team-mate joined or left, close) through a queue and a session-local marker that wakes it.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import zenoh

from protocol import QOS, SIZE_LIMITS, Topic, topic_key, topic_selector

from agents.transport.inbox import BURST_S, Inbox, SenderBudget

log = logging.getLogger("evopose.bus")

#: The budget key shared by every sender without a presence token (not a team-mate that announced itself).
UNKNOWN_SENDER = "@unknown"
#: Team-mates with a ring of their own, per topic; others share the shared ring (each with its own budget).
MAX_MATE_RINGS = 32
#: Bytes of largest valid payloads one ring may hold (its capacity in samples follows from the topic's size limit).
RING_BYTES = 4 * 1024 * 1024
#: Most samples one ring holds.
MAX_RING = 1024
#: After a team-mate's shared copy, its own sample is looked for (Zenoh may not have put it in the team-mate's ring
#: yet when the shared copy woke the thread): yielding the GIL only for SPIN_S, then every POLL_S up to OWED_S, s.
SPIN_S, POLL_S, OWED_S = 0.002, 0.0005, 0.02
#: A team-mate's ring is used after this long even if the shared ring's marker was overwritten (a flood), s.
HANDOVER_S = 0.5

_WAKE, _ROUTED, _UNROUTED = b"w", b"r", b"u"
_PUT = zenoh.SampleKind.PUT


def ring_capacity(topic: Topic, image_ring: int) -> int:
    """Samples a ring of ``topic`` holds: the newest ``image_ring`` images, else :data:`RING_BYTES` of largest
    payloads (28 feature sets, 1024 hints)."""
    if QOS[topic].ring:
        return max(1, image_ring)
    return int(min(MAX_RING, max(8, RING_BYTES // SIZE_LIMITS[topic])))


def _digest(sample: zenoh.Sample, limit: int) -> int:
    """A sample's identity in a join (:attr:`_MateRing.handed`): its payload's hash; a payload over ``limit`` bytes
    is never copied, only its size is."""
    size = len(sample.payload)
    return hash(("oversized", size)) if size > limit else hash(sample.payload.to_bytes())


class _Pace:
    """A token bucket for the shared ring's pulls."""

    def __init__(self, rate: float) -> None:
        self.rate, self.tokens, self.at = rate, rate * BURST_S, time.monotonic()

    def refill(self, now: float) -> None:
        self.tokens = min(self.rate * BURST_S, self.tokens + (now - self.at) * self.rate)
        self.at = now

    def wait_s(self) -> float:
        return 0.0 if self.tokens >= 1.0 else (1.0 - self.tokens) / self.rate


@dataclass
class _MateRing:
    vehicle: str
    key: str
    subscriber: zenoh.Subscriber
    declared: float
    past_marker: bool = False  #: its ring was read up to the hand-over marker (what came before is in the shared one)
    throttled: bool = False  #: it was over its budget since its last sample pulled: samples may be overwritten
    owed: int = 0  #: shared copies seen whose sample was not yet pulled from this ring
    #: digests (_digest) of its samples pulled from the shared ring since this ring was declared, handed on or refused
    #: (a refused one counted once); None once the join is over
    handed: set[int] | None = field(default_factory=set)


class TopicReceiver:
    """The receive path of one topic (see the module docstring); hands admitted samples to ``inbox`` as
    ``("sample", topic, key, payload bytes, received_ns, throttled)``.

    Parameters
    ----------
    alive : callable
        Whether a vehicle's presence token exists now (a sender without one shares :data:`UNKNOWN_SENDER`'s budget).
    reject : callable
        ``reject(topic, reason, message)``: count and log a refused sample.
    """

    def __init__(self, session: zenoh.Session, fleet: str, vehicle: str, topic: Topic, *, include_self: bool,
                 budget: SenderBudget, inbox: Inbox, alive: Callable[[str], bool],
                 reject: Callable[[Topic, str, str], None], image_ring: int) -> None:
        self.topic = topic
        self._session, self._fleet, self._budget, self._inbox = session, fleet, budget, inbox
        self._alive, self._reject = alive, reject
        self._limit, self._ring = SIZE_LIMITS[topic], QOS[topic].ring
        self._capacity = ring_capacity(topic, image_ring)
        self._nonce = os.urandom(16)
        self._wake_key = topic_key(fleet, vehicle, topic)
        self._own_key = None if include_self else self._wake_key
        self._commands: deque[tuple] = deque()
        self._mates: dict[str, _MateRing] = {}
        self._routed: dict[str, float] = {}  # team-mates whose shared copies are skipped -> when (unrouting) ends
        self._owed_at = self._owed_until = 0.0
        self._pace = _Pace(budget.rate(topic))
        self._shared_throttled = False
        self._shared_dropped = False  # the shared ring was left unread for want of pace since the last admitted sample
        self._finished = False
        self.done = threading.Event()  #: set once the thread has stopped and undeclared its subscribers
        self._shared = session.declare_subscriber(topic_selector(fleet, topic),
                                                  zenoh.handlers.RingChannel(self._capacity))
        self._thread = threading.Thread(target=self._run, name=f"fleetbus-rx-{topic.value}", daemon=True)
        self._thread.start()

    # -- asked by other threads ----------------------------------------------------------------

    def request(self, *command) -> None:
        """Ask the thread to act: ``("join", vehicle)``, ``("leave", vehicle)`` or ``("close",)``."""
        self._commands.append(command)
        self._mark(self._wake_key, _WAKE)

    def join(self, timeout: float) -> bool:
        """Wait for the thread to stop (after ``request("close")``); False on timeout."""
        if self._thread is not threading.current_thread():
            self._thread.join(timeout)
        return not self._thread.is_alive()

    # -- the thread ------------------------------------------------------------------------------

    def _mark(self, key: str, what: bytes) -> None:
        """A session-local DELETE on ``key`` that only this receiver recognises (it never leaves the process)."""
        try:
            self._session.delete(key, attachment=self._nonce + what,
                                 allowed_destination=zenoh.Locality.SESSION_LOCAL)
        except Exception as err:  # the session is closing
            log.debug("marker not put on %s: %s", key, err)

    def _marker(self, sample: zenoh.Sample) -> bytes | None:
        if sample.kind == _PUT or sample.attachment is None:
            return None
        data = sample.attachment.to_bytes()
        return data[len(self._nonce):] if data[:len(self._nonce)] == self._nonce else None

    def _run(self) -> None:
        try:
            while True:
                while self._commands:
                    self._command(self._commands.popleft())
                if self._finished:
                    return
                now = time.monotonic()
                if self._pull_shared(now) + self._pull_mates(now):
                    continue
                wait = self._idle_wait(time.monotonic())
                if wait is not None:
                    time.sleep(wait)
                    continue
                sample = self._shared.recv()  # blocks, the GIL released, until any sample or a marker arrives
                self._pace.refill(time.monotonic())
                self._on_shared(sample, time.monotonic())
        except zenoh.ZError as err:  # the session was closed under us
            log.debug("receiver of %s stopped: %s", self.topic.value, err)
        except Exception:  # a bug here must not go unnoticed, but the bus closes cleanly
            log.exception("receiver of %s stopped", self.topic.value)
        finally:
            self._undeclare(self._shared, *(mate.subscriber for mate in self._mates.values()))
            self._mates.clear()
            self.done.set()

    def _command(self, command: tuple) -> None:
        what = command[0]
        if what == "join":
            self._join(command[1])
        elif what == "leave":
            self._leave(command[1])
        elif what == "close":
            now = time.monotonic()  # what arrived before close is handled (within the budgets)
            self._drain(self._shared, now, self._on_shared)
            for mate in list(self._mates.values()):
                if mate.vehicle in self._routed and self._ready(mate, now):
                    self._drain(mate.subscriber, now, lambda sample, now, mate=mate: self._on_mate(mate, sample, now))
            self._finished = True

    def _drain(self, subscriber, now: float, handle) -> None:
        for _ in range(self._capacity + 1):
            sample = subscriber.try_recv()
            if sample is None:
                return
            if subscriber is self._shared:
                self._pace.tokens = max(self._pace.tokens, 1.0)  # closing: no pacing, the budgets still apply
            handle(sample, now)

    def _join(self, vehicle: str) -> None:
        if vehicle in self._mates or len(self._mates) >= MAX_MATE_RINGS:
            return
        key = topic_key(self._fleet, vehicle, self.topic)
        if key == self._own_key:
            return
        subscriber = self._session.declare_subscriber(key, zenoh.handlers.RingChannel(self._capacity))
        self._mates[vehicle] = _MateRing(vehicle, key, subscriber, time.monotonic())
        self._mark(key, _ROUTED)  # behind what is already in the shared ring: copies after it are skipped
        self._pace.rate = self._budget.rate(self.topic) * (1 + len(self._mates))

    def _leave(self, vehicle: str) -> None:
        mate = self._mates.get(vehicle)
        if mate is None:
            return
        now = time.monotonic()
        if vehicle in self._routed and self._ready(mate, now):  # what it sent before it left, within its budget
            self._drain(mate.subscriber, now, lambda sample, now: self._on_mate(mate, sample, now))
        del self._mates[vehicle]
        self._undeclare(mate.subscriber)
        if vehicle in self._routed:  # copies still in the shared ring are skipped until the marker
            self._routed[vehicle] = now + HANDOVER_S
            self._mark(mate.key, _UNROUTED)
        self._pace.rate = self._budget.rate(self.topic) * (1 + len(self._mates))

    def _pull_shared(self, now: float) -> int:
        self._pace.refill(now)
        self._shared_throttled = False
        pulled = 0
        while True:
            if self._pace.tokens < 1.0:
                self._shared_throttled = self._shared_dropped = True
                return pulled
            sample = self._shared.try_recv()
            if sample is None:
                return pulled
            pulled += 1
            self._on_shared(sample, now)

    def _on_shared(self, sample: zenoh.Sample, now: float) -> None:
        self._pace.tokens -= 1.0
        if sample.kind != _PUT:
            marker = self._marker(sample)
            if marker in (_ROUTED, _UNROUTED):
                vehicle = str(sample.key_expr).split("/")[2]
                if marker == _UNROUTED:
                    self._routed.pop(vehicle, None)
                elif vehicle in self._mates:
                    self._routed[vehicle] = float("inf")
            return
        key = str(sample.key_expr)
        if key == self._own_key:
            return
        parts = key.split("/")
        vehicle = parts[2] if len(parts) > 3 else ""
        until = self._routed.get(vehicle)
        if until is not None:
            if now < until:  # a copy of what the team-mate's own ring got
                mate = self._mates.get(vehicle)
                if mate is not None:
                    mate.owed += 1
                    self._owed_at, self._owed_until = time.monotonic(), now + OWED_S
                return
            del self._routed[vehicle]  # the unrouting marker was overwritten (a flood): end the skipping now
        mate = self._mates.get(vehicle)
        if mate is not None and mate.handed is not None:  # its ring is declared: the join is under way, and what is
            mate.handed.add(_digest(sample, self._limit))  # pulled here, handed on or refused, is not pulled again
        if self._admit(sample, key, key if self._alive(vehicle) else UNKNOWN_SENDER, self._shared_dropped) is not None:
            self._shared_dropped = False

    def _ready(self, mate: _MateRing, now: float) -> bool:
        """Whether the team-mate's own ring is read now: once the shared ring passed its marker (or that marker was
        overwritten in a flood), from its own marker on."""
        if mate.vehicle not in self._routed:
            if now - mate.declared < HANDOVER_S:
                return False  # its samples still come through the shared ring, up to the marker
            self._routed[mate.vehicle] = float("inf")  # the marker was overwritten in a full shared ring
        if not mate.past_marker:  # what its ring got before the marker was handed on from the shared ring, except
            for _ in range(self._capacity + 1):  # what the shared ring got after its marker (see the docstring)
                sample = mate.subscriber.try_recv()
                if sample is None or self._marker(sample) == _ROUTED:
                    break  # (an empty ring without the marker: it was overwritten, and what followed is skipped)
                if sample.kind == _PUT and _digest(sample, self._limit) not in mate.handed:
                    self._on_mate(mate, sample, now)
            mate.past_marker = True
        return True

    def _pull_mates(self, now: float) -> int:
        pulled = 0
        for mate in list(self._mates.values()):
            if not self._ready(mate, now):
                continue
            while True:
                if self._budget.wait_s(self.topic, mate.key, now) > 0.0:
                    mate.throttled = True
                    break
                sample = mate.subscriber.try_recv()
                if sample is None:
                    break
                pulled += 1
                self._on_mate(mate, sample, now)
        return pulled

    def _on_mate(self, mate: _MateRing, sample: zenoh.Sample, now: float) -> None:
        mate.owed = max(0, mate.owed - 1)
        if sample.kind != _PUT:  # its marker, or a DELETE
            return
        if mate.handed is not None and mate.past_marker:  # its first samples after the marker: handed on already?
            if _digest(sample, self._limit) in mate.handed:
                return
            mate.handed = None  # the first one that was not: the join is over
        if self._admit(sample, mate.key, mate.key, mate.throttled) is not None:
            mate.throttled = False

    def _idle_wait(self, now: float) -> float | None:
        """How long to sleep before pulling again (a ring over its budget, a team-mate's sample on its way), or None
        to block on the shared ring."""
        waits = []
        if self._shared_throttled:
            waits.append(self._pace.wait_s())
        for mate in self._mates.values():
            if mate.vehicle not in self._routed:
                continue
            if mate.throttled:
                waits.append(self._budget.wait_s(self.topic, mate.key, now))
            elif mate.owed and now < self._owed_until:
                waits.append(0.0 if now - self._owed_at < SPIN_S else POLL_S)
            else:
                mate.owed = 0
        return min(waits) if waits else None

    def _admit(self, sample: zenoh.Sample, key: str, sender: str, throttled: bool) -> bytes | None:
        """Check ``sample`` cheaply and hand its bytes to the inbox; the bytes if they went in, else None."""
        topic = self.topic
        size = len(sample.payload)
        if size > self._limit:
            self._reject(topic, "oversized", f"{key}: payload of {size} bytes exceeds the {self._limit}-byte limit")
            return None
        if not self._budget.admit(topic, sender, time.monotonic()):  # dropped before any decoding
            self._reject(topic, "rate-limited", f"{key}: over {self._budget.rate(topic):g} messages/s")
            return None
        payload = sample.payload.to_bytes()
        item = ("sample", topic, key, payload, time.time_ns(), throttled)
        if not self._inbox.put(item, ring=self._ring):
            self._reject(topic, "overflow", f"{key}: receiver queue full, "
                                            f"{'oldest frame' if self._ring else 'sample'} dropped")
            return None
        return payload

    @staticmethod
    def _undeclare(*subscribers) -> None:
        for subscriber in subscribers:
            try:
                subscriber.undeclare()
            except Exception as err:  # already undeclared by a closed session
                log.debug("undeclare: %s", err)


__all__ = ["MAX_MATE_RINGS", "TopicReceiver", "UNKNOWN_SENDER", "ring_capacity"]
