"""Fleet throughput side by side: each share mode of Experiment 2 run as real processes over Zenoh on loopback.

Per configuration (scenario, camera rate) and helicopter: the camera rate it sustained (frames processed per
second of the run; a frame is skipped when the previous one is not done in time), the messages and bytes per
second it sent on its share topic, the latency of its team-mate's data (arrival - acquisition stamp, which
includes the sender's rendering and extraction), the median time of an estimate, the time to the first good
pose and the mean position error. Writes ``benchmarks/results/fleet.md``.

    .venv/bin/python -m benchmarks.bench_fleet [--runs 3] [--seconds 10]

Side by side (``--trees A B``): the configurations at ``--fps`` (default 30) run with each checkout's code in turn,
``--runs`` rounds, the trees' order swapped every round; writes ``benchmarks/results/fleet_side_by_side.md``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import threading
from pathlib import Path

from agents.experiments.runner import run_scenario
from agents.transport.ports import free_loopback_port as free_port
from scenarios.fleet import load_fleet_scenario

from .report import provenance, write_section
from .trees import label, run_in_tree



def free_endpoint() -> str:
    """A loopback endpoint on a port nobody listens on now."""
    return f"tcp/127.0.0.1:{free_port()}"

RESULTS = Path(__file__).resolve().parent / "results" / "fleet.md"
CONFIGS = (("exp2-solo", 10.0), ("exp2a-features", 10.0), ("exp2a-features", 30.0), ("exp2b-hints", 10.0),
           ("exp2b-hints", 30.0), ("exp2-raw", 10.0), ("exp2-raw", 30.0))
SHARE_TOPIC = {"none": None, "features": "features", "hint": "hint", "raw": "image"}


def measure(name: str, fps: float, runs: int, seconds: float) -> list[dict]:
    scenario = load_fleet_scenario(name)
    frames = int(round(seconds * fps))
    records = run_scenario(scenario, runs=runs, frames=frames, seed=0, endpoint=free_endpoint(), fps=fps,
                           stop=threading.Event())
    rows = []
    for vehicle in ("H1", "H2"):
        summaries = [r["agents"][vehicle] for r in records if r["agents"].get(vehicle)]
        share = summaries[0]["share"]
        topic = SHARE_TOPIC[share]

        def mean(key: str, values=None) -> float:
            values = [s.get(key) for s in summaries] if values is None else values
            values = [v for v in values if v is not None]
            return statistics.fmean(values) if values else float("nan")

        duration = [s["frames"] / fps + s["late_frames"] / fps for s in summaries]
        sustained = mean("", [s["frames"] / d for s, d in zip(summaries, duration)])
        sent = [s["traffic"]["sent"].get(topic, 0) for s in summaries] if topic else [0]
        sent_bytes = [s["traffic"]["bytes_sent"].get(topic, 0) for s in summaries] if topic else [0]
        rows.append({
            "scenario": name, "fps": fps, "vehicle": vehicle, "share": share, "runs": len(summaries),
            "sustained_fps": sustained, "late": mean("late_frames"),
            "msgs_per_s": statistics.fmean(n / d for n, d in zip(sent, duration)) if topic else 0.0,
            "bytes_per_msg": (sum(sent_bytes) / sum(sent)) if topic and sum(sent) else 0.0,
            "latency_ms": 1e3 * mean("mate_latency_median_s"), "latency_p95_ms": 1e3 * mean("mate_latency_p95_s"),
            "estimate_ms": 1e3 * mean("frame_seconds_median"), "first_good_ms": 1e3 * mean("first_good_s"),
            "error_mm": 1e3 * mean("error_position")})
    return rows


def bps(row: dict) -> float:
    """Bytes per second a row's vehicle sent on its share topic."""
    return row["msgs_per_s"] * row["bytes_per_msg"]


#: One configuration measured with a tree's own code (``run_in_tree``): its rows as JSON.
_TREE_SCRIPT = """
import json, sys
import benchmarks.bench_fleet as bench
rows = bench.measure(sys.argv[1], float(sys.argv[2]), 1, float(sys.argv[3]))
print(json.dumps({"file": bench.__file__, "rows": rows}))
"""
SIDE_BY_SIDE = Path(__file__).resolve().parent / "results" / "fleet_side_by_side.md"


