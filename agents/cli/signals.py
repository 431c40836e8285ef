"""Clean shutdown on SIGINT / SIGTERM: the signal only sets an Event; the main loop checks it and returns."""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def stop_on_signals(signals: tuple[int, ...] = (signal.SIGINT, signal.SIGTERM)) -> Iterator[threading.Event]:
    """Within the block, SIGINT/SIGTERM set the yielded Event instead of killing the process.

    Must be entered in the main thread; the previous handlers come back on exit. A second signal
    while stopping is ignored, so ``with FleetBus(...)`` always gets to close the session.
    """
    stop = threading.Event()
    previous = {sig: signal.signal(sig, lambda *_: stop.set()) for sig in signals}
    try:
        yield stop
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
