"""``evopose scenario run``: every agent of a fleet scenario as its own process, for one or more runs.

Per run, the agents get one fleet name, one frame clock (``--epoch-from-stdin``: once every agent is warm, each
is given the same epoch a second ahead, so that all start at the same frame), the run's seeds (search seed
``seed + run``, world seed ``world seed + run``: each run sees other noise and IMU biases) and ``--frames N``;
each ends with a JSON summary. Networking: the first agent listens on the scenario's endpoint (default
``tcp/127.0.0.1:7447``) and the others connect to it, peer to peer; with ``router: true`` a router listens there
and every agent joins it as a client. An outside program (``evopose meter --connect tcp/127.0.0.1:7447``) can watch
the traffic there. Multicast scouting is off (the default): the agents meet through the endpoint only.

``dataset``: the camera vehicles play a rendered dataset's images instead of the renderer (``evopose agent --source
DIR``: each frame's camera and truth from the dataset, docs/datasets.md); the world is the dataset's world.yaml
(:func:`dataset_scenario`), the frames the dataset's, the fleet clock as usual.

``secure``: every run gets its fleet's credentials (``evopose fleet credentials``, in ``credentials/<fleet>``
or a temporary directory removed after the run), a router listens on the endpoint as ``tls/`` with mutual
TLS and the deny-by-default ACL, and every agent is a TLS client with its own certificate (docs/security.md).
An outside meter needs the ``meter`` observer's configuration from that directory.

Every child is stopped, whatever happens: a crashed agent ends the run (the others get SIGTERM), Ctrl-C
stops them all, and anything still alive after a grace period is killed. The router is watched like the
agents: if it dies, one line on stderr says so and it is started again on the same endpoint (its agents,
Zenoh clients, reconnect by themselves: docs/scaling.md, "Faults"); the run's record lists each death under
``router_restarts``. A router that dies more than :data:`ROUTER_RESTARTS` times, or does not come back, ends
the run with an error.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from scenarios.fleet import FleetScenario, VariantSpec, load_fleet_scenario

from agents.errors import FleetError
from agents.experiments import DEFAULT_ENDPOINT
from agents.vehicle.start_signal import RELEASE_MARGIN_S, release_line

#: How long a run's agents may take to be warm (imports, warm-up, the session) before the run fails.
WARM_TIMEOUT_S = 120.0
#: Seconds an agent gets to stop after SIGTERM before it is killed.
GRACE_S = 10.0
#: How long an agent waits for its team-mates before it gives up with an error (``--wait-timeout``).
WAIT_FOR_TEAM_S = 30.0
#: Times a run's router is started again after it died before the run is given up.
ROUTER_RESTARTS = 3
#: The member of a secure fleet that may only watch (``evopose meter --config <credentials>/meter.json5``).
OBSERVER = "meter"


class ScenarioRunError(FleetError):
    """A run could not be completed (an agent crashed or timed out)."""


def dataset_scenario(name: str | Path, dataset: str | Path, variants: list[str] | None = None
                     ) -> tuple[FleetScenario, int]:
    """The fleet scenario ``name`` on a rendered dataset's world (its world.yaml), and the dataset's frame count.

    Raises
    ------
    DatasetError
        The dataset is malformed, or a camera vehicle of the chosen variants has no folder in it (one line).
    """
    from scenarios.dataset import DatasetError, open_dataset

    data = open_dataset(dataset)
    scenario = load_fleet_scenario(name, data.root / "world.yaml")
    target = scenario.world.spec.target.name
    for variant in [scenario.variant(v) for v in variants] if variants else scenario.spec.variants:
        for agent in variant.agents:
            if agent.vehicle != target and agent.vehicle not in data.cameras:
                raise DatasetError(f"--dataset {dataset}: vehicle {agent.vehicle} of {scenario.name} (variant "
                                   f"{variant.name}) has no camera folder in the dataset (cameras: "
                                   f"{', '.join(data.cameras)})")
    return scenario, data.frames


@dataclass
class AgentProcess:
    """One running ``evopose agent``: its stdout JSON lines are collected by a thread."""

    vehicle: str
    popen: subprocess.Popen
    records: list = field(default_factory=list)  #: every record but the per-frame ones (counted instead)
    frames_done: int = 0
    stderr: str = ""
    warm: threading.Event = field(default_factory=threading.Event)  #: its "warm" record came: it waits for its epoch

    def __post_init__(self) -> None:
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self._errors = threading.Thread(target=self._read_errors, daemon=True)   # drained as it comes: a full pipe
        self._errors.start()                                                      # would block the agent

    def _read_errors(self) -> None:
        chunks = []
        if self.popen.stderr is not None:
            for chunk in iter(lambda: self.popen.stderr.read(4096), ""):
                chunks.append(chunk)
        self.stderr = "".join(chunks)

    def _read(self) -> None:
        for line in self.popen.stdout:
            try:
                record = json.loads(line)
            except ValueError:
                continue
            if not isinstance(record, dict):   # a line that is JSON but no record
                continue
            if record.get("event") == "frame":
                self.frames_done += 1
            else:
                self.records.append(record)
                if record.get("event") == "warm":
                    self.warm.set()

    def release(self, line: str) -> None:
        """Give the agent its epoch (``line``, :func:`agents.vehicle.start_signal.release_line`, on its standard input;
        it may have exited)."""
        try:
            self.popen.stdin.write(line)
            self.popen.stdin.flush()
        except (OSError, ValueError):
            pass

    @property
    def summary(self) -> dict | None:
        for record in reversed(self.records):
            if record.get("event") == "summary":
                return record
        return None

    def finish(self, timeout: float) -> None:
        """Wait for the agent to end and its output to be read to the end (stdout by the reader, not here: two
        readers of one pipe would split its lines)."""
        try:
            self.popen.wait(timeout)
        except subprocess.TimeoutExpired:
            pass
        if self.popen.stdin is not None:
            try:
                self.popen.stdin.close()
            except OSError:
                pass
        self._reader.join(1.0)
        self._errors.join(1.0)


def agent_command(scenario: FleetScenario, agent_args: list[str], *, fleet: str, frames: int, fps: float,
                  seed: int, world_seed: int, network: list[str], wait_for: list[str]) -> list[str]:
    """The command line of one agent of a run (its epoch comes on its standard input: :func:`release_when_warm`)."""
    return [sys.executable, "-m", "agents.cli", "agent", "--scenario", str(scenario.world_path), "--fleet", fleet,
            *agent_args, "--frames", str(frames), "--fps", f"{fps:g}", "--epoch-from-stdin",
            "--seed", str(seed), "--world-seed", str(world_seed), "--wait-for", ",".join(wait_for),
            "--wait-timeout", f"{WAIT_FOR_TEAM_S:g}", "--json", *network]


def tls_endpoint(endpoint: str) -> str:
    """``tcp/host:port`` as ``tls/host:port`` (a secure fleet listens with TLS only)."""
    protocol, _, address = endpoint.partition("/")
    if protocol not in ("tcp", "tls") or not address:
        raise ScenarioRunError(f"--secure needs a tcp/ or tls/ endpoint, got {endpoint!r}")
    return f"tls/{address}"


def make_credentials(directory: Path, fleet: str, vehicles: list[str], endpoint: str, env: dict) -> None:
    """``evopose fleet credentials`` for one run's fleet (a subprocess: this room never imports the agents)."""
    cmd = [sys.executable, "-m", "agents.cli", "fleet", "credentials", str(directory), "--fleet", fleet,
           "--vehicles", ",".join(vehicles), "--observers", OBSERVER, "--listen", endpoint, "--force", "--json"]
    done = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=120)
    if done.returncode != 0:
        raise ScenarioRunError(f"credentials for fleet {fleet!r}: {done.stderr.strip()[-300:]}")


