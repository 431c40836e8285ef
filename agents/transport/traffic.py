"""Thread-safe traffic counters of one agent, and a rate-limited log of rejections."""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from dataclasses import dataclass, field

log = logging.getLogger("evopose.bus")


@dataclass
class TrafficCounters:
    """Messages and payload bytes sent and received per topic name, rejections per reason and per topic."""

    sent: Counter = field(default_factory=Counter)
    received: Counter = field(default_factory=Counter)
    bytes_sent: Counter = field(default_factory=Counter)
    bytes_received: Counter = field(default_factory=Counter)
    rejected: Counter = field(default_factory=Counter)          #: reason -> count
    rejected_by_topic: Counter = field(default_factory=Counter)  #: topic -> count
    lost: Counter = field(default_factory=Counter)              #: topic -> messages missing by ``seq``
    unread: Counter = field(default_factory=Counter)            #: topic -> pushed out of a full recv() queue
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def count_sent(self, topic: str, size: int) -> None:
        with self._lock:
            self.sent[topic] += 1
            self.bytes_sent[topic] += size

    def count_received(self, topic: str, size: int) -> None:
        with self._lock:
            self.received[topic] += 1
            self.bytes_received[topic] += size

    def count_rejected(self, topic: str, reason: str, count: int = 1) -> None:
        with self._lock:
            self.rejected[reason] += count
            self.rejected_by_topic[topic] += count

    def count_lost(self, topic: str, missing: int) -> None:
        with self._lock:
            self.lost[topic] += missing

    def count_unread(self, topic: str) -> None:
        with self._lock:
            self.unread[topic] += 1

    def snapshot(self) -> dict[str, dict[str, int]]:
        """A copy of every table, as plain dicts (JSON-ready)."""
        with self._lock:
            return {name: dict(getattr(self, name)) for name in
                    ("sent", "received", "bytes_sent", "bytes_received", "rejected", "rejected_by_topic", "lost",
                     "unread")}


class RateLimitedLog:
    """Log at most one warning per ``interval_s`` per reason; say how many were suppressed."""

    def __init__(self, interval_s: float = 5.0, logger: logging.Logger = log) -> None:
        self.interval_s, self.logger = interval_s, logger
        self._last: dict[str, float] = {}
        self._suppressed: Counter = Counter()
        self._lock = threading.Lock()

    def warning(self, reason: str, message: str) -> None:
        now = time.monotonic()
        with self._lock:
            if now - self._last.get(reason, -1e9) < self.interval_s:
                self._suppressed[reason] += 1
                return
            self._last[reason] = now
            suppressed, self._suppressed[reason] = self._suppressed[reason], 0
        more = f" ({suppressed} more suppressed)" if suppressed else ""
        self.logger.warning("rejected (%s): %s%s", reason, message, more)
