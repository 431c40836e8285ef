"""Where a camera vehicle's resident memory goes: RSS after each import and each step of its warm-up.

Run from the repository root (a few seconds per condition)::

    .venv/bin/python -m benchmarks.bench_agent_memory [--out benchmarks/results/agent_memory.md]

Each condition is a fresh interpreter that does what ``evopose agent --scenario exp2 --vehicle H1`` does before
its first frame, one step at a time, and reads its own ``VmRSS`` (``/proc/self/status``) after each step: the
imports in the order an agent needs them (each row's libraries on top of the rows above: the figure is what that
import adds to a process that has the others), the world, then numba's own start at the first kernel through its
JIT, in three rows (``import numba``; numba imports ``scipy.linalg`` for its BLAS and LAPACK; then it loads its
implementation registries and starts LLVM's code generator), which add nothing with the kernels compiled ahead of
time, then the camera vehicle's warm-up as ``CameraVehicle.warm_up`` runs it (open the camera, render and extract
the first image, one search, tracking frames, a generation between frames). MB = 10^6 bytes.
*compiled ahead of time* runs the kernels of ``evopose.kernels_aot`` (``make install`` builds it; docs/design.md §2,
"Compiled kernels"), as agents run when it is built; the *JIT* conditions run the same kernels through numba's JIT
(``EVOPOSE_KERNELS=jit``), their code from numba's on-disk cache (``cache=True``; warmed first) or compiled in the
process (an empty ``NUMBA_CACHE_DIR``); *peak* is the kernel's high-water mark
(``VmHWM``) so far: the renderer's one-off ground texture (made through FFTs, then freed) lifts it for a moment,
here on top of numba's start (JIT); in an agent the texture comes before numba starts, and its peak is lower (the
footprint section's *peak RSS*). The last table splits the final RSS by mapping (``/proc/self/smaps``): the
libraries' code and data that were touched, and the anonymous memory (Python objects, numpy arrays, LLVM's and
OpenCV's heaps).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from .report import md_table, provenance, write_section

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = Path(__file__).resolve().parent / "results" / "agent_memory.md"
MB = 1e6

#: What the child process does, step by step; it prints one JSON line per step, and the mappings at the end.
CHILD = r'''
import importlib, json, sys, time

def status():
    out = {}
    with open("/proc/self/status") as f:
        for line in f:
            key, _, rest = line.partition(":")
            if key in ("VmRSS", "VmHWM", "Threads"):
                out[key] = int(rest.split()[0]) * (1 if key == "Threads" else 1024)
    return out

def step(name):
    print(json.dumps({"step": name, **status()}), flush=True)

step("the interpreter")
for names in (["numpy"], ["typer", "rich.console"], ["pydantic", "msgpack", "yaml"], ["zenoh"], ["cv2"],
              ["agents.vehicle.agent"]):
    for name in names:
        importlib.import_module(name)
    step("import " + ", ".join(names))
from agents.vehicle.agent import load_world
from agents.vehicle.config import AgentConfig
from agents.vehicle.memory import pin_mmap_threshold, release_free_memory
from agents.vehicle.threads import limit_blas_threads
import agents.vehicle.roles as roles
pin_mmap_threshold()
limit_blas_threads()
config = AgentConfig(fleet="memory", vehicle="H1", scenario="exp2", share="features")
scenario = load_world(config)
scenario.bounds()
step("the world loaded (exp2)")
from evopose import kernel_backend
if kernel_backend.BACKEND == "jit":
    importlib.import_module("numba")
step("JIT only: import numba")
if kernel_backend.BACKEND == "jit":
    importlib.import_module("scipy.linalg")
step("JIT only: numba's first kernel: scipy.linalg (numba's BLAS, LAPACK)")
if kernel_backend.BACKEND == "jit":
    from numba.core.registry import cpu_target
    cpu_target.target_context.refresh()
step("JIT only: numba's first kernel: its registries, LLVM's code generator")
camera = roles.open_camera(config, scenario)
step("the camera opened")
frame = camera.acquire(0, 0)
camera.close()
release_free_memory()
step("the first image rendered and its points extracted")
views, _ = roles.build_views([roles.own_view(config.vehicle, 0, frame.camera, frame.points, frame.labels)])
rules = roles.Cooperation(scenario.model.evopose_model(), scenario.bounds(),
                          roles.SearchOptions(max_generations=1, min_starts=1))
state, _ = roles.EstimatorState(), None
state, _ = rules.estimate(state, views, frame=0, candidates=None)
step("one search")
for k in range(1, roles.WARM_UP_FRAMES):
    best = state.current_best
    state, _ = rules.estimate(state, views, frame=k, candidates=None if best is None else best[None])
rules.generation(state, budget_s=0.0)
release_free_memory()
step("tracking frames and a generation (the warm-up's end)")
by = {}
current = None
with open("/proc/self/smaps") as f:
    for line in f:
        parts = line.split()
        if len(parts) >= 5 and "-" in parts[0] and not parts[0].endswith(":"):
            current = parts[5].rsplit("/", 1)[-1] if len(parts) >= 6 else "anonymous"
        elif parts and parts[0] == "Rss:":
            by[current] = by.get(current, 0) + int(parts[1]) * 1024
print(json.dumps({"mappings": by}), flush=True)
'''


def run_child(cold_cache: bool, backend: str = "jit") -> tuple[list[dict], dict]:
    """The child's steps and its final RSS by mapping; ``backend`` "aot" (the compiled kernels, which must be built
    and current) or "jit"; ``cold_cache``: numba compiles every kernel itself."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "EVOPOSE_KERNELS": backend}
    with tempfile.TemporaryDirectory(prefix="numba-cache-") as empty:
        if cold_cache:
            env["NUMBA_CACHE_DIR"] = empty
        out = subprocess.run([sys.executable, "-c", CHILD], cwd=ROOT, env=env, capture_output=True, text=True,
                             timeout=900)
    if out.returncode != 0:
        raise RuntimeError(f"the child failed:\n{out.stderr[-3000:]}")
    records = [json.loads(line) for line in out.stdout.splitlines() if line.startswith("{")]
    return [r for r in records if "step" in r], next(r["mappings"] for r in records if "mappings" in r)


