"""One vehicle of the fleet as its own process: ``evopose agent``.

Roles (DESIGN.md §1, paper §IV):

``uav``, ``ground-station``
    Camera vehicles. Per frame: acquire the simulated image -> extract the marks -> share them
    (``--share raw`` the image, ``features`` the points with the camera, ``hint`` the pose) -> solve or track
    with EvoPose using what team-mates shared (their images or feature sets as more views, eq. 4; their
    hints as individuals; an IMU attitude as eq. 3 knowledge) -> publish the pose estimate. With hints, the
    best pose is published as a 24-byte hint after every generation, between frames too.
``airship``
    Publishes its IMU attitude every frame and receives its own pose from the ground station.
``target``
    The simulated target: publishes its true pose every frame (ground truth for observers).

Every agent evaluates what it publishes or receives against the scenario's ground truth and ends
with a summary (JSON with ``--json``). Zenoh is used only through :class:`agents.bus.FleetBus`.
"""

from __future__ import annotations

import math
import statistics
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from evopose import SearchOptions
from evopose.cooperative import CooperativeEstimator, Estimate, Knowledge
from evopose.pose import wrap_angle
from protocol import Attitude, FeatureSet, ImageFrame, PoseEstimate, Topic
from scenarios.world import Scenario, build_scenario, load_scenario

from agents.transport.bus import FleetBus, Received
from agents.vehicle.memory import pin_mmap_threshold, release_free_memory
from agents.errors import FleetError
from agents.vehicle.frames import NS, FrameClock, SimulatedCamera
from agents.vehicle.team_views import (TeamViews, attitude_knowledge, build_views, encode_image, mate_view,
                         own_view, wait_until)
from agents.transport.session import SessionOptions
from agents.vehicle.config import CAMERA_ROLES, IDLE_GENERATIONS, TARGET_IMU_STREAM, AgentConfig

Emit = Callable[[dict], None]


def load_world(config: AgentConfig) -> Scenario:
    """The scenario, with its seed replaced by ``world_seed`` when given (each run of a scenario differs)."""
    scenario = load_scenario(config.scenario)
    if config.world_seed is not None:
        spec = scenario.spec.model_copy(update={"seed": int(config.world_seed)})
        scenario = build_scenario(spec, Path(scenario.path).parent if scenario.path else None, scenario.path)
    return scenario


def resolve_role(scenario: Scenario, vehicle: str, role: str | None) -> str:
    """The vehicle's role: the given one, else the scenario's; it must fit the vehicle (target or camera)."""
    target = scenario.spec.target
    if vehicle == target.name:
        found = role or target.role or "target"
        if found not in ("airship", "target"):
            raise FleetError(f"--vehicle {vehicle} is the scenario's target; its role is airship or target, "
                             f"not {found!r}")
        return found
    names = [v.name for v in scenario.vehicles]
    if vehicle not in names:
        raise FleetError(f"--vehicle {vehicle!r} is not in scenario {scenario.name!r} "
                         f"(vehicles: {', '.join(names)}; target: {target.name})")
    found = role or scenario.vehicle(vehicle).role or "uav"
    if found not in CAMERA_ROLES:
        raise FleetError(f"--vehicle {vehicle} carries a camera; its role is uav or ground-station, not {found!r}")
    return found


def pose_error(estimate: np.ndarray, truth: np.ndarray) -> dict:
    """Absolute errors: x, y, z in metres and roll, pitch, yaw in degrees; ``position`` the distance."""
    d = np.asarray(estimate, float) - np.asarray(truth, float)
    d[3:] = np.degrees(wrap_angle(d[3:]))
    out = {n: float(abs(v)) for n, v in zip(("x", "y", "z", "roll", "pitch", "yaw"), d)}
    out["position"] = float(np.linalg.norm(d[:3]))
    return out


def pose_dict(pose: np.ndarray) -> dict:
    return {n: float(v) for n, v in zip(("x", "y", "z", "roll", "pitch", "yaw"), pose)}


#: Recent values kept for medians and percentiles (bounded: an agent's memory must not grow with its frames).
RECENT = 4096


