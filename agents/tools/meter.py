"""The rate and bandwidth meter: what ``ros2 topic hz`` and ``ros2 topic bw`` report, per key.

The Zenoh callback only appends ``(arrival time, payload size)`` to the key's window (and copies
Stats payloads, which are decoded later in the report loop). Once a second the meter reports, per
key: average rate over the window, min/max/std dev of the period, window size, bandwidth (mean
size x rate) and mean/min/max payload size; at the end, totals and the agents' own Stats.
``ros2_hz`` and ``ros2_bw`` are the numbers ``ros2 topic hz`` and ``ros2 topic bw`` print, computed as ros2cli does
(ros2topic/verb/hz.py and bw.py: ``window`` periods; bandwidth = the window's bytes over the time from its first
arrival to now, so it falls when a topic stops), and :func:`ros2_hz_line` / :func:`ros2_bw_line` their exact lines.
"""

from __future__ import annotations

import math
import statistics
import threading
import time
from collections import deque
from dataclasses import dataclass, field

import zenoh

from protocol import ProtocolError, Stats, Topic, decode_sample, fleet_selector


@dataclass
class KeyWindow:
    """The last ``size`` arrivals on one key, and totals since the meter started."""

    size: int
    arrivals_s: deque = field(default_factory=deque)  #: monotonic arrival times, s
    sizes: deque = field(default_factory=deque)       #: payload sizes, bytes
    count: int = 0
    total_bytes: int = 0

    def add(self, arrival_s: float, size: int) -> None:
        if len(self.arrivals_s) == self.size + 1:  # ``ros2 topic hz`` keeps ``size`` periods: size + 1 arrivals
            self.arrivals_s.popleft()
            self.sizes.popleft()
        self.arrivals_s.append(arrival_s)
        self.sizes.append(size)
        self.count += 1
        self.total_bytes += size

    def report(self, now_s: float) -> dict:
        """Rate (Hz), period min/max/std (s), window, bandwidth (B/s), sizes (B), age of the last message (s)."""
        all_times = list(self.arrivals_s)
        times, sizes = all_times[-self.size:], list(self.sizes)[-self.size:]
        periods = [b - a for a, b in zip(times, times[1:])]
        span = times[-1] - times[0] if len(times) > 1 else 0.0
        rate = (len(times) - 1) / span if span > 0 else 0.0
        mean_size = sum(sizes) / len(sizes)
        return {
            "rate_hz": rate,
            "period_min_s": min(periods) if periods else None,
            "period_max_s": max(periods) if periods else None,
            "period_std_s": statistics.pstdev(periods) if len(periods) > 1 else 0.0 if periods else None,
            "window": len(times),
            "bandwidth_Bps": mean_size * rate,
            "size_mean": mean_size, "size_min": min(sizes), "size_max": max(sizes),
            "count": self.count, "total_bytes": self.total_bytes,
            "age_s": now_s - times[-1],
            "ros2_hz": ros2_hz(all_times), "ros2_bw": ros2_bw(times, sizes, now_s),
        }


def ros2_hz(arrivals_s: list[float]) -> dict | None:
    """``ros2 topic hz`` over these arrivals (ros2cli ``ROSTopicHz.get_hz``): rate = 1 / mean period, min, max and
    population std dev of the periods, window = number of periods; None with fewer than two arrivals."""
    periods = [b - a for a, b in zip(arrivals_s, arrivals_s[1:])]
    if not periods:
        return None
    mean = sum(periods) / len(periods)
    return {"rate": 1.0 / mean if mean > 0 else 0.0, "min": min(periods), "max": max(periods),
            "std_dev": math.sqrt(sum((p - mean) ** 2 for p in periods) / len(periods)), "window": len(periods)}


def ros2_bw(arrivals_s: list[float], sizes: list[int], now_s: float) -> dict | None:
    """``ros2 topic bw`` (ros2cli ``ROSTopicBandwidth.get_bw``): the sum of the window's sizes over the time from its
    first arrival to now (so it falls when a topic stops), the number of messages, mean, min and max size."""
    if len(arrivals_s) < 2 or now_s <= arrivals_s[0]:
        return None
    total = sum(sizes)
    return {"bytes_per_s": total / (now_s - arrivals_s[0]), "messages": len(sizes), "mean": total / len(sizes),
            "min": min(sizes), "max": max(sizes)}


def ros2_hz_line(hz: dict) -> str:
    """The lines ``ros2 topic hz`` prints (ros2cli ``print_hz``)."""
    return ("average rate: %.3f\n\tmin: %.3fs max: %.3fs std dev: %.5fs window: %s"
            % (hz["rate"], hz["min"], hz["max"], hz["std_dev"], hz["window"]))


def ros2_bw_line(bw: dict) -> str:
    """The lines ``ros2 topic bw`` prints (ros2cli ``print_bw``: one unit for all four numbers, chosen by the
    bandwidth: B without decimals, KB or MB, powers of 1000, with two)."""
    rate = bw["bytes_per_s"]
    if rate < 1000:
        unit = lambda b: f"{b:.0f} B"  # noqa: E731
    elif rate < 1000000:
        unit = lambda b: f"{b / 1000:.2f} KB"  # noqa: E731
    else:
        unit = lambda b: f"{b / 1000 / 1000:.2f} MB"  # noqa: E731
    return (f"{unit(rate)}/s from {bw['messages']} messages\n"
            f"\tMessage size mean: {unit(bw['mean'])} min: {unit(bw['min'])} max: {unit(bw['max'])}")


class Meter:
    """Subscribes to every data key of ``fleet`` (of every fleet when None) on ``session``."""

    def __init__(self, session: zenoh.Session, fleet: str | None = None, window: int = 100) -> None:
        if window < 2:
            raise ValueError(f"window must be at least 2 messages, got {window}")
        self.window = window
        self.started_s = time.monotonic()
        self._keys: dict[str, KeyWindow] = {}
        self._stats_payloads: deque[tuple[str, bytes]] = deque(maxlen=1000)
        self.agents: dict[str, dict] = {}
        self._lock = threading.Lock()
        self._subscriber = session.declare_subscriber(fleet_selector(fleet), self._on_sample)

    def _on_sample(self, sample: zenoh.Sample) -> None:  # Zenoh thread: append only
        if sample.kind != zenoh.SampleKind.PUT:
            return
        key, size, now = str(sample.key_expr), len(sample.payload), time.monotonic()
        with self._lock:
            window = self._keys.get(key)
            if window is None:
                window = self._keys[key] = KeyWindow(self.window)
            window.add(now, size)
        if key.endswith("/" + Topic.STATS.value) and size <= 16384:
            self._stats_payloads.append((key, sample.payload.to_bytes()))

    def _collect_stats(self) -> None:
        while self._stats_payloads:
            key, payload = self._stats_payloads.popleft()
            try:
                parts, stats = decode_sample(key, payload)
            except ProtocolError:
                continue
            assert isinstance(stats, Stats)
            self.agents[f"{parts.fleet}/{parts.vehicle}"] = stats.model_dump(
                include={"seq", "sent", "received", "bytes_sent", "bytes_received", "rejected"})

    def report(self) -> list[dict]:
        """One record per key seen so far, sorted by key."""
        self._collect_stats()
        now = time.monotonic()
        with self._lock:
            return [{"key": key, "t_s": now - self.started_s, **window.report(now)}
                    for key, window in sorted(self._keys.items())]

    def close(self) -> None:
        self._subscriber.undeclare()
        self._collect_stats()
