"""The instant a vehicle plays, against which team-mates' data are judged stale: the wall clock, or behind it by a
lag when the vehicle plays a recording slower than it was taken (agents/vehicle/dataset_source.py).

While a vehicle works on a frame the instant it plays runs on with the wall clock, but never past the next frame's
instant: a vehicle behind a recording plays that frame next, whatever the wall clock reads by then. So a frame that
takes longer than ``--max-age`` (a loaded machine) does not make a team-mate's view of that very instant stale."""

from __future__ import annotations

import threading
import time


class PlaybackClock:
    """The wall clock less a lag, up to a bound. One writer (the vehicle's frame loop: :meth:`play_behind`),
    readers on the bus's threads (:meth:`now_ns`): lag and bound are read and written under the clock's own lock."""

    def __init__(self) -> None:
        self._lag_ns = 0
        self._until_ns: int | None = None
        self._lock = threading.Lock()

    def play_behind(self, lag_ns: int, until_ns: int | None = None) -> None:
        """The vehicle now plays ``lag_ns`` behind the wall clock (0 or less: on it), up to ``until_ns`` (ns since
        the epoch: the instant of the frame it plays next; ``None``: no bound)."""
        with self._lock:
            self._lag_ns = max(0, int(lag_ns))
            self._until_ns = None if until_ns is None else int(until_ns)

    def now_ns(self, wall_ns: int | None = None) -> int:
        """The instant played when the wall clock reads ``wall_ns`` (default now), ns since the epoch."""
        with self._lock:
            lag_ns, until_ns = self._lag_ns, self._until_ns
        played = (time.time_ns() if wall_ns is None else wall_ns) - lag_ns
        return played if until_ns is None else min(played, until_ns)


__all__ = ["PlaybackClock"]
