"""What a flood of valid feature sets costs a vehicle agent (issue 12): its frame rate, estimate time and memory.

Run from the repository root (the victim and the flooder share the machine's cores, so run nothing else)::

    .venv/bin/python -m benchmarks.bench_flood [--flood-s 10] [--rounds 1] [--out benchmarks/results/flood.md]

A victim agent (a real process: ``python -m agents.cli agent --share features --json``, listening as a peer on a
free loopback port) runs at 10 fps. A flooder (another process, a Zenoh peer connected to the victim) publishes
valid 30-point feature sets at ``--rate`` (10 kHz; it spins in between, so it keeps a core busy) for ``--flood-s`` seconds, starting a few
seconds after the victim's frame 0. Conditions, side by side in one run (interleaved when ``--rounds`` > 1):

* **no flood** - the victim alone;
* **unsubscribed key** - the same flooder publishing on a key nobody subscribes to: the messages never leave the
  flooder's process, so this is the cost of merely sharing the cores with a busy process (the baseline no
  receive path can beat);
* **team-mate flood** - the flood on the victim's subscribed key ``evopose/<fleet>/H2/features``, the flooder
  holding H2's presence token (a member flooding under its own name);
* **outsider flood** - the same flood from a sender without a presence token (an outsider; it shares the
  budget of unknown senders);
* **on-clock team-mate flood** - the team-mate flood with every set stamped at the fleet clock's newest frame
  instant, so the victim pairs the flooder's sets with its frames (a member lying in step with the clock).

The flooder declares H2's token in every flood condition but the outsider's (so the victim's team is the same).
Measured over the flood window (frames whose stamp falls in it): frames due by the clock, frames run, skipped;
estimate time p50/p95 (the ``seconds`` of the victim's frame events); the victim's CPU use (``/proc``); its RSS
just before the flood and just after it; the rejection counters of its summary. The benchmark asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from agents.transport.ports import free_loopback_port as free_port

from .report import md_table, provenance, write_section

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = Path(__file__).resolve().parent / "results" / "flood.md"
FPS = 10.0
#: Frame 0 this long after the victim starts (imports, numba cache, warm-up solve).
EPOCH_LEAD_S = 6.0
#: Normal running before the flood, and after it, s.
BEFORE_S, AFTER_S = 2.5, 2.0
CONDITIONS = ("no flood", "unsubscribed key", "team-mate flood", "outsider flood", "on-clock team-mate flood")
TICKS = os.sysconf("SC_CLK_TCK")


def flood(endpoint: str, fleet: str, key: str, token: bool, start_ns: int, end_ns: int, rate: float,
          epoch_ns: int | None = None) -> None:
    """The flooder (run in its own process): valid feature sets on ``key`` from ``start_ns`` to ``end_ns`` at ``rate``
    per second (0: as fast as this loop goes), spinning in between (it keeps a core busy either way); prints
    ``{"sent": n, "seconds": s, "cpu_s": c}``. Each set is stamped now, or with ``epoch_ns`` at the newest frame
    instant of the fleet clock (:data:`FPS`)."""
    import zenoh

    from protocol import CameraInfo, FeatureSet, encode

    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    config.insert_json5("listen/endpoints", "[]")
    config.insert_json5("scouting/multicast/enabled", "false")
    camera = CameraInfo(fx=1700, fy=1700, cx=320, cy=240, width=640, height=480,
                        world_from_camera=(-27, 6, 12, 0, 0, 0))
    points = np.random.default_rng(0).uniform(300, 340, (30, 2)).astype("<f4").tobytes()
    sender = key.split("/")[2]
    period_ns = int(1e9 / FPS)
    with zenoh.open(config) as session:
        alive = session.liveliness().declare_token(f"evopose/{fleet}/@alive/H2") if token else None
        publisher = session.declare_publisher(key)
        time.sleep(max(0.0, (start_ns - time.time_ns()) / 1e9))
        sent, started, cpu0 = 0, time.monotonic(), time.process_time()
        while time.time_ns() < end_ns:
            if rate and sent >= (time.monotonic() - started) * rate:
                continue
            stamp = time.time_ns()
            if epoch_ns is not None:  # in step with the fleet clock: the newest frame instant
                stamp = epoch_ns + (stamp - epoch_ns) // period_ns * period_ns
            message = FeatureSet(sender=sender, seq=sent, stamp_ns=stamp, camera=camera, points=points)
            publisher.put(encode(message))
            sent += 1
        seconds, cpu = time.monotonic() - started, time.process_time() - cpu0
        publisher.undeclare()
        if alive is not None:
            alive.undeclare()
    print(json.dumps({"sent": sent, "seconds": seconds, "cpu_s": cpu}), flush=True)


def _proc_sample(pid: int) -> tuple[float, int] | None:
    """The process's CPU seconds (user + system) and VmRSS in kB, or None once it is gone."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return None
    fields = stat.rsplit(")", 1)[1].split()
    cpu = (int(fields[11]) + int(fields[12])) / TICKS
    rss = next((int(line.split()[1]) for line in status.splitlines() if line.startswith("VmRSS:")), 0)
    return cpu, rss