def side_by_side(trees: list[Path], fps: float, rounds: int, seconds: float) -> None:
    """The configurations at ``fps`` with each tree's code, ``rounds`` rounds, the trees' order swapped each round."""
    configs = [(name, rate) for name, rate in CONFIGS if rate == fps]
    rows: dict[tuple, list[dict]] = {}
    for k in range(rounds):
        for tree in (trees if k % 2 == 0 else trees[::-1]):
            for name, rate in configs:
                found = run_in_tree(tree, _TREE_SCRIPT, [name, str(rate), str(seconds)])
                for row in found["rows"]:
                    rows.setdefault((str(tree), name, row["vehicle"]), []).append(row)
                print(f"{label(tree)} {name} at {rate:g} fps, round {k + 1}: "
                      + json.dumps({r["vehicle"]: round(r["sustained_fps"], 1) for r in found["rows"]}), flush=True)
    lines = [f"Command: `.venv/bin/python -m benchmarks.bench_fleet --trees {' '.join(str(t) for t in trees)} "
             f"--fps {fps:g} --runs {rounds} --seconds {seconds:g}` ({provenance()}; trees: "
             + ", ".join(f"{t} = {label(t)}" for t in trees) + "). Each round runs every configuration with one "
             "tree's code, then the other's (the order swapped each round); per round and helicopter, the rate it "
             "sustained (frames over the run's length), the ticks it skipped, the median time of a frame's estimate.",
             "", "| scenario | vehicle | tree | sustained fps per round | skipped frames per round "
             "| estimate median, ms |", "|---|---|---|---|---|---|"]
    for name, rate in configs:
        for vehicle in ("H1", "H2"):
            for tree in trees:
                got = rows.get((str(tree), name, vehicle), [])
                lines.append(f"| {name} | {vehicle} | {label(tree)} | "
                             + ", ".join(f"{r['sustained_fps']:.1f}" for r in got) + " | "
                             + ", ".join(f"{r['late']:.0f}" for r in got) + " | "
                             + ", ".join(f"{r['estimate_ms']:.1f}" for r in got) + " |")
    write_section(SIDE_BY_SIDE, f"Fleet throughput at {fps:g} fps on drawn worlds, side by side", "\n".join(lines))
    print("\n".join(lines))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=10.0, help="Length of each run (camera time).")
    parser.add_argument("--trees", type=Path, nargs=2, help="Two checkouts side by side (their own code).")
    parser.add_argument("--fps", type=float, default=30.0, help="With --trees: the configurations at this rate.")
    args = parser.parse_args()
    if args.trees:
        side_by_side([t.resolve() for t in args.trees], args.fps, args.runs, args.seconds)
        return
    rows = []
    for name, fps in CONFIGS:
        rows += measure(name, fps, args.runs, args.seconds)
        print(f"{name} at {fps:g} fps done", flush=True)
    lines = ["## Fleet throughput (Experiment 2, real processes over Zenoh on loopback)", "",
             f"`.venv/bin/python -m benchmarks.bench_fleet --runs {args.runs} --seconds {args.seconds:g}` "
             f"({provenance()}; the cores are shared "
             "by the three agent processes of each run and whatever else the machine ran). Mean over runs; "
             "latency: a team-mate's data from its acquisition stamp to arrival (includes the sender's rendering, "
             "~16 ms, and extraction).", "",
             "| scenario | camera fps | vehicle | share | sustained fps | skipped frames | sent msgs/s | bytes/msg | "
             "team-mate latency median / p95, ms | estimate median, ms | first good pose, ms | position error, mm |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['scenario']} | {r['fps']:g} | {r['vehicle']} | {r['share']} | {r['sustained_fps']:.1f} | "
                     f"{r['late']:.1f} | {r['msgs_per_s']:.1f} | {r['bytes_per_msg']:,.0f} | "
                     f"{r['latency_ms']:.1f} / {r['latency_p95_ms']:.1f} | {r['estimate_ms']:.2f} | "
                     f"{r['first_good_ms']:.0f} | {r['error_mm']:.2f} |")
    by = {(r["scenario"], r["fps"], r["vehicle"]): r for r in rows}
    raw, feat, hint = by.get(("exp2-raw", 10.0, "H1")), by.get(("exp2a-features", 10.0, "H1")), by.get(
        ("exp2b-hints", 10.0, "H1"))
    if raw and feat and hint:
        lines += ["", f"Per message, a raw frame is {raw['bytes_per_msg'] / feat['bytes_per_msg']:,.0f}x a feature set "
                  f"and a feature set {feat['bytes_per_msg'] / hint['bytes_per_msg']:.0f}x a hint; in bytes per "
                  f"second raw images cost {bps(raw) / bps(feat):,.0f}x feature sets, and hints at "
                  f"{hint['msgs_per_s']:.0f} Hz {bps(hint) / bps(feat):.1f}x."]
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