class ErrorTotals:
    """Running mean and max of each error component over the good frames (constant memory)."""

    def __init__(self) -> None:
        self.count = 0
        self.sums: dict[str, float] = {}
        self.maxima: dict[str, float] = {}

    def add(self, error: dict) -> None:
        self.count += 1
        for name, value in error.items():
            self.sums[name] = self.sums.get(name, 0.0) + value
            self.maxima[name] = max(self.maxima.get(name, 0.0), value)

    def summary(self) -> dict:
        out = {}
        for name, total in self.sums.items():
            out[f"error_{name}"] = total / self.count
            out[f"error_{name}_max"] = self.maxima[name]
        return out


@dataclass
class RunRecord:
    """What an agent measured over its run (the summary); constant memory however long it runs."""

    frames: int = 0
    estimates: int = 0
    good: int = 0
    solves: int = 0
    late_frames: int = 0
    multi_view_frames: int = 0
    first_good_s: float | None = None
    first_confirmed_s: float | None = None
    first_solve_s: float | None = None
    first_history: list = field(default_factory=list)
    hints_published: int = 0
    hints_used: int = 0
    last_pose: list | None = None
    last_error: dict | None = None
    errors: ErrorTotals = field(default_factory=ErrorTotals)
    frame_seconds: deque = field(default_factory=lambda: deque(maxlen=RECENT))
    mate_latency_s: deque = field(default_factory=lambda: deque(maxlen=RECENT))  # team-mates' data: arrival - stamp

    def summary(self) -> dict:
        out = {k: v for k, v in asdict(self).items() if k not in ("errors", "frame_seconds", "mate_latency_s")}
        out.update(self.errors.summary())
        if self.frame_seconds:
            out["frame_seconds_median"] = statistics.median(self.frame_seconds)
        if self.mate_latency_s:
            latency = np.array(self.mate_latency_s)
            out["mate_latency_median_s"] = float(np.median(latency))
            out["mate_latency_p95_s"] = float(np.percentile(latency, 95))
        return out


