"""Router capacity: one ``evopose router``, N synthetic vehicles at the paper's rates, N increased until it saturates.

Run from the repository root; each part takes 2-4 minutes and is saved to ``benchmarks/results/capacity/<part>.json``,
the section ``benchmarks/results/capacity.md`` is composed of every part saved::

    .venv/bin/python -m benchmarks.bench_capacity --part hints      # hints, hints-batched, hints-2-subscribers
    .venv/bin/python -m benchmarks.bench_capacity --part features

What runs (docs/scaling.md, "Router capacity"):

* One ``evopose router`` process (``python -m agents.cli router``), fresh for every point.
* N synthetic vehicles, without rendering or estimation. A vehicle is one Zenoh session in client mode connected
  to the router (as an agent that runs as a client of a router), with one publisher declared with the fleet bus's
  QoS for its topic (``protocol.QOS``: hints BLOCK + express, feature sets BLOCK) and, when it subscribes, one
  subscriber on ``evopose/<fleet>/*/<topic>`` (every vehicle's, as the agents subscribe). The vehicles are spread
  over ``--workers`` worker processes (default 2, one per core of this machine); a worker holds its vehicles'
  sessions, one thread that publishes for all of them on a staggered schedule, and the subscribers' callbacks
  (Zenoh's threads). So 2 + 1 processes for any N, and the publishers, the receivers and the router share the
  machine's cores: the saturation found is that of this machine, the router's share of it is measured separately
  (its CPU time from ``/proc/<pid>/stat``).
* Hint mode: every vehicle sends 24-byte hints at 200 Hz. Feature mode: every vehicle sends a feature set of 30
  points (505 B of msgpack, ``evopose publish``'s FeatureSet; the agents' are 440-460 B) at 10 Hz. Both are well-formed messages of the protocol: a
  hint's six float32 carry the send time in microseconds (two 20-bit halves), the sequence number and the sender's
  index; a feature set its ``stamp_ns`` (send time), ``seq`` and ``sender``.
* Receivers are lightweight: a callback takes the payload's bytes, reads the stamp (``struct`` for a hint, msgpack
  for a feature set, no pydantic validation) and records the one-way latency (same host, same clock). The agents'
  fleet bus does more per message (a copy into its inbox, pydantic decoding in a worker thread), so what the
  receivers cost here is a lower bound of what agents would cost.

Per point (a fresh router each): a 1 s warm-up of publishing, then a window of ``--seconds`` s in which messages
are counted by their send stamp (sent in the window by the publishers, received with a stamp in the window by the
subscribers, after a drain of at least 1.5 s, until nothing of the window has come for 0.5 s). Delivered
messages/s = received in the window / window; the nominal is the model's N(N-1)r at the paper's rates. A point is saturated when delivered < 99 % of nominal or the one-way p99
exceeds ``--latency-limit-ms`` (50 ms, half a frame at 10 frames/s: a feature set later than that misses the
agents' pairing, ``--sync-wait``). With BLOCK congestion control nothing is dropped: an overloaded path makes
the publishers wait, so saturation shows as the offered rate falling short of the nominal and as latency.

Modes (:data:`MODES`): ``hints`` (the bus's QoS, express), ``hints-batched`` (hints without express, so that Zenoh
batches them), ``features``, all three all-to-all (N(N-1)r deliveries), and ``hints-2-subscribers`` (every vehicle
publishes, only 2 subscribe: N r messages into the router and about 2 N r out, to separate the router's
per-message ingress cost from the N^2 fan-out).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import struct
import subprocess
import sys
import tempfile
import threading
import time
from array import array
from pathlib import Path

import numpy as np

from agents.transport.ports import free_loopback_port as free_port

from .report import md_table, provenance, write_section

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = Path(__file__).resolve().parent / "results" / "capacity.md"
FLEET = "capacity"
#: Per mode: the share topic, the paper's per-vehicle rate (Hz), whether hints keep the bus's ``express`` (no
#: batching), who subscribes (None: every vehicle, all-to-all; k: only the first k vehicles) and the N tried.
MODES = {
    "hints": {"topic": "hint", "rate": 200.0, "express": True, "subscribers": None, "ns": (2, 4, 8, 10, 12, 16)},
    "hints-batched": {"topic": "hint", "rate": 200.0, "express": False, "subscribers": None,
                      "ns": (8, 12, 16, 24, 32, 48)},
    "features": {"topic": "features", "rate": 10.0, "express": True, "subscribers": None,
                 "ns": (8, 16, 32, 48, 64, 96, 128, 160)},
    "hints-2-subscribers": {"topic": "hint", "rate": 200.0, "express": True, "subscribers": 2,
                            "ns": (8, 16, 24, 32, 64)},
}
#: Parts run by default, each in one locked run of under 5 minutes: (part, modes).
PARTS = {"hints": ("hints", "hints-batched", "hints-2-subscribers"), "features": ("features",)}
PART_DIR = Path(__file__).resolve().parent / "results" / "capacity"
WARMUP_S = 1.0
DRAIN_S = 1.5
QUIET_S = 0.5
MAX_DRAIN_S = 10.0
HINT = struct.Struct("<6f")
MASK20 = (1 << 20) - 1
WRAP_US = 1 << 40
CLK_TCK = os.sysconf("SC_CLK_TCK")


def vehicle_name(index: int) -> str:
    return f"v{index:03d}"


# -- payloads ------------------------------------------------------------------------------------------------------

def hint_payload(now_ns: int, seq: int, sender: int) -> bytes:
    """A well-formed 24-byte hint whose float32 values carry the send time (us, two 20-bit halves), seq, sender."""
    us = now_ns // 1000
    return HINT.pack((us >> 20) & MASK20, us & MASK20, seq & 0xFFFFFF, sender, 0.0, 0.0)


def hint_stamp(payload: bytes, now_ns: int) -> tuple[int, int]:
    """(send time in ns, sender index) of a :func:`hint_payload`, the time unwrapped against ``now_ns``."""
    hi, lo, _, sender, _, _ = HINT.unpack(payload)
    now_us = now_ns // 1000
    us = (now_us & ~(WRAP_US - 1)) | (int(hi) << 20) | int(lo)
    if us > now_us + WRAP_US // 2:
        us -= WRAP_US
    return us * 1000, int(sender)


def feature_template(vehicle: str) -> dict:
    """The msgpack document of one of the protocol's FeatureSets (30 points), to be re-stamped per message."""
    import msgpack

    from agents.tools.runners import PublishSpec, sample_message
    from protocol import Topic, encode

    message = sample_message(PublishSpec(Topic.FEATURES, points=30), {"sender": vehicle, "seq": 0, "stamp_ns": 0},
                             np.random.default_rng(len(vehicle)))
    return msgpack.unpackb(encode(message), raw=False)


