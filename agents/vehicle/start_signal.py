"""Frame 0 once every agent of a run is warm: ``evopose agent --epoch-from-stdin``.

A fleet's agents share one frame clock (:mod:`agents.vehicle.frames`): frame ``n`` at ``epoch + n / fps``. Given with
``--epoch-ns`` when the agents start, the epoch must lie far enough ahead for the slowest to import and warm up on a
loaded machine, a guess that wastes seconds on a fast one and loses frame 0 on a slow one. With
``--epoch-from-stdin`` the agent warms up, says so (a ``warm`` record), and waits for one line on its standard input:
the epoch, which its launcher (``evopose scenario run``) writes to every agent of the run once all of them are warm.
"""

from __future__ import annotations

import os
import select
import threading
import time

from agents.errors import FleetError

#: A launcher's epoch lies this long after its last agent said ``warm`` (s): each agent then builds its vehicle and
#: meets its team-mates over sessions already connected (~10 ms alone here).
RELEASE_MARGIN_S = 1.0
#: How long an agent waits for its epoch before it gives up (s): longer than any team's warm-up.
EPOCH_WAIT_S = 300.0
#: An epoch further than this from the agent's clock (s) is refused: a launcher's epoch is seconds ahead.
MAX_EPOCH_OFFSET_S = 3600.0
#: Longest line read (bytes): an int64 of nanoseconds and a newline fit many times over.
MAX_LINE_BYTES = 64


def release_line(margin_s: float = RELEASE_MARGIN_S) -> tuple[int, str]:
    """The epoch a launcher gives its warm agents, ``margin_s`` from now, and the line that carries it (what
    :func:`read_epoch` reads)."""
    epoch_ns = time.time_ns() + int(margin_s * 1e9)
    return epoch_ns, f"{epoch_ns}\n"


def parse_epoch(line: bytes, now_ns: int) -> int:
    """The epoch (ns since the Unix epoch) of one line from the launcher; :class:`FleetError` naming what was wrong."""
    text = line.decode("ascii", errors="replace").strip()
    what = ("--epoch-from-stdin: expected one line holding the fleet clock's epoch (an integer, ns since the Unix "
            "epoch)")
    try:
        epoch = int(text)
    except ValueError:
        raise FleetError(f"{what}, got {text[:40]!r}") from None
    if abs(epoch - now_ns) > MAX_EPOCH_OFFSET_S * 1e9:
        raise FleetError(f"{what} within {MAX_EPOCH_OFFSET_S:g} s of this machine's clock, got {epoch} "
                         f"({(epoch - now_ns) / 1e9:+.0f} s)")
    return epoch


def read_epoch(stop: threading.Event, fd: int = 0, timeout_s: float = EPOCH_WAIT_S) -> int | None:
    """Wait for the epoch's line on file descriptor ``fd`` (standard input); None when ``stop`` is set first.

    Raises
    ------
    FleetError
        The input ended, or held no epoch, or none came within ``timeout_s`` (one line naming it).
    """
    deadline = time.monotonic() + timeout_s
    line = b""
    while b"\n" not in line:
        if stop.is_set():
            return None
        left = deadline - time.monotonic()
        if left <= 0:
            raise FleetError(f"--epoch-from-stdin: no epoch on standard input within {timeout_s:g} s")
        ready, _, _ = select.select([fd], [], [], min(left, 0.2))
        if not ready:
            continue
        chunk = os.read(fd, MAX_LINE_BYTES)
        if not chunk:
            if stop.is_set():   # stopped, and the launcher closed the input as it stopped
                return None
            if line.strip():
                break   # the last line without its newline
            raise FleetError("--epoch-from-stdin: standard input ended before an epoch came (was the launcher "
                             "stopped?)")
        line += chunk
        if len(line) > MAX_LINE_BYTES:
            raise FleetError(f"--epoch-from-stdin: expected one line of at most {MAX_LINE_BYTES} bytes, got more")
    return parse_epoch(line.split(b"\n", 1)[0], time.time_ns())


__all__ = ["EPOCH_WAIT_S", "RELEASE_MARGIN_S", "parse_epoch", "read_epoch", "release_line"]