class VehicleAgent:
    """The per-frame loop of one vehicle on an open :class:`FleetBus` (see the module docstring)."""

    def __init__(self, config: AgentConfig, bus: FleetBus, scenario: Scenario, role: str, emit: Emit) -> None:
        self.config, self.bus, self.scenario, self.role, self.emit = config, bus, scenario, role, emit
        self.clock = FrameClock(config.fps or scenario.spec.fps, config.epoch_ns)
        self.period_s = 1.0 / self.clock.fps
        self.sync_wait_s = self.period_s / 2 if config.sync_wait_s is None else config.sync_wait_s
        self.record = RunRecord()
        self.team = TeamViews()
        self._hints: list[np.ndarray] = []
        self._hints_lock = threading.Lock()
        self._next_hint_s = 0.0
        self._hint_send_lock = threading.Lock()
        #: Held while the estimator is used: by the frame loop (per-frame estimate) and by the improver thread.
        self._estimator_lock = threading.Lock()
        self._started_ns = 0
        self._image_ready: float | None = None  # perf_counter when the first frame's image existed
        self._done = threading.Event()

    # -- set-up -----------------------------------------------------------------------------

    def subscribe(self) -> None:
        share, bus = self.config.share, self.bus
        if self.role in CAMERA_ROLES:
            if share == "raw":
                bus.subscribe(Topic.IMAGE)
            elif share == "features":
                bus.subscribe(Topic.FEATURES)
            elif share == "hint":
                bus.subscribe(Topic.HINT, self._on_hint)
            if self.role == "ground-station" and self.config.use_attitude:
                bus.subscribe(Topic.ATTITUDE)
        elif self.role == "airship":
            bus.subscribe(Topic.POSE)

    def _on_hint(self, rx: Received) -> None:  # bus worker thread: append only
        with self._hints_lock:
            self._hints.append(np.asarray(rx.message.pose, float))
            del self._hints[:-64]

    def take_hints(self) -> np.ndarray | None:
        with self._hints_lock:
            hints, self._hints = self._hints, []
            self.record.hints_used += len(hints)
        return np.array(hints) if hints else None

    # -- the loop ---------------------------------------------------------------------------

    def run(self, stop: threading.Event) -> dict:
        step = {"airship": self.airship_frame, "target": self.target_frame}.get(self.role, None)
        camera_loop = step is None
        if camera_loop:
            self.camera = SimulatedCamera(self.scenario, self.config.vehicle)
            self.estimator = CooperativeEstimator(self.scenario.model.evopose_model(), self.scenario.bounds(),
                                                  SearchOptions(time_budget=self.config.time_budget_s),
                                                  seed=self.config.seed)
            step = self.camera_frame
            self.warm_up()
        mates = [v for v in self.config.wait_for if v != self.config.vehicle]
        if mates:
            ok = self.bus.wait_for_teammates(mates, self.config.wait_timeout_s)
            self.emit({"event": "teammates", "vehicle": self.config.vehicle, "ready": ok,
                       "alive": sorted(self.bus.teammates())})
        self.emit({"event": "ready", "vehicle": self.config.vehicle, "role": self.role, "share": self.config.share,
                   "fps": self.clock.fps})
        improver = None
        if camera_loop and self.config.share in IDLE_GENERATIONS:
            improver = threading.Thread(target=self.improve, args=(stop,), name="improver", daemon=True)
            improver.start()
        try:
            return self._loop(step, stop)
        finally:
            self._done.set()
            if improver is not None:
                improver.join(2.0)

    def _loop(self, step, stop: threading.Event) -> dict:
        n = None
        while not stop.is_set() and (self.config.frames is None or self.record.frames < self.config.frames):
            nxt = self.clock.wait_next(n, stop)
            if nxt is None:
                break
            if n is not None and nxt > n + 1:
                self.record.late_frames += nxt - n - 1
            n = nxt
            if not self._started_ns:
                self._started_ns = self.clock.stamp_ns(n)
            step(n)
            self.record.frames += 1
        return self.summary()

    def warm_up(self) -> None:
        """Render once and solve once before frame 0, so that frame 0 is not slowed by caches and compilation."""
        frame = self.camera.acquire(0, self.clock.stamp_ns(0))
        views, _ = build_views([own_view(self.config.vehicle, 0, frame.camera, frame.points)])
        if views:
            CooperativeEstimator(self.estimator.model, self.estimator.bounds,
                                 SearchOptions(max_generations=1, min_starts=1)).estimate(views)
        release_free_memory()  # what the one-off work (ground texture, compilation) freed

    def summary(self) -> dict:
        return {"event": "summary", "vehicle": self.config.vehicle, "role": self.role, "share": self.config.share,
                "fleet": self.config.fleet, "scenario": self.scenario.name, "seed": self.config.seed,
                "world_seed": self.scenario.seed, "fps": self.clock.fps, **self.record.summary(),
                "teammates": sorted(self.bus.teammates()), "traffic": self.bus.counters.snapshot()}

    # -- camera vehicles --------------------------------------------------------------------------

    def camera_frame(self, n: int) -> None:
        stamp = self.clock.stamp_ns(n)
        t_acquire = time.perf_counter()
        frame = self.camera.acquire(n, stamp)
        if self._image_ready is None:
            self._image_ready = t_acquire + frame.render_s
        mine = own_view(self.config.vehicle, stamp, frame.camera, frame.points)
        self.share_frame(frame, mine)
        views, inputs = build_views([mine, *self.paired_views(stamp)])
        knowledge = self.knowledge()
        t0 = time.perf_counter()
        if not views:
            self.emit({"event": "no-estimate", "vehicle": self.config.vehicle, "frame": n,
                       "points": len(frame.points), "reason": "too few image points"})
            return
        hint_mode = self.config.share == "hint"
        with self._estimator_lock:
            estimate = self.estimator.estimate(
                views, knowledge=knowledge, hints=self.take_hints() if hint_mode else None, frame=n,
                hint_source=self.take_hints if hint_mode else None,
                on_generation=self._publish_generation if hint_mode else None)
        seconds = time.perf_counter() - t0
        self.record.frame_seconds.append(seconds)
        self.record.multi_view_frames += len(views) > 1
        if estimate.good_after_s is not None and self.record.first_good_s is None:
            self.record.first_good_s = t0 + estimate.good_after_s - self._image_ready
        self.publish_estimate(n, stamp, estimate, inputs, seconds, frame.truth, len(frame.points), knowledge)

    def share_frame(self, frame, mine) -> None:
        share, bus = self.config.share, self.bus
        if share == "features":
            bus.publish(FeatureSet(**bus.header(Topic.FEATURES, mine.stamp_ns), camera=mine.camera,
                                   points=mine.points.astype("<f4").tobytes()))
        elif share == "raw":
            header = bus.header(Topic.IMAGE, mine.stamp_ns)
            if self.config.image_encoding == "raw":
                message = ImageFrame.from_array(frame.image, mine.camera, **header)
            else:
                h, w = frame.image.shape[:2]
                message = ImageFrame(**header, camera=mine.camera, encoding=self.config.image_encoding, width=w,
                                     height=h, channels=3, data=encode_image(frame.image, self.config.image_encoding))
            bus.publish(message)

    def paired_views(self, stamp_ns: int) -> list:
        """Team-mates' views of this instant: wait up to ``sync_wait_s`` for each live, sharing team-mate."""
        share = self.config.share
        if share not in ("raw", "features"):
            return []
        topic = Topic.IMAGE if share == "raw" else Topic.FEATURES
        max_age = self.config.max_age_s

        def poll(timeout: float) -> None:
            rx = self.bus.recv(topic, timeout=timeout)
            while rx is not None:
                self.record.mate_latency_s.append((rx.received_ns - rx.stamp_ns) / NS)
                try:
                    self.team.add(mate_view(rx.vehicle, rx.message, self.camera.extract))
                except ValueError as err:  # a frame that does not decode: count it, carry on
                    self.bus.counters.count_rejected(topic.value, "undecodable")
                    self.emit({"event": "rejected", "vehicle": rx.vehicle, "reason": str(err)})
                rx = self.bus.recv(topic, timeout=0)

        poll(0)
        alive = self.bus.teammates()
        self.team.keep_only(alive)
        expected = self.team.sharing(alive, stamp_ns, max_age + self.period_s)
        deadline = time.monotonic() + self.sync_wait_s
        wait_until(lambda: set(self.team.at(stamp_ns, expected)) >= expected, deadline, poll)
        found = self.team.at(stamp_ns, expected)
        # a team-mate whose frame of this instant did not come in time: its newest fresh one
        found.update({m: v for m, v in self.team.newest(expected - set(found), stamp_ns, max_age).items()})
        return list(found.values())

    def knowledge(self) -> list[Knowledge]:
        if self.role != "ground-station" or not self.config.use_attitude:
            return []
        target = self.scenario.spec.target.name
        for rx in self.bus.latest(Topic.ATTITUDE).values():
            if isinstance(rx.message, Attitude) and rx.message.body == target:
                return attitude_knowledge(rx.message, self.config.attitude_sigmas)
        return []

    def _publish_generation(self, state) -> None:
        """Hint mode: the best of each generation of a search goes out at once (rate-limited)."""
        self._publish_hint(state.best_pose)

    def _publish_hint(self, pose: np.ndarray) -> None:
        """Send ``pose`` as a hint unless that would exceed ``hint_rate_hz`` (a schedule, not a minimum gap, so that
        a late wake-up does not lower the rate)."""
        period = 1.0 / self.config.hint_rate_hz
        with self._hint_send_lock:
            now = time.monotonic()
            if now < self._next_hint_s:
                return
            self._next_hint_s = max(self._next_hint_s + period, now - period)
            self.bus.publish_hint(pose)
            self.record.hints_published += 1

    def improve(self, stop: threading.Event) -> None:
        """The improver thread: generations on the latest views, with the hints that arrive (hint mode, where each
        new best goes out as a hint), at up to ``hint_rate_hz``, also while the frame loop renders the next image.
        The compiled kernels release the GIL, so this runs beside the frame loop on another core."""
        period = 1.0 / self.config.hint_rate_hz
        hint_mode = self.config.share == "hint"
        next_s = time.monotonic()
        while not stop.is_set() and not self._done.is_set():
            with self._estimator_lock:
                estimate = self.estimator.generation(self.take_hints() if hint_mode else None)
            if estimate is not None and hint_mode:
                self._publish_hint(estimate.pose)
            now = time.monotonic()
            next_s = max(next_s + period, now - period)
            self._done.wait(max(0.0, next_s - now) if estimate is not None else 0.01)

    def publish_estimate(self, n: int, stamp: int, estimate: Estimate, inputs: list[str], seconds: float,
                         truth: np.ndarray, points: int, knowledge: list[Knowledge]) -> None:
        sol, rec = estimate.solution, self.record
        rec.estimates += 1
        rec.solves += int(estimate.solved)
        if estimate.solved and rec.first_solve_s is None:
            rec.first_history = [float(f) for f in sol.history]
            rec.first_solve_s = seconds
        error = pose_error(sol.pose, truth)
        if estimate.good:
            rec.good += 1
            rec.errors.add(error)
            if rec.first_confirmed_s is None:
                rec.first_confirmed_s = time.perf_counter() - self._image_ready
        rec.last_pose, rec.last_error = [float(v) for v in sol.pose], error
        target = self.scenario.spec.target.name
        self.bus.publish(PoseEstimate(**self.bus.header(Topic.POSE, stamp), target=target,
                                      pose=tuple(float(v) for v in sol.pose), fitness=float(sol.fitness),
                                      mismatch=estimate.mismatch, converged=estimate.good,
                                      generations=int(sol.generations), seconds=seconds,
                                      from_hint=bool(sol.from_hint),
                                      inputs=tuple(v for v in inputs if v != self.config.vehicle)))
        if self.config.share == "hint" and estimate.good:
            self._publish_hint(sol.pose)
        self.emit({"event": "frame", "vehicle": self.config.vehicle, "frame": n, "stamp_ns": stamp,
                   "points": points, "views": inputs, "knowledge": [k.name for k in knowledge],
                   "pose": pose_dict(sol.pose), "fitness": float(sol.fitness), "mismatch": estimate.mismatch,
                   "good": estimate.good, "solved": estimate.solved, "from_hint": bool(sol.from_hint),
                   "seconds": seconds, "error": error})

    # -- airship and target -----------------------------------------------------------------------

    def airship_frame(self, n: int) -> None:
        """Publish the IMU attitude of this frame; evaluate the poses the ground station sent back."""
        scene = n % self.scenario.frames
        truth = self.scenario.target_pose(scene)
        imu = self.scenario.target_imu
        if imu is not None:
            rpy = imu.read(truth[3:], self.scenario.seed, TARGET_IMU_STREAM, scene)
            sigma = float(math.hypot(imu.bias_sigma, imu.noise_sigma))
            self.bus.publish(Attitude(**self.bus.header(Topic.ATTITUDE, self.clock.stamp_ns(n)),
                                      body=self.config.vehicle, roll=float(rpy[0]), pitch=float(rpy[1]),
                                      yaw=float(rpy[2]), sigma=(sigma, sigma, sigma)))
        self._receive_own_pose()

    def _receive_own_pose(self) -> None:
        rx = self.bus.recv(Topic.POSE, timeout=0)
        while rx is not None:
            message = rx.message
            if isinstance(message, PoseEstimate) and message.target == self.config.vehicle:
                k = self.clock.index_of(message.stamp_ns)
                if k is not None:
                    error = pose_error(np.array(message.pose), self.scenario.target_pose(k % self.scenario.frames))
                    self.record.estimates += 1
                    self.record.last_pose, self.record.last_error = list(message.pose), error
                    if message.converged:
                        self.record.good += 1
                        self.record.errors.add(error)
                        if self.record.first_good_s is None:
                            self.record.first_good_s = (rx.received_ns - self._started_ns) / NS
                    self.emit({"event": "own-pose", "vehicle": self.config.vehicle, "from": rx.vehicle,
                               "frame": k, "pose": pose_dict(np.array(message.pose)), "good": message.converged,
                               "latency_s": (rx.received_ns - message.stamp_ns) / NS, "error": error})
            rx = self.bus.recv(Topic.POSE, timeout=0)

    def target_frame(self, n: int) -> None:
        """Publish the true pose of this frame (ground truth for observers)."""
        truth = self.scenario.target_pose(n % self.scenario.frames)
        self.bus.publish(PoseEstimate(**self.bus.header(Topic.POSE, self.clock.stamp_ns(n)),
                                      target=self.config.vehicle, pose=tuple(float(v) for v in truth), fitness=0.0,
                                      mismatch=0.0, converged=True, generations=0, seconds=0.0))


def run_agent(options: SessionOptions, config: AgentConfig, stop: threading.Event, emit: Emit) -> dict:
    """Open the bus and run the vehicle until ``stop`` or ``config.frames``; returns the summary."""
    config.check()
    pin_mmap_threshold()
    scenario = load_world(config)
    role = resolve_role(scenario, config.vehicle, config.role)
    if role in CAMERA_ROLES:
        scenario.bounds()  # a camera vehicle needs the operating area: fail before joining the fleet
    with FleetBus.open(options, config.fleet, config.vehicle, max_age_s=config.max_age_s, stats_period_s=1.0,
                       on_join=lambda v: emit({"event": "join", "vehicle": v}),
                       on_leave=lambda v: emit({"event": "leave", "vehicle": v})) as bus:
        agent = VehicleAgent(config, bus, scenario, role, emit)
        agent.subscribe()
        return agent.run(stop)
