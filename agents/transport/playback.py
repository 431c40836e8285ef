"""The instant a vehicle plays, against which team-mates' data are judged stale: the wall clock, or behind it by a
lag when the vehicle plays a recording slower than it was taken (agents/vehicle/dataset_source.py)."""

from __future__ import annotations

import threading
import time


class PlaybackClock:
    """The wall clock less a lag. One writer (the vehicle's frame loop: :meth:`play_behind`), readers on the bus's
    threads (:meth:`now_ns`): the lag is read and written under the clock's own lock."""

    def __init__(self) -> None:
        self._lag_ns = 0
        self._lock = threading.Lock()

    def play_behind(self, lag_ns: int) -> None:
        """The vehicle now plays ``lag_ns`` behind the wall clock (0 or less: on it)."""
        with self._lock:
            self._lag_ns = max(0, int(lag_ns))

    def now_ns(self, wall_ns: int | None = None) -> int:
        """The instant played when the wall clock reads ``wall_ns`` (default now), ns since the epoch."""
        with self._lock:
            lag_ns = self._lag_ns
        return (time.time_ns() if wall_ns is None else wall_ns) - lag_ns


__all__ = ["PlaybackClock"]
