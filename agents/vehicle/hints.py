"""Team-mates' hints between their arrival (a bus worker thread) and their use (the frame loop): which are kept.

The bus's worker appends each plausible hint; the frame loop takes them all at its next frame or generation. Only
the newest :data:`HINTS_KEPT` wait (older ones are dropped, counted); the newest one is also kept apart, for the
next frame to weigh against its own best (:data:`agents.vehicle.step.HINT_MARGIN`), even when a generation between
frames took the batch first.
"""

from __future__ import annotations

import threading

import numpy as np

#: Hints kept while waiting for the next frame or generation (the newest).
HINTS_KEPT = 64


class HintInbox:
    """Hints (6,) from team-mates, thread-safe: :meth:`put` from the bus, :meth:`take_all` / :meth:`take_latest`
    from the frame loop."""

    def __init__(self, kept: int = HINTS_KEPT) -> None:
        self.kept = kept
        self._lock = threading.Lock()
        self._hints: list[np.ndarray] = []
        self._latest: np.ndarray | None = None
        self.dropped = 0  #: hints dropped because newer ones filled the inbox

    def put(self, pose: np.ndarray) -> None:
        pose = np.asarray(pose, float)
        with self._lock:
            self._latest = pose
            self._hints.append(pose)
            if len(self._hints) > self.kept:
                self.dropped += len(self._hints) - self.kept
                del self._hints[:-self.kept]

    def take_all(self) -> np.ndarray | None:
        """Every hint waiting, oldest first, shape (H, 6); None when there is none."""
        with self._lock:
            hints, self._hints = self._hints, []
        return np.array(hints) if hints else None

    def take_latest(self) -> np.ndarray | None:
        """The newest hint since the last call (kept after :meth:`take_all` took it), then forgotten."""
        with self._lock:
            hint, self._latest = self._latest, None
        return hint


__all__ = ["HINTS_KEPT", "HintInbox"]
