"""Agent footprint: resident memory of vehicle agent processes over a long run with constant traffic.

Run from the repository root::

    .venv/bin/python -m benchmarks.bench_footprint [--minutes 10] [--quick] [--out benchmarks/results/footprint.md]
    .venv/bin/python -m benchmarks.bench_footprint --before ../main-checkout   # before/after, side by side

Each configuration starts two UAV agents of scenario exp2 (H1 and H2) as real separate processes
(``.venv/bin/evopose agent ...``), peers over loopback TCP (H1 listens on a free port, H2 connects;
multicast off), with a fleet name of their own, sharing a heavy mode so that messages flow all the time:

* ``features`` at 30 fps (every frame's image points go to the team-mate),
* ``hint`` (the best pose of each search generation goes out, at up to 200 Hz),
* ``raw`` (640 x 480 x 3 = 921 KB images at 10 fps), for a shorter time (``--raw-minutes``).

By default the configurations run one after the other: on the 2-core machine one heavy pair already keeps
1.4 (features) to 1.8 (hint) cores busy, so two pairs side by side would skip frames and send less
(``--together`` runs features and hint side by side anyway; ``--configs hint`` runs one configuration).
Every ``--interval`` seconds the benchmark reads, for each agent,
VmRSS and VmHWM from ``/proc/PID/status`` and Pss and Private_* (USS) from ``/proc/PID/smaps_rollup``
(no psutil). Times count from frame 0 (the fleet epoch, given to both agents); the warm-up is the first
30 s after it. At the end the agents get SIGTERM and print their JSON summary (last line of stdout), whose
``traffic`` field gives the messages sent and received per topic.

Every agent runs the code of its checkout (``PYTHONPATH`` set to it; the interpreter is this checkout's
``.venv``). ``--before DIR`` names a second checkout (a git worktree of the code before a change, its numba cache
warmed, or its agents compile at start-up): each configuration then runs a pair of that code and a pair of this
one, one after the other, and the section gives both and their ratios.

Targets (from the issue): max RSS < 200 MB and growth < 0.5 MB/min after warm-up (least-squares slope).
MB here is 10^6 bytes. The benchmark asserts nothing; it prints PASS/FAIL lines and writes the section file.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from agents.transport.ports import free_loopback_port as free_port

from .report import code_version, md_table, write_section

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = Path(__file__).resolve().parent / "results" / "footprint.md"
AGENT = ROOT / ".venv" / "bin" / "evopose"
MB = 1e6
MAX_RSS_MB = 200.0
MAX_SLOPE_MB_MIN = 0.5
WARM_UP_S = 30.0
#: Frame 0 this long after the agents start (imports, numba cache load and the warm-up solve come first).
EPOCH_LEAD_S = 15.0
VEHICLES = ("H1", "H2")
#: Minutes of the features and hint pairs in `make bench-footprint`; shorter runs say what their slope is not.
FULL_RUN_MINUTES = 10.0
SHORT_RUN_NOTE = ("These runs are shorter than `make bench-footprint`'s 10 minutes: their slope covers the first "
                  "minutes after the warm-up, where RSS still settles (caches, buffers), and tells no leak from "
                  "that; the RSS figures are what they compare.")


@dataclass(frozen=True)
class Config:
    """One pair of agents: what they share, at which camera rate, for how long, and whose code."""

    name: str
    share: str
    fps: float
    minutes: float
    note: str
    #: the checkout whose code the agents run, and its label in the results ("" without --before)
    root: Path = ROOT
    code_label: str = ""


@dataclass
class Sample:
    t: float  #: seconds since frame 0 (negative during start-up)
    rss: float  #: bytes
    hwm: float  #: bytes (peak RSS so far, kernel's count)
    pss: float | None
    uss: float | None
    cpu_s: float  #: user + system CPU seconds so far


@dataclass
class Agent:
    config: Config
    vehicle: str
    proc: subprocess.Popen
    stdout: Path
    stderr: Path
    epoch_s: float
    code: str = ""
    samples: list[Sample] = field(default_factory=list)
    summary: dict | None = None
    returncode: int | None = None


# -- /proc ----------------------------------------------------------------------------------------------

def _kb_fields(path: str, names: tuple[str, ...]) -> dict[str, float]:
    """``Name:   1234 kB`` lines of a /proc file, as bytes."""
    out = {}
    with open(path) as f:
        for line in f:
            key, _, rest = line.partition(":")
            if key in names:
                out[key] = float(rest.split()[0]) * 1024.0
    return out


def read_memory(pid: int) -> tuple[float, float, float | None, float | None, float]:
    """(RSS, peak RSS, PSS, USS, CPU seconds) of a live process, from /proc; PSS/USS None without smaps_rollup."""
    status = _kb_fields(f"/proc/{pid}/status", ("VmRSS", "VmHWM"))
    pss = uss = None
    try:
        rollup = _kb_fields(f"/proc/{pid}/smaps_rollup", ("Pss", "Private_Clean", "Private_Dirty"))
        pss = rollup.get("Pss")
        uss = rollup.get("Private_Clean", 0.0) + rollup.get("Private_Dirty", 0.0)
    except OSError:
        pass
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    cpu = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime
    return status["VmRSS"], status["VmHWM"], pss, uss, cpu


# -- agents ---------------------------------------------------------------------------------------------

def checkout_version(root: Path) -> str:
    """The commit of a checkout, and whether its code has uncommitted changes (as :func:`code_version`)."""
    if root == ROOT:
        return code_version()
    def git(*args: str) -> str:
        done = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=30)
        return done.stdout.strip()
    dirty = git("status", "--porcelain", "--", "agents", "evopose", "geometry", "scenarios", "protocol", "vision")
    return (git("rev-parse", "--short", "HEAD") or "unknown commit") + (" + uncommitted changes" if dirty else "")


def start_pair(config: Config, logs: Path) -> list[Agent]:
    """Start H1 (listening) and H2 (connecting) sharing ``config.share``; frame 0 in EPOCH_LEAD_S seconds."""
    code = checkout_version(config.root)
    port = free_port()
    tag = f"{config.name}-{config.code_label}" if config.code_label else config.name
    fleet = f"footprint-{tag}-{os.getpid()}-{port}"
    env = {**os.environ, "PYTHONPATH": str(config.root)}  # the checkout's code, not the editable install's
    epoch_s = time.time() + EPOCH_LEAD_S
    common = ["agent", "--fleet", fleet, "--scenario", "exp2", "--share", config.share, "--fps", f"{config.fps:g}",
              "--epoch-ns", str(int(epoch_s * 1e9)), "--no-multicast", "--json", "--wait-timeout", str(EPOCH_LEAD_S)]
    endpoint = f"tcp/127.0.0.1:{port}"
    agents = []
    for vehicle, link in zip(VEHICLES, (["--listen", endpoint], ["--connect", endpoint])):
        # the team-mate only (agents before 9d836ff waited out --wait-timeout when their own name was listed)
        mates = ",".join(v for v in VEHICLES if v != vehicle)
        out, err = logs / f"{tag}-{vehicle}.jsonl", logs / f"{tag}-{vehicle}.err"
        with open(out, "wb") as fo, open(err, "wb") as fe:
            proc = subprocess.Popen([str(AGENT), *common, "--vehicle", vehicle, "--wait-for", mates, *link],
                                    cwd=config.root, env=env, stdin=subprocess.DEVNULL, stdout=fo, stderr=fe)
        agents.append(Agent(config, vehicle, proc, out, err, epoch_s, code))
    return agents


def sample(agents: list[Agent]) -> None:
    now = time.time()
    for a in agents:
        if a.returncode is not None or a.proc.poll() is not None:
            a.returncode = a.proc.returncode
            continue
        try:
            rss, hwm, pss, uss, cpu = read_memory(a.proc.pid)
        except (OSError, KeyError, IndexError, ValueError):  # exited between poll() and the read
            continue
        a.samples.append(Sample(now - a.epoch_s, rss, hwm, pss, uss, cpu))


def last_json(path: Path) -> dict | None:
    """The last JSON object line of an agent's stdout (its summary), or None."""
    try:
        lines = path.read_bytes().splitlines()
    except OSError:
        return None
    for line in reversed(lines):
        try:
            record = json.loads(line)
        except ValueError:
            continue
        if isinstance(record, dict):
            return record
    return None