def measure(condition: str, flood_s: float, rate: float, victim_args: list[str]) -> dict:
    """One victim run under ``condition``; the metrics of its flood window."""
    port, fleet = free_port(), f"flood{os.getpid()}x{time.monotonic_ns() % 100000}"
    endpoint = f"tcp/127.0.0.1:{port}"
    epoch = time.time_ns() + int(EPOCH_LEAD_S * 1e9)
    start_ns = epoch + int(BEFORE_S * 1e9)
    end_ns = start_ns + int(flood_s * 1e9)
    frames = int(round((BEFORE_S + flood_s + AFTER_S) * FPS))
    victim = subprocess.Popen([sys.executable, "-m", "agents.cli", "agent", "--fleet", fleet, "--vehicle", "H1",
                               "--share", "features", "--frames", str(frames), "--fps", f"{FPS:g}",
                               "--epoch-ns", str(epoch), "--json", "--listen", endpoint, *victim_args],
                              cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(victim.stdout), daemon=True)
    reader.start()
    samples: list[tuple[int, float, int]] = []  # (wall ns, cpu s, rss kB)
    stop = threading.Event()

    def sample() -> None:
        while not stop.wait(0.1):
            got = _proc_sample(victim.pid)
            if got is not None:
                samples.append((time.time_ns(), *got))

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    flooder = None
    try:
        if condition != "no flood":
            sender = "x0" if condition == "outsider flood" else "H2"
            topic = "unsubscribed" if condition == "unsubscribed key" else "features"
            on_clock = epoch if condition == "on-clock team-mate flood" else None
            code = (f"from benchmarks.bench_flood import flood; flood({endpoint!r}, {fleet!r}, "
                    f"'evopose/{fleet}/{sender}/{topic}', {condition != 'outsider flood'}, {start_ns}, {end_ns}, {rate}, "
                    f"{on_clock})")
            time.sleep(2.0)  # the victim listens by then (it opens its session before the warm-up ends)
            flooder = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                                     timeout=EPOCH_LEAD_S + BEFORE_S + flood_s + 60)
        victim.wait(timeout=EPOCH_LEAD_S + BEFORE_S + flood_s + AFTER_S + 120)
    finally:
        stop.set()
        if victim.poll() is None:
            victim.kill()
            victim.wait()
    reader.join(5)
    records = []
    for line in lines:
        try:
            records.append(json.loads(line))
        except ValueError:
            pass
    summary = next((r for r in reversed(records) if r.get("event") == "summary"), None)
    if victim.returncode != 0 or summary is None:
        raise RuntimeError(f"victim failed ({condition}): {victim.stderr.read()[-1500:]}")
    flooded = json.loads(flooder.stdout.strip().splitlines()[-1]) if flooder and flooder.stdout.strip() else {}
    if flooder is not None and not flooded:
        raise RuntimeError(f"flooder failed ({condition}): {flooder.stderr[-1500:]}")
    period_ns = int(1e9 / FPS)
    first_due = -(-(start_ns - epoch) // period_ns)  # frame indices whose stamps fall in [start, end)
    last_due = -(-(end_ns - epoch) // period_ns)
    in_window = [r for r in records if r.get("event") == "frame" and first_due <= r["frame"] < last_due]
    seconds = np.array([r["seconds"] for r in in_window], float)

    def at(t_ns: int) -> tuple[float, int]:
        before = [s for s in samples if s[0] <= t_ns]
        chosen = before[-1] if before else samples[0]
        return chosen[1], chosen[2]

    cpu0, rss0 = at(start_ns)
    cpu1, rss1 = at(end_ns)
    return {"condition": condition, "due": last_due - first_due, "run": len(in_window),
            "good": sum(bool(r.get("good")) for r in in_window),
            "with_flooder": sum("H2" in r.get("views", ()) for r in in_window),
            "error_cm": float(np.median([r["error"]["position"] for r in in_window if r.get("error")] or [np.nan])) * 100,
            "p50_ms": float(np.percentile(seconds, 50)) * 1e3 if len(seconds) else float("nan"),
            "p95_ms": float(np.percentile(seconds, 95)) * 1e3 if len(seconds) else float("nan"),
            "cpu": (cpu1 - cpu0) / flood_s, "rss0_mb": rss0 / 1024, "rss1_mb": rss1 / 1024,
            "rss_max_mb": max(s[2] for s in samples if start_ns <= s[0] <= end_ns + int(1e9)) / 1024,
            "sent": flooded.get("sent", 0), "flood_rate": flooded.get("sent", 0) / max(flooded.get("seconds", 1), 1e-9),
            "flooder_cpu": flooded.get("cpu_s", 0.0) / max(flooded.get("seconds", 1), 1e-9),
            "rejected": summary["traffic"]["rejected"], "received": summary["traffic"]["received"].get("features", 0),
            "late_total": summary["late_frames"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--flood-s", type=float, default=10.0)
    parser.add_argument("--rounds", type=int, default=1, help="Repeat the conditions, interleaved.")
    parser.add_argument("--rate", type=float, default=10000.0, help="Flood messages per second (0: unpaced).")
    parser.add_argument("--conditions", default=",".join(CONDITIONS), help="Comma-separated subset.")
    parser.add_argument("--victim-args", default="", help="More options of the victim agent, e.g. '--sync-wait 0'.")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args()
    conditions = [c.strip() for c in args.conditions.split(",") if c.strip()]
    rows = []
    for _ in range(args.rounds):
        for condition in conditions:
            row = measure(condition, args.flood_s, args.rate, args.victim_args.split())
            rows.append(row)
            print(json.dumps(row), flush=True)
    by: dict[str, list[dict]] = {}
    for row in rows:
        by.setdefault(row["condition"], []).append(row)
    normal = by.get("no flood")
    base_rate = (sum(r["run"] for r in normal) / sum(r["due"] for r in normal)) if normal else None
    table = []
    for row in rows:
        rate = row["run"] / row["due"]
        rejected = ", ".join(f"{k} {v}" for k, v in sorted(row["rejected"].items())) or "-"
        table.append([row["condition"], f"{row['sent']:,} ({row['flood_rate']:,.0f}/s)" if row["sent"] else "-",
                      f"{row['run']} / {row['due']}", row["due"] - row["run"], row["good"], row["with_flooder"],
                      f"{row['error_cm']:.2f}",
                      f"{rate / base_rate:.2f}" if base_rate else "-",
                      f"{row['p50_ms']:.1f} / {row['p95_ms']:.1f}", f"{row['cpu']:.2f}",
                      f"{row['rss0_mb']:.1f} -> {row['rss1_mb']:.1f} ({row['rss_max_mb'] - row['rss0_mb']:+.1f})",
                      row["received"], rejected])
    header = ["condition", "flood sent", "frames run / due", "skipped", "good", "with the flooder's view",
              "median position error, cm", "frame rate vs no flood",
              "estimate p50 / p95, ms", "victim CPU, cores", "victim RSS, MB: before -> after (max - before)",
              "feature sets received", "rejected (whole run)"]
    command = (f".venv/bin/python -m benchmarks.bench_flood --flood-s {args.flood_s:g} --rate {args.rate:g} "
               f"--rounds {args.rounds}"
               + ("" if conditions == list(CONDITIONS) else f" --conditions '{','.join(conditions)}'")
               + (f" --victim-args '{args.victim_args}'" if args.victim_args else ""))
    body = "\n".join([
        f"Command: `{command}` ({provenance()}).", "",
        f"A victim agent (`agents.cli agent --share features`, {FPS:g} fps, a peer on loopback) and a flooder "
        f"process (valid 30-point feature sets at {args.rate:g}/s, spinning in between) on the machine's 2 cores. Numbers "
        f"over the {args.flood_s:g} s flood window (the same window in `no flood`); frame rate = frames run / "
        "frames due, relative to `no flood`; RSS from `/proc` just before and just after the flood. "
        "`unsubscribed key`: the flooder publishes where nobody subscribes (its messages never leave its process), "
        "the cost of sharing the cores with it. Target (issue 12): frame rate >= 0.95 of normal, memory within "
        "+20 MB.", "", *md_table(header, table)])
    write_section(args.out, "Flood", body)
    print(args.out)


if __name__ == "__main__":
    main()