def release_when_warm(procs: list[AgentProcess], stop: threading.Event, timeout_s: float = WARM_TIMEOUT_S) -> bool:
    """Once every agent of a run is warm, give each the same epoch, ``RELEASE_MARGIN_S`` ahead
    (:mod:`agents.vehicle.start_signal`; True); False when
    ``stop`` is set or an agent exits first (the run's loop then says why).

    Raises
    ------
    ScenarioRunError
        An agent was not warm within ``timeout_s``.
    """
    deadline = time.monotonic() + timeout_s
    while not all(p.warm.is_set() for p in procs):
        if stop.is_set() or any(p.popen.poll() is not None for p in procs):
            return False
        if time.monotonic() > deadline:
            cold = ", ".join(p.vehicle for p in procs if not p.warm.is_set())
            raise ScenarioRunError(f"agents {cold} were not warm within {timeout_s:g} s")
        stop.wait(0.01)
    _, line = release_line()
    for proc in procs:
        proc.release(line)
    return True


def _stop_all(procs: list, sig: int = signal.SIGTERM) -> None:
    for proc in procs:
        if proc.poll() is None:
            try:
                proc.send_signal(sig)
            except ProcessLookupError:
                pass
    deadline = time.monotonic() + GRACE_S
    for proc in procs:
        try:
            proc.wait(max(deadline - time.monotonic(), 0.05))
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)


