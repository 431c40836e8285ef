"""A camera vehicle's malloc settings (agents/vehicle/memory.py): the warm-up's large blocks each in their own
mapping (returned when freed), then the frames' arrays from the heap, reused frame after frame instead of mapped,
faulted in page by page and unmapped again."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.fleet_procs import ROOT

#: In a fresh interpreter (malloc's settings are the process's): page faults of a frame-like loop (1 MB arrays made
#: and freed), pinned as during the warm-up, then as in the frame loop.
CHILD = r"""
import json, resource
import numpy as np
from agents.vehicle.memory import pin_mmap_threshold, reuse_frame_memory

def faults(repeat=40):
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(repeat):
        a = np.ones(1 << 20, np.uint8); b = a + 1; del a, b
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before

pinned = pin_mmap_threshold()
faults(2)
pinned_faults = faults()
reused = reuse_frame_memory()
faults(2)
print(json.dumps({"pinned": pinned, "reused": reused, "pinned_faults": pinned_faults, "reused_faults": faults()}))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_the_frames_arrays_reuse_the_heap_instead_of_being_mapped_and_faulted_in_each_time():
    done = subprocess.run([sys.executable, "-c", CHILD], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    assert out["pinned"] and out["reused"]
    # pinned: two 1 MB arrays a round, each a fresh mapping of 256 pages faulted in; reused: the heap's own pages
    assert out["pinned_faults"] > 40 * 256, out
    assert out["reused_faults"] < out["pinned_faults"] / 20, out