MAPPINGS = (("libllvmlite.so", "LLVM (numba's compiler, llvmlite)"), ("anonymous", "anonymous"),
            ("[heap]", "heap (brk)"), ("cv2.abi3.so", "OpenCV"), ("zenoh.abi3.so", "Zenoh"))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    from evopose.kernel_backend import load_aot

    if load_aot() is None:
        parser.error("the compiled kernels are not built or not current: python -m evopose.kernel_build")
    run_child(cold_cache=False)  # warm numba's on-disk cache, as an agent finds it
    aot, aot_mappings = run_child(cold_cache=False, backend="aot")
    cached, mappings = run_child(cold_cache=False)
    cold, _ = run_child(cold_cache=True)
    rows, before = [], 0.0
    for c, a, b in zip(aot, cached, cold):
        rows.append([c["step"], f"{c['VmRSS'] / MB:.1f}", f"{(c['VmRSS'] - before) / MB:+.1f}",
                     f"{c['VmHWM'] / MB:.1f}", f"{a['VmRSS'] / MB:.1f}", f"{a['VmHWM'] / MB:.1f}",
                     f"{b['VmRSS'] / MB:.1f}", c["Threads"]])
        before = c["VmRSS"]
        print(f"{c['step']:70s} {c['VmRSS'] / MB:7.1f} {a['VmRSS'] / MB:7.1f} {b['VmRSS'] / MB:7.1f}", flush=True)
    rows.append(["peak (VmHWM) at the end", "", "", f"{aot[-1]['VmHWM'] / MB:.1f}", "",
                 f"{cached[-1]['VmHWM'] / MB:.1f}", f"{cold[-1]['VmHWM'] / MB:.1f}", ""])
    known = {name for name, _ in MAPPINGS}
    split = [[label, f"{aot_mappings.get(name, 0) / MB:.1f}", f"{mappings.get(name, 0) / MB:.1f}"]
             for name, label in MAPPINGS]
    split.append(["other libraries (Python, numpy, OpenBLAS x 3, pydantic-core, libcrypto, ...)",
                  *(f"{sum(v for k, v in m.items() if k not in known) / MB:.1f}" for m in (aot_mappings, mappings))])
    split.append(["total", *(f"{sum(m.values()) / MB:.1f}" for m in (aot_mappings, mappings))])
    body = "\n".join([
        f"Produced by `.venv/bin/python -m benchmarks.bench_agent_memory`; {provenance()}.", "",
        next(part for part in __doc__.split("\n\n") if part.startswith("Each condition")).replace("\n", " "), "",
        *md_table(["step", "RSS (MB), compiled ahead of time", "added (MB)", "peak so far (MB)",
                   "RSS (MB), JIT, numba cache", "peak (MB), JIT, numba cache", "RSS (MB), JIT compiled in the process",
                   "threads"], rows), "",
        "The final RSS by mapping:", "",
        *md_table(["mapping", "RSS (MB), compiled ahead of time", "RSS (MB), JIT, numba cache"], split),
    ])
    write_section(args.out, "Where a camera vehicle's memory goes", body)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
