"""Keeping a long-running agent's resident memory flat (glibc only; elsewhere these do nothing).

glibc raises its mmap threshold each time a large block is freed, so after the renderer's one-off
work (a 1024 x 1024 procedural ground texture made through FFTs) later large numpy arrays come from the
heap, and freed heap memory stays resident: about 75 MB for an agent measured here. Pinning the
threshold keeps large arrays in their own mappings, which are returned to the system when freed, and
``malloc_trim`` gives back what the warm-up left behind.

Once warm, a camera vehicle's frames allocate and free the same arrays every frame: the contrast front-end
dozens of 0.3-4 MB ones. Each in its own mapping was mapped, faulted in page by page (zeroed by the kernel) and
unmapped again every frame: on a 640 x 480 frame 19 000-27 000 page faults and 29-43 ms of system time, about as
much as the front-end's own work (BENCHMARKS.md, "What the camera front-end costs a vehicle per frame"). The frame
loop therefore takes blocks under 4 MB from the heap, where a frame reuses what the last one freed, and keeps 16 MB
of freed memory at its top (:func:`reuse_frame_memory`): the frames' working set stays resident instead (there
87 -> 108 MB over the frames of two datasets, against 86 -> 91 MB pinned).
"""

from __future__ import annotations

import ctypes
import ctypes.util

#: mallopt parameter number of the mmap threshold (malloc.h).
M_MMAP_THRESHOLD = -3
#: Blocks of this many bytes or more get their own mapping.
MMAP_THRESHOLD = 256 * 1024
#: mallopt parameter number of the trim threshold (malloc.h): freed memory at the heap's top beyond this is returned.
M_TRIM_THRESHOLD = -1
#: In the frame loop: blocks under 4 MB come from the heap (numpy asks for huge pages from 4 MB, so larger ones are
#: few faults each), and up to 16 MB of freed memory stays at the heap's top for the next frame.
FRAME_MMAP_THRESHOLD, FRAME_TRIM_THRESHOLD = 4 * 1024 * 1024, 16 * 1024 * 1024


def _libc():
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name) if name else None
    except OSError:
        return None
    return libc if libc is not None and hasattr(libc, "malloc_trim") and hasattr(libc, "mallopt") else None


def pin_mmap_threshold() -> bool:
    """Large allocations always mapped (and unmapped on free); True if glibc took it."""
    libc = _libc()
    return bool(libc and libc.mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD))


def release_free_memory() -> bool:
    """Return freed heap memory to the system; True if glibc did."""
    libc = _libc()
    return bool(libc and libc.malloc_trim(0))


def reuse_frame_memory() -> bool:
    """After the warm-up: a frame's arrays under :data:`FRAME_MMAP_THRESHOLD` reuse the heap's memory, and
    :data:`FRAME_TRIM_THRESHOLD` of it stays at the top (see the module's docstring); True if glibc took both."""
    libc = _libc()
    return bool(libc and libc.mallopt(M_MMAP_THRESHOLD, FRAME_MMAP_THRESHOLD)
                and libc.mallopt(M_TRIM_THRESHOLD, FRAME_TRIM_THRESHOLD))