def start_ros2_mirror(fleet: str, domain: int, endpoint: str, use_router: bool, env: dict) -> subprocess.Popen:
    """``evopose ros2`` on the fleet (an observer, like the meter), once it is subscribed; stopped with the agents.

    Without a router it connects to the first agent's endpoint before that listens: Zenoh retries."""
    network = ["--mode", "client", "--connect", endpoint] if use_router else ["--connect", endpoint]
    mirror = subprocess.Popen([sys.executable, "-m", "agents.cli", "ros2", "--fleet", fleet, "--domain", str(domain),
                               "--json", *network], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    if not mirror.stdout.readline():  # its "ready" line
        raise ScenarioRunError(f"the ROS 2 mirror did not start: {mirror.stderr.read().strip()[-300:]}")
    return mirror


def start_recorder(fleet: str, out: Path, endpoint: str, use_router: bool, env: dict) -> subprocess.Popen:
    """``evopose record`` of the fleet into the rosbag2 bag directory ``out`` (``out/<name>.mcap``: the ROS 2
    channels, with its metadata.yaml; the raw ones beside it), once subscribed; stopped (SIGTERM: the file is finished) with the agents."""
    network = ["--mode", "client", "--connect", endpoint] if use_router else ["--connect", endpoint]
    out.parent.mkdir(parents=True, exist_ok=True)
    recorder = subprocess.Popen([sys.executable, "-m", "agents.cli", "record", "--fleet", fleet, "--out", str(out),
                                 "--json", *network], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                env=env)
    if not recorder.stdout.readline():  # its "ready" line
        raise ScenarioRunError(f"the recorder did not start: {recorder.stderr.read().strip()[-300:]}")
    return recorder


def start_router(cmd: list[str], env: dict) -> subprocess.Popen:
    """``evopose router`` (``cmd``), once it listens (its first JSON line)."""
    router = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    if not router.stdout.readline():
        raise ScenarioRunError(f"the router did not start: {router.stderr.read().strip()[-300:]}")
    return router


def run_variant(scenario: FleetScenario, variant: VariantSpec, run: int, *, frames: int, seed: int,
                endpoint: str, stop: threading.Event, on_progress: Callable[[dict], None] | None = None,
                fps: float | None = None, secure: bool = False, credentials: Path | None = None,
                ros2_domain: int | None = None, record_dir: Path | None = None, dataset: Path | None = None) -> dict:
    """One run of one variant: start its agents (and router), wait for their summaries, stop everything.

    ``secure``: TLS, mTLS and the router's ACL, with this run's credentials in ``credentials/<fleet>`` (kept)
    or in a temporary directory (removed). ``ros2_domain``: also run ``evopose ros2`` (docs/ros2.md) on the
    fleet, publishing its ROS 2 mirror in that domain. ``record_dir``: the run's traffic is recorded into
    the rosbag2 bag directory ``record_dir/<fleet>`` (``evopose record``: ``<fleet>.mcap`` and ``metadata.yaml``,
    what ROS 2 tools open; the raw channels, replayable, in ``<fleet>.raw.mcap`` inside it). ``dataset``: every
    camera vehicle plays that rendered dataset (``--source``; see :func:`dataset_scenario`).
    """
    fps = fps or scenario.fps
    started = time.monotonic()
    fleet = f"{scenario.name}-{variant.name}-{run}".replace("+", "-")[:64]
    vehicles = [a.vehicle for a in variant.agents]
    router, slow, router_restarts = None, False, []
    children: list[subprocess.Popen] = []
    procs: list[AgentProcess] = []
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    use_router = scenario.spec.router or secure
    keys_dir, temporary = None, None
    try:
        if secure:
            endpoint = tls_endpoint(endpoint)
            temporary = None if credentials is not None else tempfile.mkdtemp(prefix="evopose-credentials-")
            keys_dir = Path(credentials) / fleet if credentials is not None else Path(temporary)
            make_credentials(keys_dir, fleet, vehicles, endpoint, env)
        if use_router:
            config = ["--config", str(keys_dir / "router.json5")] if secure else []
            router_cmd = [sys.executable, "-m", "agents.cli", "router", *config, "--listen", endpoint, "--json"]
            router = start_router(router_cmd, env)
            children.append(router)
        if ros2_domain is not None:  # before the agents, so that it mirrors their first frames
            children.append(start_ros2_mirror(fleet, ros2_domain, endpoint, use_router, env))
        if record_dir is not None:  # before the agents too: their first frames are in the file
            children.append(start_recorder(fleet, Path(record_dir) / fleet, endpoint, use_router, env))
        for i, agent in enumerate(variant.agents):
            if secure:  # the vehicle's file: a TLS client with its certificate
                network = ["--config", str(keys_dir / f"{agent.vehicle}.json5"), "--connect", endpoint]
            elif use_router:
                network = ["--mode", "client", "--connect", endpoint]
            elif i == 0:
                network = ["--listen", endpoint]
            else:
                network = ["--connect", endpoint]
            args = agent.cli_args()
            if dataset is not None and agent.vehicle != scenario.world.spec.target.name:
                args += ["--source", str(dataset)]
            cmd = agent_command(scenario, args, fleet=fleet, frames=frames, fps=fps, seed=seed + run,
                                world_seed=scenario.world.seed + run, network=network,
                                wait_for=[v for v in vehicles if v != agent.vehicle])
            popen = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, env=env)
            children.append(popen)
            procs.append(AgentProcess(agent.vehicle, popen))
        release_when_warm(procs, stop)
        deadline = time.monotonic() + RELEASE_MARGIN_S + frames / fps * 3 + 60
        while not stop.is_set():
            if all(p.popen.poll() is not None for p in procs):
                break
            crashed = [p for p in procs if p.popen.poll() not in (None, 0)]
            if crashed:
                break
            if router is not None and router.poll() is not None and not stop.is_set():
                router = _restart_router(router, router_cmd, env, router_restarts, started, run, endpoint)
                children.append(router)
            if time.monotonic() > deadline:  # slow: stop the agents, keep what they measured (their summaries)
                slow = True
                break
            if on_progress is not None:
                on_progress({"run": run, "variant": variant.name,
                             "frames": min(p.frames_done for p in procs)})
            stop.wait(0.25)
    finally:
        _stop_all(children)
        for proc in procs:
            proc.finish(GRACE_S)
        if temporary is not None:
            shutil.rmtree(temporary, ignore_errors=True)
    crashed = [p for p in procs if p.popen.returncode not in (0, None) and p.summary is None]
    if crashed and not stop.is_set():
        details = "; ".join(f"{p.vehicle} exited {p.popen.returncode}"
                            + (f" ({p.stderr.strip().splitlines()[-1]})" if p.stderr.strip() else "") for p in crashed)
        raise ScenarioRunError(f"run {run} of {scenario.name}/{variant.name}: {details}")
    return {"scenario": scenario.name, "world": scenario.world.name, "variant": variant.name, "run": run,
            "fleet": fleet, "slow": slow, "secure": secure, "router_restarts": router_restarts,
            "recording": str(Path(record_dir) / fleet) if record_dir is not None else None,
            "dataset": None if dataset is None else str(dataset),
            "interrupted": stop.is_set(), "seconds": time.monotonic() - started,
            "agents": {p.vehicle: p.summary for p in procs}}


