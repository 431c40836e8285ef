"""Keeping a long-running agent's resident memory flat (glibc only; elsewhere these do nothing).

glibc raises its mmap threshold each time a large block is freed, so after the renderer's one-off
work (a 1024 x 1024 procedural ground texture made through FFTs) later large numpy arrays come from the
heap, and freed heap memory stays resident: about 75 MB for an agent measured here. Pinning the
threshold keeps large arrays in their own mappings, which are returned to the system when freed, and
``malloc_trim`` gives back what the warm-up left behind.
"""

from __future__ import annotations

import ctypes
import ctypes.util

#: mallopt parameter number of the mmap threshold (malloc.h).
M_MMAP_THRESHOLD = -3
#: Blocks of this many bytes or more get their own mapping.
MMAP_THRESHOLD = 256 * 1024


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
