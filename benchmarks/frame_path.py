"""The path of one camera frame through the code, measured: which modules it crosses, in order (docs/architecture.md).

Runs a real agent in this process (``run_agent``: the renderer, a Zenoh session on a free loopback port, the
vehicle's role) for a few frames and profiles one frame after the warm-up in the frame-loop thread. A *hop* is a
call from a function of one project module into a function of another; calls inside the search core (``evopose``
to ``evopose``) and into :mod:`geometry` are not counted (the search is its own room; geometry is a leaf)::

    .venv/bin/python -m benchmarks.frame_path [--share features] [--frame 3]

prints the hops in order, their number (all, and outside the simulator: calls made by ``scenarios`` modules are the
renderer's own work, not the vehicle's), the distinct module boundaries and how often ``agents.vehicle.roles`` was
entered from another module.
"""

from __future__ import annotations

import argparse
import sys
import threading
from pathlib import Path

from agents.transport.session import SessionOptions
from agents.vehicle.agent import run_agent
from agents.vehicle.config import SHARES, AgentConfig

from .bench_fleet import free_endpoint

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("agents", "evopose", "protocol", "scenarios", "geometry")


def _module(filename: str) -> str | None:
    path = Path(filename)
    try:
        parts = path.resolve().relative_to(ROOT).with_suffix("").parts
    except ValueError:
        return None
    if not parts or parts[0] not in PACKAGES:
        return None
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _caller_module(frame) -> str | None:
    frame = frame.f_back
    while frame is not None:
        mod = _module(frame.f_code.co_filename)
        if mod is not None:
            return mod
        frame = frame.f_back
    return None


def measure(share: str = "features", frame_index: int = 3) -> list[tuple[str, str, str]]:
    """The hops ``(from module, to module, function)`` of the vehicle's frame number ``frame_index`` (from 0) of a
    lone vehicle H1 of exp2 (the role's ``frame`` method, entered from the frame loop)."""
    hops: list[tuple[str, str, str]] = []
    state = {"depth": 0, "frames": 0}
    main = threading.get_ident()

    def profile(frame, event, arg):  # noqa: ARG001 - the profiler's signature
        if threading.get_ident() != main:
            return
        code = frame.f_code
        mod = _module(code.co_filename)
        if mod == "agents.vehicle.roles" and code.co_name == "frame" and not state["depth"]:
            if event == "call":
                state["frames"] += 1
                if state["frames"] == frame_index + 1:
                    state["depth"], state["code"] = 1, code
            return
        if not state["depth"] or mod is None:
            return
        if event == "call":
            caller = _caller_module(frame)
            if caller is None or caller == mod or mod == "geometry":
                return
            if caller.startswith("evopose") and mod.startswith("evopose"):
                return
            hops.append((caller, mod, code.co_name))
        if event == "return" and code is state.get("code"):
            state["depth"] = 0

    config = AgentConfig(fleet="framepath", vehicle="H1", scenario="exp2", share=share, frames=frame_index + 2,
                         fps=5.0)
    stop = threading.Event()
    sys.setprofile(profile)
    try:
        run_agent(SessionOptions(listen=(free_endpoint(),)), config, stop, lambda record: None)
    finally:
        sys.setprofile(None)
    return hops


def report(hops: list[tuple[str, str, str]]) -> str:
    lines = [f"{i:3d}. {a} -> {b}.{f}" for i, (a, b, f) in enumerate(hops, 1)]
    boundaries = sorted({(a, b) for a, b, _ in hops})
    roles = sum(1 for a, b, _ in hops if b == "agents.vehicle.roles")
    vehicle = [(a, b, f) for a, b, f in hops if not a.startswith("scenarios")]
    order: list[str] = []
    for _, b, _ in vehicle:
        if b not in order:
            order.append(b)
    lines += ["", "modules entered outside the simulator, in order: " + " -> ".join(order),
              f"hops: {len(hops)}, of which {len(vehicle)} outside the simulator (the renderer's own calls); "
              f"distinct module boundaries: {len(boundaries)}; "
              f"agents.vehicle.roles entered from another module: {roles} times"]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--share", choices=SHARES, default="features")
    parser.add_argument("--frame", type=int, default=3, help="the frame profiled (after the warm-up)")
    args = parser.parse_args(argv)
    print(report(measure(args.share, args.frame)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