def _restart_router(dead: subprocess.Popen, cmd: list[str], env: dict, restarts: list[dict], started: float,
                    run: int, endpoint: str) -> subprocess.Popen:
    """Say that the run's router died (one line on stderr), note it in ``restarts`` and start it again."""
    at = time.monotonic() - started
    restarts.append({"after_s": round(at, 3), "exit_code": dead.returncode})
    if len(restarts) > ROUTER_RESTARTS:
        raise ScenarioRunError(f"run {run}: the router on {endpoint} died {len(restarts)} times (exit code "
                               f"{dead.returncode} at {at:.1f} s); giving up")
    sys.stderr.write(f"run {run}: the router on {endpoint} died (exit code {dead.returncode}) at {at:.1f} s; "
                     f"restarting it ({len(restarts)} of {ROUTER_RESTARTS})\n")
    sys.stderr.flush()
    return start_router(cmd, env)


def run_scenario(scenario: FleetScenario, *, runs: int = 1, frames: int | None = None, seed: int = 0,
                 endpoint: str = DEFAULT_ENDPOINT, variants: list[str] | None = None, stop: threading.Event,
                 fps: float | None = None, keep_going: bool = False, secure: bool = False,
                 credentials: Path | None = None, on_run: Callable[[dict], None] | None = None,
                 on_progress: Callable[[dict], None] | None = None, ros2_domain: int | None = None,
                 record_dir: Path | None = None, dataset: Path | None = None) -> list[dict]:
    """Every run of every (chosen) variant; returns one record per run (see :func:`run_variant`).

    A run that fails raises :class:`ScenarioRunError`; with ``keep_going`` it is recorded instead, as
    ``{"scenario", "variant", "run", "error", "agents": {}}``, and the next run starts.
    """
    chosen = [scenario.variant(v) for v in variants] if variants else scenario.spec.variants
    results = []
    for variant in chosen:
        for run in range(runs):
            if stop.is_set():
                return results
            try:
                record = run_variant(scenario, variant, run, frames=frames or scenario.frames, seed=seed,
                                     endpoint=endpoint, stop=stop, on_progress=on_progress, fps=fps,
                                     secure=secure, credentials=credentials, ros2_domain=ros2_domain,
                                     record_dir=record_dir, dataset=dataset)
            except ScenarioRunError as err:
                if not keep_going:
                    raise
                record = {"scenario": scenario.name, "world": scenario.world.name, "variant": variant.name,
                          "run": run, "error": str(err),
                          "interrupted": False, "agents": {}}
            results.append(record)
            if on_run is not None:
                on_run(record)
    return results