# -- the worker process: several synthetic vehicles ----------------------------------------------------------------

def worker(spec: dict) -> dict:
    """Run the vehicles of ``spec`` (one Zenoh session each) through one point; return what they sent and received.

    Protocol with the parent: prints ``ready`` once every session is open and declared, reads one line
    ``t_go t_window_start t_window_end`` (wall-clock ns), publishes from ``t_go`` to the window's end, waits
    :data:`DRAIN_S`, then returns the counts (the latencies go to ``spec["latency_file"]``).
    """
    import msgpack
    import zenoh

    from agents.transport.session import SessionOptions, open_session
    from protocol import QOS, Topic, topic_key, topic_selector

    topic = Topic(spec["topic"])
    rate = float(spec["rate"])
    qos = QOS[topic]
    options = SessionOptions(mode="client", connect=(spec["endpoint"],))
    indices = spec["vehicles"]
    publishing = [i for i in indices if i in set(spec["publishers"])]
    subscribing = [i for i in indices if i in set(spec["subscribers"])]
    sessions = {i: open_session(options) for i in indices}
    window = [0, 0]  # wall ns, set at go
    lock = threading.Lock()
    latencies = array("d")  # ms, in-window messages only
    received = {i: 0 for i in subscribing}

    def on_hint(me: int):
        def callback(sample) -> None:
            now = time.time_ns()
            stamp, sender = hint_stamp(sample.payload.to_bytes(), now)
            if sender == me or not window[0] <= stamp < window[1]:
                return
            with lock:
                received[me] += 1
                latencies.append((now - stamp) * 1e-6)
        return callback

    def on_features(me: int):
        own = vehicle_name(me)

        def callback(sample) -> None:
            now = time.time_ns()
            document = msgpack.unpackb(sample.payload.to_bytes(), raw=False)
            stamp = document["stamp_ns"]
            if document["sender"] == own or not window[0] <= stamp < window[1]:
                return
            with lock:
                received[me] += 1
                latencies.append((now - stamp) * 1e-6)
        return callback

    handle = on_hint if topic is Topic.HINT else on_features  # called on Zenoh's thread per sample
    subscribers = [sessions[i].declare_subscriber(topic_selector(FLEET, topic), handle(i)) for i in subscribing]
    publishers = {i: sessions[i].declare_publisher(
        topic_key(FLEET, vehicle_name(i), topic),
        congestion_control=zenoh.CongestionControl.BLOCK if qos.block else zenoh.CongestionControl.DROP,
        express=qos.express and spec["express"], priority=getattr(zenoh.Priority, qos.priority))
        for i in publishing}
    templates = {i: feature_template(vehicle_name(i)) for i in publishing} if topic is Topic.FEATURES else {}
    print("ready", flush=True)
    go, window[0], window[1] = (int(x) for x in sys.stdin.readline().split())

    sent = {i: 0 for i in publishing}     # with a stamp in the window
    seq = {i: 0 for i in publishing}
    skipped = 0                           # publish slots given up because the loop was a whole period late
    lag = array("d")                      # how late each publish was against its slot, ms
    k = len(publishing)
    size = 0
    if k:
        slot_ns = 1e9 / (rate * k)        # the vehicles' publications staggered evenly over a period
        period_ns = 1e9 / rate
        time.sleep(max(0.0, (go - time.time_ns()) * 1e-9))
        start, n = go, 0
        while True:
            now = time.time_ns()
            due = start + n * slot_ns
            if due >= window[1]:
                break
            if due > now:
                time.sleep((due - now) * 1e-9)
                continue
            if now - due > period_ns:     # a whole period behind: drop the missed slots, as a late vehicle would
                behind = int((now - due) // slot_ns)
                skipped += behind
                n += behind
                continue
            i = publishing[n % k]
            stamp = time.time_ns()
            if topic is Topic.HINT:
                payload = hint_payload(stamp, seq[i], i)
            else:
                document = templates[i]
                document["seq"], document["stamp_ns"] = seq[i], stamp
                payload = msgpack.packb(document, use_bin_type=True)
            publishers[i].put(payload)
            size = len(payload)
            seq[i] += 1
            if window[0] <= stamp < window[1]:
                sent[i] += 1
                lag.append((stamp - due) * 1e-6)
            n += 1
    # drain: at least DRAIN_S, then until no message of the window came for QUIET_S (queues behind a saturated
    # path empty slowly), at most MAX_DRAIN_S
    time.sleep(max(0.0, (window[1] - time.time_ns()) * 1e-9) + DRAIN_S)
    ended = time.monotonic()
    while time.monotonic() - ended < MAX_DRAIN_S - DRAIN_S:
        with lock:
            before = sum(received.values())
        time.sleep(QUIET_S)
        with lock:
            if sum(received.values()) == before:
                break
    with lock:
        result = {"sent": {str(i): n for i, n in sent.items()}, "received": {str(i): n for i, n in received.items()},
                  "skipped": skipped, "lag_p99_ms": float(np.percentile(lag, 99)) if len(lag) else 0.0,
                  "sizes": size}
        np.save(spec["latency_file"], np.frombuffer(latencies, dtype=np.float64))
    for entity in (*subscribers, *publishers.values()):
        entity.undeclare()
    for session in sessions.values():
        session.close()
    return result


# -- the parent: router, workers, /proc ------------------------------------------------------------------------------

def proc_cpu_s(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` (all its threads) from /proc/<pid>/stat."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK  # utime, stime: fields 14 and 15 of stat(5)


def proc_rss_mb(pid: int) -> tuple[float, float]:
    """(VmRSS, VmHWM) of ``pid`` in MB."""
    values = {}
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith(("VmRSS:", "VmHWM:")):
                key, kb = line.split()[:2]
                values[key[:-1]] = int(kb) / 1024
    return values.get("VmRSS", float("nan")), values.get("VmHWM", float("nan"))


def machine_cpu() -> tuple[float, float]:
    """(busy, total) jiffies of the whole machine from /proc/stat."""
    with open("/proc/stat") as f:
        values = [int(v) for v in f.readline().split()[1:]]
    idle = values[3] + values[4]
    total = sum(values[:8])
    return total - idle, total


def tail(log, chars: int = 800) -> str:
    log.flush()
    log.seek(0)
    return log.read()[-chars:]


def start_router(endpoint: str, log) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-m", "agents.cli", "router", "--listen", endpoint, "--json"], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=log, text=True)
    if not proc.stdout.readline():
        proc.wait(5)
        raise RuntimeError(f"router did not start: {tail(log)}")
    return proc


def stop(procs: list[subprocess.Popen]) -> None:
    for proc in procs:
        if proc.poll() is None:
            proc.terminate()
    for proc in procs:
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def measure(mode: str, n: int, *, seconds: float, workers: int, latency_limit_ms: float) -> dict:
    """One point: ``n`` vehicles in ``mode`` (:data:`MODES`)."""
    topic, rate, express = MODES[mode]["topic"], MODES[mode]["rate"], MODES[mode]["express"]
    subscribers = MODES[mode]["subscribers"]
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    subs = list(range(n)) if subscribers is None else list(range(min(subscribers, n)))
    procs: list[subprocess.Popen] = []
    with tempfile.TemporaryDirectory(prefix="evopose-capacity-") as tmp:
        try:
            router = start_router(endpoint, open(Path(tmp) / "router.err", "w+"))
            procs.append(router)
            specs = []
            for w in range(min(workers, n)):
                mine = list(range(w, n, workers))  # subscribers spread over the workers too
                specs.append({"endpoint": endpoint, "topic": topic, "rate": rate, "vehicles": mine,
                              "publishers": mine, "subscribers": [i for i in mine if i in subs],
                              "latency_file": str(Path(tmp) / f"w{w}.npy"), "express": express})
            code = "import json, sys; from benchmarks.bench_capacity import worker; " \
                   "print(json.dumps(worker(json.loads(sys.argv[1]))), flush=True)"
            logs = [open(Path(tmp) / f"w{w}.err", "w+") for w in range(len(specs))]  # a full pipe would stall
            children = [subprocess.Popen([sys.executable, "-c", code, json.dumps(spec)], cwd=ROOT,
                                         stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log, text=True)
                        for spec, log in zip(specs, logs)]
            procs += children
            for child in children:
                line = child.stdout.readline().strip()
                if line != "ready":
                    child.wait(5)
                    raise RuntimeError(f"worker did not start ({line!r}): {tail(logs[children.index(child)])}")
            time.sleep(1.0)  # the subscriptions reach the router and every publisher
            go = time.time_ns() + int(0.2e9)
            t0 = go + int(WARMUP_S * 1e9)
            t1 = t0 + int(seconds * 1e9)
            for child in children:
                child.stdin.write(f"{go} {t0} {t1}\n")
                child.stdin.flush()
            time.sleep(max(0.0, (t0 - time.time_ns()) * 1e-9))
            cpu0 = {p.pid: proc_cpu_s(p.pid) for p in procs}
            machine0, wall0 = machine_cpu(), time.monotonic()
            time.sleep(max(0.0, (t1 - time.time_ns()) * 1e-9))
            cpu1 = {p.pid: proc_cpu_s(p.pid) for p in procs}
            machine1, wall1 = machine_cpu(), time.monotonic()
            rss, hwm = proc_rss_mb(router.pid)
            results = []
            for child in children:
                out, _ = child.communicate(timeout=60 + seconds)
                if child.returncode != 0:
                    raise RuntimeError(f"worker failed ({child.returncode}): {tail(logs[children.index(child)])}")
                results.append(json.loads(out.strip().splitlines()[-1]))
            latencies = np.concatenate([np.load(spec["latency_file"]) for spec in specs])
        finally:
            stop(procs)
    wall = wall1 - wall0
    cores = os.cpu_count() or 1
    machine_busy = (machine1[0] - machine0[0]) / max(machine1[1] - machine0[1], 1) * cores  # cores busy
    router_cpu = (cpu1[router.pid] - cpu0[router.pid]) / wall
    workers_cpu = sum(cpu1[c.pid] - cpu0[c.pid] for c in children) / wall
    sent = {int(k): v for r in results for k, v in r["sent"].items()}
    received = sum(v for r in results for v in r["received"].values())
    expected = sum(count * (len(subs) - (1 if i in subs else 0)) for i, count in sent.items())
    nominal = n * rate * seconds * (len(subs) - 1) if subscribers is None else \
        sum(rate * seconds * (len(subs) - (1 if i in subs else 0)) for i in range(n))
    p50, p99 = (float(np.percentile(latencies, q)) for q in (50, 99)) if len(latencies) else (math.nan, math.nan)
    row = {
        "mode": mode, "variant": "all-to-all" if subscribers is None else f"{len(subs)} subscribers",
        "n": n, "subscribers": len(subs), "rate_hz": rate, "seconds": seconds,
        "offered_nominal_per_s": n * rate, "offered_per_s": sum(sent.values()) / seconds,
        "delivered_nominal_per_s": nominal / seconds, "delivered_per_s": received / seconds,
        "delivery_ratio": received / nominal if nominal else math.nan,
        "received_of_sent": received / expected if expected else math.nan,
        "p50_ms": p50, "p99_ms": p99, "max_ms": float(latencies.max()) if len(latencies) else math.nan,
        "router_cpu": router_cpu, "workers_cpu": workers_cpu, "machine_busy": machine_busy,
        "other_cpu": max(0.0, machine_busy - router_cpu - workers_cpu),
        "router_rss_mb": rss, "router_hwm_mb": hwm, "payload_bytes": max(r["sizes"] for r in results),
        "publish_lag_p99_ms": max(r["lag_p99_ms"] for r in results), "skipped_slots": sum(r["skipped"] for r in results),
    }
    row["saturated"] = bool(row["delivery_ratio"] < 0.99 or not p99 <= latency_limit_ms)
    return row


def sweep(mode: str, ns, *, past: int, **kwargs) -> list[dict]:
    """Points of increasing N until ``past`` + 1 saturated ones in a row (or the list ends)."""
    rows, in_a_row = [], 0
    for n in ns:
        row = measure(mode, n, **kwargs)
        rows.append(row)
        print(json.dumps(row), flush=True)
        in_a_row = in_a_row + 1 if row["saturated"] else 0
        if in_a_row > past:
            break
    return rows


def router_us_per_message(row: dict) -> float:
    """Router CPU per message it handled (in + out), microseconds."""
    handled = row["offered_per_s"] + row["delivered_per_s"]
    return 1e6 * row["router_cpu"] / handled if handled else math.nan


def ceiling(rows: list[dict]) -> dict | None:
    """The unsaturated point with the most deliveries (the measured ceiling below which everything held)."""
    good = [r for r in rows if not r["saturated"]]
    return max(good, key=lambda r: r["delivered_per_s"]) if good else None


def table(rows: list[dict]) -> list[str]:
    return md_table(
        ["mode", "subscribers", "N", "bytes/msg", "offered msgs/s (nominal N r)", "delivered msgs/s (nominal)",
         "delivered / nominal", "received / sent", "one-way p50 / p99, ms", "router CPU, % of a core",
         "router CPU per msg in+out, us", "workers CPU, %", "other processes, %", "router RSS (peak), MB",
         "saturated"],
        [[r["mode"], r["variant"], r["n"], r["payload_bytes"],
          f"{r['offered_per_s']:,.0f} ({r['offered_nominal_per_s']:,.0f})",
          f"{r['delivered_per_s']:,.0f} ({r['delivered_nominal_per_s']:,.0f})",
          f"{100 * r['delivery_ratio']:.1f} %", f"{100 * r['received_of_sent']:.1f} %",
          f"{r['p50_ms']:.2f} / {r['p99_ms']:.2f}", f"{100 * r['router_cpu']:.0f}", f"{router_us_per_message(r):.1f}",
          f"{100 * r['workers_cpu']:.0f}", f"{100 * r['other_cpu']:.0f}",
          f"{r['router_rss_mb']:.0f} ({r['router_hwm_mb']:.0f})", "yes" if r["saturated"] else "no"] for r in rows])


def summary_lines(rows: list[dict]) -> list[str]:
    """Per mode: the largest N that held, and the first that did not."""
    lines = []
    for mode in MODES:
        mine = [r for r in rows if r["mode"] == mode]
        if not mine:
            continue
        top, bad = ceiling(mine), next((r for r in mine if r["saturated"]), None)
        held = (f"held up to N = {top['n']}: {top['delivered_per_s']:,.0f} deliveries/s from {top['offered_per_s']:,.0f} "
                f"msgs/s in, p99 {top['p99_ms']:.1f} ms, router {100 * top['router_cpu']:.0f} % of a core "
                f"({router_us_per_message(top):.1f} us per message in+out), the machine "
                f"{top['machine_busy']:.2f} of {os.cpu_count()} cores busy" if top else "held at no N tried")
        broke = (f"; saturated at N = {bad['n']}: {100 * bad['delivery_ratio']:.1f} % of the nominal "
                 f"{bad['delivered_nominal_per_s']:,.0f}/s delivered, p99 {bad['p99_ms']:.0f} ms, router "
                 f"{100 * bad['router_cpu']:.0f} % of a core, workers {100 * bad['workers_cpu']:.0f} %"
                 if bad else "; not saturated in the range tried")
        lines.append(f"- **{mode}** ({mine[0]['variant']}): {held}{broke}.")
    fit = ingress_and_fanout_cost([r for r in rows if r["mode"] in ("hints", "hints-2-subscribers")])
    if fit:
        lines.append(f"- Router CPU of express hints, least squares over the {fit['points']} points of `hints` and "
                     f"`hints-2-subscribers` that held: ~{fit['in_us']:.0f} us per message in plus "
                     f"~{fit['out_us']:.1f} us per delivery (residual up to {fit['max_residual']:.0f} % of a core).")
    return lines


def ingress_and_fanout_cost(rows: list[dict]) -> dict | None:
    """Router CPU ~ a x messages in + b x deliveries, fitted over unsaturated points (the two variants tell a from b)."""
    good = [r for r in rows if not r["saturated"]]
    if len({r["variant"] for r in good}) < 2:
        return None
    a = np.array([[r["offered_per_s"], r["delivered_per_s"]] for r in good])
    y = np.array([r["router_cpu"] for r in good])
    (cost_in, cost_out), *_ = np.linalg.lstsq(a, y, rcond=None)
    return {"points": len(good), "in_us": 1e6 * cost_in, "out_us": 1e6 * cost_out,
            "max_residual": 100 * float(np.max(np.abs(a @ [cost_in, cost_out] - y)))}


INTRO = """One `evopose router`; N synthetic vehicles (one Zenoh client session each, no rendering, no estimation) in
{workers} worker processes, every vehicle sending at the paper's rate (hints 200 Hz x 24 B; feature sets 10 Hz, 30
points) with the fleet bus's QoS and, all-to-all, subscribing to every other's, as the agents do. Modes: `hints` (the
bus's QoS: BLOCK, express), `hints-batched` (the same without express, so Zenoh batches), `features`,
`hints-2-subscribers` (every vehicle publishes hints, only 2 subscribe: the router's ingress without the N^2
fan-out). Router, publishers and receivers share the machine's 2 cores, so the saturation is of this machine; the
router's own share is its CPU time (`/proc/<pid>/stat`, 100 % = one core); "other processes" is the rest of the
machine's busy time (other engineers' work). Messages are counted by their send stamp over a window of {seconds:g} s;
one-way latency from that stamp. Saturated: delivered < 99 % of the nominal (the model's N(N-1)r) or p99 >
{limit:g} ms. With BLOCK congestion control nothing is dropped: an overloaded path slows the publishers and queues,
so saturation shows as latency and as the offered rate falling short. The model and what these points say of it:
docs/scaling.md, "Router capacity"."""


def compose(out: Path, part_dir: Path = PART_DIR) -> None:
    """Write the "Router capacity" section from the parts measured (``part_dir/<part>.json``)."""
    parts = [json.loads((part_dir / f"{name}.json").read_text()) for name in PARTS if (part_dir / f"{name}.json").exists()]
    if not parts:
        return
    first = parts[0]
    lines = [INTRO.format(workers=first["workers"], seconds=first["seconds"], limit=first["latency_limit_ms"]), ""]
    rows = []
    for part in parts:
        lines += [f"Part `{part['part']}`: `.venv/bin/{part['command']}` ({part['provenance']}; {part['elapsed_s']:.0f} s, "
                  "under `flock /tmp/evopose-bench.lock`).", ""]
        rows += part["rows"]
    lines += [*table(rows), "", *summary_lines(rows)]
    write_section(out, "Router capacity", "\n".join(lines))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", choices=(*PARTS, "all"), default="all",
                        help="Which part to measure (each under 5 minutes); the section is composed of every part.")
    parser.add_argument("--ns", default=None, help="Comma-separated N for every mode of the part (default: each "
                                                   "mode's own list).")
    parser.add_argument("--seconds", type=float, default=3.0, help="Measurement window per point.")
    parser.add_argument("--workers", type=int, default=2, help="Worker processes holding the synthetic vehicles.")
    parser.add_argument("--past", type=int, default=1, help="Saturated points in a row after the first before "
                                                            "stopping a mode.")
    parser.add_argument("--latency-limit-ms", type=float, default=50.0)
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument("--part-dir", type=Path, default=PART_DIR)
    args = parser.parse_args()
    common = {"seconds": args.seconds, "workers": args.workers, "latency_limit_ms": args.latency_limit_ms}
    for part in (PARTS if args.part == "all" else (args.part,)):
        started = time.monotonic()
        rows: list[dict] = []
        for mode in PARTS[part]:
            ns = [int(x) for x in args.ns.split(",")] if args.ns else MODES[mode]["ns"]
            rows += sweep(mode, ns, past=args.past, **common)
        command = ["python -m benchmarks.bench_capacity", f"--part {part}"]
        for flag, value, default in (("--ns", args.ns, None), ("--seconds", args.seconds, 3.0),
                                     ("--workers", args.workers, 2), ("--past", args.past, 1),
                                     ("--latency-limit-ms", args.latency_limit_ms, 50.0)):
            if value != default:
                command.append(f"{flag} {value:g}" if isinstance(value, float) else f"{flag} {value}")
        args.part_dir.mkdir(parents=True, exist_ok=True)
        (args.part_dir / f"{part}.json").write_text(json.dumps(
            {"part": part, "command": " ".join(command), "provenance": provenance(),
             "elapsed_s": time.monotonic() - started, **common, "rows": rows}, indent=1) + "\n")
    compose(args.out, args.part_dir)
    print(args.out)


if __name__ == "__main__":
    main()
