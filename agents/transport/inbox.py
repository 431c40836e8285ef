"""What the fleet bus admits, in bounded memory: the hand-off queue from the receivers to the worker, a per-sender
rate budget that drops floods before they are decoded, and a bounded set of senders.

Anything received is untrusted (docs/design.md §4): a flood of valid messages from one sender, or messages under a
new sender name each time, must cost a counter, not the vehicle's frame rate or its memory.
"""

from __future__ import annotations

import threading
from collections import OrderedDict, deque

from protocol import Topic

#: Most messages per second one sender may send on a topic (a camera at up to 100 fps; hints at the paper's
#: >100 Hz with room; Stats about once a second). Over it a message is dropped, counted as ``rate-limited``.
RATE_PER_SENDER = {Topic.IMAGE: 100.0, Topic.FEATURES: 100.0, Topic.HINT: 1000.0, Topic.ATTITUDE: 200.0,
                   Topic.POSE: 200.0, Topic.STATS: 20.0}
#: Burst a sender may send at once before its rate applies, in seconds of its rate.
BURST_S = 1.0
#: Senders whose state (rate budget, latest message, sequence number) is kept; beyond, the longest silent goes.
MAX_SENDERS = 128


class Inbox:
    """Bounded hand-off from the receivers (``agents.transport.receiver``) and the presence callback to the worker: a
    FIFO, plus a ring for images."""

    def __init__(self, fifo_size: int, ring_size: int) -> None:
        self.fifo: deque = deque()
        self.ring: deque = deque(maxlen=ring_size)
        self.fifo_size = fifo_size
        self.ready = threading.Condition()

    def put(self, item: tuple, *, ring: bool = False, force: bool = False) -> bool:
        """Queue ``item``; False if it (or, for the ring, the oldest frame) had to be dropped."""
        with self.ready:
            if ring:
                kept = len(self.ring) < (self.ring.maxlen or 0)
                self.ring.append(item)
            else:
                kept = force or len(self.fifo) < self.fifo_size
                if kept:
                    self.fifo.append(item)
            self.ready.notify()
        return kept

    def get(self, timeout: float) -> tuple | None:
        with self.ready:
            if not self.fifo and not self.ring:
                self.ready.wait(timeout)
            if self.fifo:
                return self.fifo.popleft()
            if self.ring:
                return self.ring.popleft()
            return None

    def wake(self) -> None:
        with self.ready:
            self.ready.notify_all()


class SenderBudget:
    """Token buckets per (topic, sender key), at most :data:`MAX_SENDERS` per topic (the least recent go)."""

    def __init__(self, rates: dict[Topic, float] | None = None, max_senders: int = MAX_SENDERS) -> None:
        self._rates = dict(RATE_PER_SENDER if rates is None else rates)
        self._max = max_senders
        self._buckets: dict[Topic, OrderedDict[str, list[float]]] = {}
        self._lock = threading.Lock()

    def rate(self, topic: Topic) -> float:
        return self._rates.get(topic, 100.0)

    def wait_s(self, topic: Topic, key: str, now_s: float) -> float:
        """Seconds until a message on ``key`` may pass (0 if now); spends nothing."""
        rate = self.rate(topic)
        with self._lock:
            bucket = self._buckets.get(topic, {}).get(key)
            if bucket is None:
                return 0.0
            tokens = min(rate * BURST_S, bucket[0] + (now_s - bucket[1]) * rate)
        return 0.0 if tokens >= 1.0 else (1.0 - tokens) / rate

    def admit(self, topic: Topic, key: str, now_s: float) -> bool:
        """Whether a message on ``key`` may pass now (one token spent), or is over its sender's rate."""
        rate = self.rate(topic)
        with self._lock:
            buckets = self._buckets.setdefault(topic, OrderedDict())
            bucket = buckets.get(key)
            if bucket is None:
                bucket = buckets[key] = [rate * BURST_S, now_s]
                if len(buckets) > self._max:
                    buckets.popitem(last=False)
            else:
                buckets.move_to_end(key)
                bucket[0] = min(rate * BURST_S, bucket[0] + (now_s - bucket[1]) * rate)
                bucket[1] = now_s
            if bucket[0] < 1.0:
                return False
            bucket[0] -= 1.0
            return True


class BoundedSenders:
    """The senders heard from, most recent last; :meth:`seen` returns those pushed out beyond ``max_senders``."""

    def __init__(self, max_senders: int = MAX_SENDERS) -> None:
        self._order: OrderedDict[str, None] = OrderedDict()
        self._max = max_senders

    def seen(self, sender: str) -> list[str]:
        self._order[sender] = None
        self._order.move_to_end(sender)
        gone = []
        while len(self._order) > self._max:
            gone.append(self._order.popitem(last=False)[0])
        return gone


__all__ = ["BURST_S", "BoundedSenders", "Inbox", "MAX_SENDERS", "RATE_PER_SENDER", "SenderBudget"]