def stop(agents: list[Agent], timeout: float = 30.0) -> None:
    """SIGTERM every live agent, wait for its summary, SIGKILL what is still alive after ``timeout``."""
    for a in agents:
        if a.proc.poll() is None:
            a.proc.send_signal(signal.SIGTERM)
    deadline = time.monotonic() + timeout
    for a in agents:
        try:
            a.proc.wait(max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            a.proc.kill()
            a.proc.wait()
        a.returncode = a.proc.returncode
        a.summary = last_json(a.stdout)
        if a.summary is not None and a.summary.get("event") != "summary":
            a.summary = None


def kill_all(agents: list[Agent]) -> None:
    """Last resort (exception, Ctrl-C): no agent outlives the benchmark."""
    for a in agents:
        if a.proc.poll() is None:
            a.proc.kill()
    for a in agents:
        try:
            a.proc.wait(5)
        except subprocess.TimeoutExpired:
            pass


def run(configs: list[Config], interval: float, logs: Path, started: list[Agent]) -> list[Agent]:
    """Run the pairs of ``configs`` side by side until the longest is done; ``started`` collects every agent."""
    pairs = []
    for config in configs:
        pair = start_pair(config, logs)
        started.extend(pair)
        pairs.append(pair)
    pending = list(pairs)
    progress: dict[str, float] = {}  # config -> t of the next progress line
    next_sample = time.monotonic()
    while pending:
        sample([a for pair in pending for a in pair])
        for pair in list(pending):
            t = time.time() - pair[0].epoch_s
            dead = [a for a in pair if a.returncode is not None]
            if t >= pair[0].config.minutes * 60.0 or dead:
                if dead:
                    print(f"  {label(pair[0].config)}: {', '.join(a.vehicle for a in dead)} exited early "
                          f"(code {dead[0].returncode}) at t = {t:.0f} s", flush=True)
                stop(pair)
                pending.remove(pair)
                for a in pair:
                    print("  " + describe(a), flush=True)
                    print("    RSS by minute (MB): " + trail(a), flush=True)
            elif t >= progress.get(label(pair[0].config), 0.0):
                progress[label(pair[0].config)] = t + 60.0
                print(f"  {time.strftime('%H:%M:%S')} {label(pair[0].config)} t = {t / 60:.1f} min: "
                      + ", ".join(f"{a.vehicle} {a.samples[-1].rss / MB:.1f} MB" for a in pair if a.samples),
                      flush=True)
        next_sample += interval
        if pending:
            time.sleep(max(0.0, next_sample - time.monotonic()))
    return [a for pair in pairs for a in pair]


def label(config: Config) -> str:
    """A configuration's name, and its code's label when two checkouts are compared."""
    return f"{config.name} ({config.code_label})" if config.code_label else config.name


# -- results --------------------------------------------------------------------------------------------

def analyse(a: Agent) -> dict:
    """The numbers of one agent (MB = 10^6 bytes, slope in MB per minute over the samples after warm-up)."""
    s = a.samples
    after = [x for x in s if x.t >= WARM_UP_S]
    out = {"config": a.config.name, "vehicle": a.vehicle, "samples": len(s), "returncode": a.returncode,
           "code": a.code, "code_label": a.config.code_label,
           "max_rss": max((x.rss for x in s), default=float("nan")) / MB,
           "peak_rss": max((x.hwm for x in s), default=float("nan")) / MB,
           "startup_rss": next((x.rss for x in reversed(s) if x.t < 0), float("nan")) / MB,
           "warm_rss": after[0].rss / MB if after else float("nan"),
           "final_rss": s[-1].rss / MB if s else float("nan"),
           "final_uss": s[-1].uss / MB if s and s[-1].uss is not None else float("nan"),
           "final_pss": s[-1].pss / MB if s and s[-1].pss is not None else float("nan"),
           "slope": float("nan"), "slope_se": float("nan"), "seconds": s[-1].t if s else 0.0}
    if len(after) >= 4:
        t_min = np.array([x.t for x in after]) / 60.0
        coef, cov = np.polyfit(t_min, np.array([x.rss for x in after]) / MB, 1, cov=True)
        out["slope"], out["slope_se"] = float(coef[0]), float(np.sqrt(cov[0, 0]))
    run_s = [x for x in s if x.t >= 0]
    if len(run_s) >= 2 and run_s[-1].t > run_s[0].t:
        out["cpu"] = (run_s[-1].cpu_s - run_s[0].cpu_s) / (run_s[-1].t - run_s[0].t)
    else:
        out["cpu"] = float("nan")
    summary = a.summary or {}
    traffic = summary.get("traffic", {})
    out["sent"], out["received"] = traffic.get("sent", {}), traffic.get("received", {})
    out["frames"], out["late"] = summary.get("frames"), summary.get("late_frames")
    out["passed"] = bool(out["max_rss"] < MAX_RSS_MB and out["slope"] < MAX_SLOPE_MB_MIN)
    return out


def describe(a: Agent) -> str:
    r = analyse(a)
    topics = ", ".join(f"{k} {r['sent'].get(k, 0)}/{r['received'].get(k, 0)}"
                       for k in sorted(set(r["sent"]) | set(r["received"])))
    return (f"{label(a.config):8s} {r['vehicle']}: RSS at frame 0 {r['startup_rss']:.1f}, at 30 s {r['warm_rss']:.1f}, "
            f"final {r['final_rss']:.1f}, max {r['max_rss']:.1f} (peak {r['peak_rss']:.1f}) MB, "
            f"USS {r['final_uss']:.1f} PSS {r['final_pss']:.1f} MB, slope {r['slope']:+.3f} "
            f"± {r['slope_se']:.3f} MB/min, CPU {r['cpu']:.2f} cores, frames {r['frames']} ({r['late']} late), "
            f"sent/received {topics or '?'}"
            + ("" if a.summary else f" [no summary, exit code {r['returncode']}]"))


def trail(a: Agent) -> str:
    """RSS at frame 0 and at each whole minute after it (the first sample at or after it)."""
    out, minute = [], 0
    for x in a.samples:
        if x.t >= minute * 60.0:
            out.append(f"{minute}: {x.rss / MB:.1f}")
            minute += 1
    return ", ".join(out)


def _count(n: int | None) -> str:
    return "?" if n is None else f"{n:,}"


def ratios(results: list[dict]) -> str:
    """This checkout's figures over the --before checkout's, per configuration (the mean of its two agents)."""
    parts = []
    for name in dict.fromkeys(r["config"] for r in results):
        before = [r for r in results if r["config"] == name and r["code_label"] == "before"]
        after = [r for r in results if r["config"] == name and r["code_label"] == "after"]
        if not before or not after:
            continue
        def ratio(key: str) -> str:
            return f"x{np.mean([r[key] for r in after]) / np.mean([r[key] for r in before]):.2f}"
        parts.append(f"*{name}*: RSS at frame 0 {ratio('startup_rss')}, at 30 s {ratio('warm_rss')}, max RSS "
                     f"{ratio('max_rss')}, final USS {ratio('final_uss')}")
    return "After over before (the mean of each pair's two agents): " + "; ".join(parts) + "." if parts else ""


def markdown(results: list[dict], configs: list[Config], command: str, together: bool) -> str:
    rows = []
    compared = any(r["code_label"] for r in results)
    for r in results:
        main = [k for k in sorted(r["sent"], key=r["sent"].get, reverse=True) if k not in ("stats", "pose")][:1]
        topic = main[0] if main else "-"
        rows.append([
            r["config"], *([f"{r['code_label']} ({r['code']})"] if compared else []), r["vehicle"],
            f"{_count(r['frames'])} ({_count(r['late'])})",
            f"{topic}: {_count(r['sent'].get(topic))} / {_count(r['received'].get(topic))}" if main else "?",
            f"{sum(r['sent'].values()):,} / {sum(r['received'].values()):,}",
            f"{r['startup_rss']:.0f}", f"{r['warm_rss']:.1f}", f"{r['final_rss']:.1f}", f"{r['max_rss']:.1f}",
            f"{r['peak_rss']:.1f}", f"{r['final_uss']:.0f} / {r['final_pss']:.0f}",
            f"{r['slope']:+.3f} ± {r['slope_se']:.3f}", f"{r['cpu']:.2f}", "PASS" if r["passed"] else "FAIL"])
    header = ["config", *(["code"] if compared else []), "agent", "frames (late)", "main topic sent / received",
              "all messages sent / received",
              "RSS at frame 0", "RSS at 30 s", "final RSS", "max RSS", "peak RSS (kernel)", "final USS / PSS",
              "slope (MB/min)", "CPU (cores)", "target"]
    table = results
    results = [r for r in results if r["code_label"] in ("", "after")]  # the verdict is this checkout's
    worst_rss = max(r["max_rss"] for r in results)
    worst = max(results, key=lambda r: r["slope"])
    mean_warm = float(np.nanmean([r["warm_rss"] for r in results]))
    shared = float(np.nanmean([r["final_rss"] - r["final_uss"] for r in results]))
    if worst_rss >= MAX_RSS_MB:
        over = [r for r in results if r["max_rss"] >= MAX_RSS_MB]
        size = (f"{'every agent is' if len(over) == len(results) else f'{len(over)} of {len(results)} agents are'} "
                f"over the {MAX_RSS_MB:.0f} MB target from the start (about {mean_warm:.0f} MB after "
                f"{WARM_UP_S:.0f} s of frames, at most {worst_rss:.1f} MB; of the final RSS, {shared:.0f} MB on "
                f"average are pages shared with other processes, such as library code), ")
    else:
        size = f"every agent stays under {MAX_RSS_MB:.0f} MB (at most {worst_rss:.1f} MB), "
    steepest = (f"steepest slope {worst['slope']:+.3f} ± {worst['slope_se']:.3f} MB/min, {worst['config']} "
                f"{worst['vehicle']}; target < {MAX_SLOPE_MB_MIN} MB/min")
    if worst["slope"] < MAX_SLOPE_MB_MIN:
        growth = f"and memory is flat under constant traffic ({steepest})."
    elif worst["slope"] - 2.0 * worst["slope_se"] < MAX_SLOPE_MB_MIN:
        growth = (f"and no agent's growth is clearly over the target ({steepest}, within two standard errors of "
                  f"it; RSS saw-tooths by a few MB, so only a longer run can tell).")
    else:
        growth = f"and memory grows with the run ({steepest})."
    layout = ("features and hint side by side, then raw" if together else "one configuration at a time")
    if compared:
        layout += ("; each configuration runs a pair of the code before (`--before`, a second checkout) and then "
                   "a pair of this checkout's; the verdict below is this checkout's")
    short = min((c.minutes for c in configs if c.name != "raw"), default=FULL_RUN_MINUTES) < FULL_RUN_MINUTES
    codes = {label(c): r["code"] for c in configs for r in table
             if r["config"] == c.name and r["code_label"] == c.code_label}
    code = (f"code at commit {next(iter(codes.values()))}" if len(set(codes.values())) == 1 else
            "code at " + ", ".join(f"{v} ({k})" for k, v in codes.items()))
    lines = [
        f"Command: `{command}` ({platform.machine()}, Python {platform.python_version()}, "
        f"{os.cpu_count()} cores, shared with other work; {time.strftime('%Y-%m-%d')}; {code}).",
        "",
        "Two UAV agents of exp2 (H1, H2) as separate `evopose agent` processes, peers over loopback TCP "
        "(multicast off), per configuration: "
        + "; ".join(dict.fromkeys(f"*{c.name}*: {c.note}, {c.minutes:g} min" for c in configs))
        + f"; {layout}. RSS (VmRSS), USS (private pages) and PSS from /proc every few seconds; "
        "MB = 10^6 bytes; times from frame 0; *RSS at 30 s* is the first sample after the 30 s warm-up, and the "
        "slope a least-squares fit over the samples after it (± its standard error); *peak RSS* is the "
        "kernel's high-water mark (VmHWM), start-up included. Messages from each agent's final summary "
        "(SIGTERM at the end). Targets: max RSS < 200 MB, slope < 0.5 MB/min.",
        "",
        *md_table(header, rows),
        "",
        ("After (this checkout): " + size if compared else size[0].upper() + size[1:]) + growth,
        "",
        *([SHORT_RUN_NOTE, ""] if short else []),
        *([ratios(table), ""] if compared else []),
    ]
    return "\n".join(lines)


def _interrupt(*_) -> None:
    raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--minutes", type=float, default=10.0, help="run of the features and hint pairs, from "
                                                                       "frame 0 (default 10)")
    parser.add_argument("--raw-minutes", type=float, default=None,
                        help="run of the raw-image pair (default 30 %% of --minutes, at least 1; 0: skip it)")
    parser.add_argument("--quick", action="store_true", help="1-minute smoke run of each configuration")
    parser.add_argument("--interval", type=float, default=None, help="seconds between samples (default 5, "
                                                                      "2 with --quick)")
    parser.add_argument("--configs", default="features,hint,raw", help="which pairs to run (comma-separated; "
                                                                       "default all three)")
    parser.add_argument("--together", action="store_true", help="run the features and hint pairs side by side")
    parser.add_argument("--logs", type=Path, default=None, help="keep the agents' stdout/stderr and the samples "
                                                                  "in this folder")
    parser.add_argument("--before", type=Path, default=None,
                        help="a second checkout (the code before a change): each configuration runs a pair of its "
                             "code, then a pair of this checkout's")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    if args.before is not None and args.together:
        parser.error("--before runs one pair at a time: no --together")
    if args.before is not None and not (args.before / "agents" / "cli").is_dir():
        parser.error(f"--before {args.before}: not a checkout of this project")
    minutes = 1.0 if args.quick else args.minutes
    raw_minutes = args.raw_minutes if args.raw_minutes is not None else (
        1.0 if args.quick else max(1.0, round(0.3 * minutes, 1)))
    interval = args.interval or (2.0 if args.quick else 5.0)
    configs = [Config("features", "features", 30.0, minutes, "`--share features --fps 30`"),
               Config("hint", "hint", 30.0, minutes, "`--share hint --fps 30` (hints at up to 200 Hz)"),
               Config("raw", "raw", 10.0, raw_minutes, "`--share raw --fps 10` (921 KB images)")]
    wanted = {name.strip() for name in args.configs.split(",")}
    configs = [c for c in configs if c.minutes > 0 and c.name in wanted]
    if not configs:
        parser.error(f"--configs: nothing to run in {args.configs!r} (features, hint, raw)")
    if args.before is not None:
        configs = [replace(c, root=root, code_label=code_label) for c in configs
                   for root, code_label in ((args.before.resolve(), "before"), (ROOT, "after"))]
    side_by_side = [c for c in configs if c.name in ("features", "hint")]
    batches = ([side_by_side, [c for c in configs if c not in side_by_side]] if args.together
               else [[c] for c in configs])

    # Ctrl-C or SIGTERM to the benchmark: unwind through the finally below, which kills the agents
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _interrupt)
    started: list[Agent] = []
    done: list[Agent] = []
    with tempfile.TemporaryDirectory(prefix="footprint-") as tmp:
        logs = args.logs or Path(tmp)
        logs.mkdir(parents=True, exist_ok=True)
        try:
            for batch in [b for b in batches if b]:
                total = max(c.minutes for c in batch)
                print(f"{time.strftime('%H:%M:%S')} running {', '.join(label(c) for c in batch)} for {total:g} min "
                      f"(+{EPOCH_LEAD_S:.0f} s start-up), a sample every {interval:g} s", flush=True)
                done += run(batch, interval, logs, started)
        except KeyboardInterrupt:
            print("interrupted: stopping the agents", file=sys.stderr)
            return 130
        finally:
            kill_all(started)
        if args.logs:
            for a in done:
                (logs / f"{label(a.config)}-{a.vehicle}.samples.json").write_text(json.dumps(
                    [vars(x) for x in a.samples]))
        for a in done:
            if a.summary is None:
                print(f"--- {label(a.config)} {a.vehicle} stderr (tail) ---\n"
                      + a.stderr.read_text(errors="replace")[-2000:], file=sys.stderr)

    results = [analyse(a) for a in done]
    print()
    for r in results:
        verdict = "PASS" if r["passed"] else "FAIL"
        code = f" ({r['code_label']})" if r["code_label"] else ""
        print(f"{verdict}: {r['config']}{code} {r['vehicle']}: max RSS {r['max_rss']:.1f} MB (target < "
              f"{MAX_RSS_MB:.0f}), slope {r['slope']:+.3f} MB/min (target < {MAX_SLOPE_MB_MIN})")
    judged = [r for r in results if r["code_label"] in ("", "after")]  # this checkout's
    overall = all(r["passed"] for r in judged)
    if args.before is not None:
        print(ratios(results))
    print(f"{'PASS' if overall else 'FAIL'}: agent footprint, {len(judged)} agents "
          f"(max RSS < {MAX_RSS_MB:.0f} MB and slope < {MAX_SLOPE_MB_MIN} MB/min)")

    argv_text = " ".join(argv if argv is not None else sys.argv[1:])
    command = f".venv/bin/python -m benchmarks.bench_footprint {argv_text}".strip()
    write_section(args.out, "Agent footprint", markdown(results, configs, command, args.together))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
