"""The vehicle roles as classes, each running its frame loop on an open :class:`FleetBus` (paper §IV).

- :class:`CameraVehicle` (``uav``): per frame, acquire the image -> extract the marks -> share them ->
  :func:`agents.vehicle.step.step` -> publish its outbox. With hints (and alone), an improver thread runs
  generations between frames (the compiled kernels release the GIL) and its bests leave as hints.
- :class:`GroundStation`: a camera vehicle that also holds the attitude within the airship's IMU reading
  (eq. 3).
- :class:`~agents.vehicle.target_roles.Airship` and :class:`~agents.vehicle.target_roles.Target`: the roles of
  the target itself (its IMU attitude out, its own pose back; its true pose for observers).
"""

from __future__ import annotations

import threading
from abc import ABC, abstractmethod
import time
from collections.abc import Callable

import cv2
import numpy as np

from evopose import SearchOptions
from evopose.cooperative import CooperativeEstimator, Knowledge
from protocol import MESSAGE_TYPES, Attitude, Topic
from scenarios.world import Scenario

from agents.errors import TeamNotMetError
from agents.runs import PoseRow
from agents.transport.bus import FleetBus, Received
from agents.vehicle.config import IDLE_GENERATIONS, AgentConfig
from agents.vehicle.frames import NS, FrameClock
from agents.vehicle.memory import release_free_memory
from agents.vehicle.plausibility import Plausibility
from agents.vehicle.records import RunRecord
from agents.vehicle.sources import SourceEnded, SourceError, open_camera
from agents.vehicle.step import FrameInputs, Outgoing, share, step
from agents.vehicle.team_views import TeamViews, attitude_knowledge, build_views, mate_view, own_view, wait_until

Emit = Callable[[dict], None]
#: Share of a frame's period a search from scratch may take in the frame loop (the rest: render, extract, share).
SEARCH_SHARE_OF_FRAME = 0.5
#: Frames estimated before joining (a search, then tracking), so that no frame compiles a kernel.
WARM_UP_FRAMES = 3
#: Hints kept while waiting for the next frame or generation (the newest).
HINTS_KEPT = 64


class SlotSchedule:
    """At most ``rate_hz`` events (hints, generations) a second on average, with a backlog of at most ``burst``.

    Slots missed while the frame loop had the interpreter are made up afterwards (up to ``burst`` of them), so
    the rate over a frame period is kept although the generations run only between frames.
    """

    def __init__(self, rate_hz: float, burst: int = 1) -> None:
        self.period, self.next_s, self.burst = 1.0 / rate_hz, 0.0, max(int(burst), 1)

    def due(self, now_s: float) -> bool:
        """True (and the next slot booked) when a slot is free at ``now_s``."""
        if now_s < self.next_s:
            return False
        self.next_s = max(self.next_s + self.period, now_s - (self.burst - 1) * self.period)
        return True

    def wait_s(self, now_s: float) -> float:
        """Seconds until the next slot (0 when one is free)."""
        return max(self.next_s - now_s, 0.0)


class Vehicle(ABC):
    """The frame loop every role shares: one ``frame(n)`` per tick of the fleet's clock, a summary at the end."""

    role = "vehicle"

    def __init__(self, config: AgentConfig, bus: FleetBus, scenario: Scenario, emit: Emit) -> None:
        self.config, self.bus, self.scenario, self.emit = config, bus, scenario, emit
        self.clock = FrameClock(config.fps or scenario.spec.fps, config.epoch_ns)
        self.period_s = 1.0 / self.clock.fps
        self.record = RunRecord()
        self._started_ns = 0
        self._cpu_started_s = 0.0

    def subscribe(self) -> None:
        """Declare the subscriptions of the role (before the first frame)."""

    @classmethod
    def warm_up(cls, config: AgentConfig, scenario: Scenario) -> None:
        """One-off work before joining the fleet (compilation, caches), so that a team-mate that sees this
        vehicle present can start its frames at once: a present vehicle is a ready one."""

    @abstractmethod
    def frame(self, n: int) -> None:
        """Everything the role does at frame ``n`` of the fleet's clock (each role defines it)."""

    def run(self, stop: threading.Event) -> dict:
        mates = [v for v in self.config.wait_for if v != self.config.vehicle]
        if mates:  # warmed up before joining (warm_up): present team-mates are ready ones
            ok = self.bus.wait_for_teammates(mates, self.config.wait_timeout_s)
            alive = sorted(self.bus.teammates())
            self.emit({"event": "teammates", "vehicle": self.config.vehicle, "ready": ok, "alive": alive})
            if not ok:  # a team that never met is an error, not a run alone (docs/security.md)
                missing = sorted(set(mates) - set(alive))
                raise TeamNotMetError(f"team-mates {', '.join(missing)} of {self.config.vehicle} did not appear in "
                                      f"fleet {self.config.fleet!r} within {self.config.wait_timeout_s:g} s "
                                      "(--wait-timeout); check --connect/--listen (multicast scouting is off "
                                      "unless --multicast)")
        self.emit({"event": "ready", "vehicle": self.config.vehicle, "role": self.role, "share": self.config.share,
                   "fps": self.clock.fps})
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
                self._cpu_started_s = time.process_time()
            try:
                self.frame(n)
            except SourceEnded:  # a video file or image sequence has no more frames: a clean end, not an error
                self.emit({"event": "end-of-source", "vehicle": self.config.vehicle, "frames": self.record.frames})
                break
            self.record.frames += 1
        return self.summary()

    def publish(self, out: Outgoing) -> None:
        """Publish one outbox message (the bus adds sender and sequence number)."""
        if out.topic == Topic.HINT.value:
            self.bus.publish_hint(out.fields["pose"])
            return
        cls = MESSAGE_TYPES[Topic(out.topic)]
        self.bus.publish(cls(**self.bus.header(out.topic, out.stamp_ns), **out.fields))

    def summary(self) -> dict:
        return {"event": "summary", "vehicle": self.config.vehicle, "role": self.role, "share": self.config.share,
                "fleet": self.config.fleet, "scenario": self.scenario.name, "seed": self.config.seed,
                "world_seed": self.scenario.seed, "fps": self.clock.fps, **self.record.summary(),
                # from the first frame's instant to the end of the last frame (rates per second of the run)
                "run_s": (time.time_ns() - self._started_ns) / NS if self._started_ns else 0.0,
                # CPU seconds of the whole process (every thread) over the same span: per frame, what a vehicle
                # of a team this size costs (of which ``render_cpu_s``: the simulated camera, not a vehicle's work)
                "cpu_s": time.process_time() - self._cpu_started_s if self._started_ns else 0.0,
                "teammates": sorted(self.bus.teammates()), "traffic": self.bus.counters.snapshot()}


class CameraVehicle(Vehicle):
    """A UAV with a camera: localizes the target from its own and its team-mates' data."""

    role = "uav"

    def __init__(self, config: AgentConfig, bus: FleetBus, scenario: Scenario, emit: Emit) -> None:
        super().__init__(config, bus, scenario, emit)
        self.sync_wait_s = self.period_s / 2 if config.sync_wait_s is None else config.sync_wait_s
        self.team = TeamViews()
        self.camera = open_camera(config, scenario, bus)  # the renderer, or a real source (--source; ROS topics on
        # the bus's session)
        self.plausible = Plausibility(scenario.bounds(), config.operating_radius_m, config.max_clock_offset_s)
        self.estimator = CooperativeEstimator(scenario.model.evopose_model(), scenario.bounds(),
                                              SearchOptions(time_budget=config.time_budget_s,
                                                            view_weights=config.view_weights), seed=config.seed)
        self._hints: list[np.ndarray] = []
        self._latest_hint: np.ndarray | None = None
        self._sharing_mates: set[str] = set()  # team-mates that ever sent views
        self._stale: set[str] = set()  # of those, the live ones whose data are stale now
        self._hints_lock = threading.Lock()
        # slots missed during a frame are made up after it (at most a frame period's worth)
        burst = max(int(config.hint_rate_hz * self.period_s), 1)
        self._hint_schedule = SlotSchedule(config.hint_rate_hz, burst)
        self._generation_schedule = SlotSchedule(config.hint_rate_hz, burst)
        self._hint_send_lock = threading.Lock()
        #: held while the estimator is used: by the frame loop and by the improver thread (one writer at a time)
        self._estimator_lock = threading.Lock()
        #: set while no frame is in progress: the improver runs only then, so the frame loop keeps the camera rate
        #: (both share one interpreter; a generation between frames never delays a frame by more than itself)
        self._between_frames = threading.Event()
        self._between_frames.set()
        self._image_ready: float | None = None  # perf_counter when the first frame's image existed
        self._done = threading.Event()

    # -- set-up ---------------------------------------------------------------------------------

    def subscribe(self) -> None:
        share_mode, bus = self.config.share, self.bus
        if share_mode == "raw":
            bus.subscribe(Topic.IMAGE)
        elif share_mode == "features":
            bus.subscribe(Topic.FEATURES)
        elif share_mode == "hint":
            bus.subscribe(Topic.HINT, self._on_hint)

    @classmethod
    def warm_up(cls, config: AgentConfig, scenario: Scenario) -> None:
        """Render once and solve once before joining, so that frame 0 is not slowed by caches and compilation
        (both are per process: the renderer's caches and the compiled kernels)."""
        camera = open_camera(config, scenario)  # a bad --source or camera file fails here, before joining
        try:
            frame = camera.acquire(0, 0)
        except SourceEnded:
            raise SourceError(f"--source {config.source}: no frames") from None
        finally:
            camera.close()
        views, _ = build_views([own_view(config.vehicle, 0, frame.camera, frame.points, frame.labels)])
        if views:  # every path a frame may take compiles here: a search, tracking (eq. 2), a team-mate's best
            estimator = CooperativeEstimator(scenario.model.evopose_model(), scenario.bounds(),
                                             SearchOptions(max_generations=1, min_starts=1))
            for k in range(WARM_UP_FRAMES):
                best = estimator.current_best
                estimator.estimate(views, frame=k, candidates=None if best is None else np.array([best]))
            estimator.generation(budget_s=0.0)
        release_free_memory()  # what the one-off work (ground texture, compilation) freed

    def run(self, stop: threading.Event) -> dict:
        improver = None
        if self.config.share in IDLE_GENERATIONS:
            improver = threading.Thread(target=self.improve, args=(stop,), name="improver", daemon=True)
        try:
            if improver is not None:
                improver.start()
            summary = super().run(stop)
            source = getattr(self.camera, "summary_fields", None)  # a dataset: which, and whether the target is in it
            if source is not None:
                summary.update(source())
                if not summary["target_visible"]:  # no target in the images: every good frame is a false positive
                    summary["false_positives"] = summary["good"]
            return summary
        finally:
            self._done.set()
            if improver is not None and improver.is_alive():
                improver.join(2.0)
            self.camera.close()

    # -- inputs ---------------------------------------------------------------------------------

    def refused(self, topic: Topic, rx: Received, reason: str | None) -> bool:
        """Count a received message that a sane team-mate could not have sent (:mod:`.plausibility`)."""
        if reason is None:
            reason = self.plausible.stamp(rx.stamp_ns, time.time_ns())
        if reason is None:
            return False
        self.bus.counters.count_rejected(topic.value, reason)
        return True

    def _on_hint(self, rx: Received) -> None:  # bus worker thread: check and append only
        if self.refused(Topic.HINT, rx, self.plausible.pose_in_box(rx.message.pose)):
            return
        with self._hints_lock:
            self._latest_hint = np.asarray(rx.message.pose, float)
            self._hints.append(self._latest_hint)
            del self._hints[:-HINTS_KEPT]

    def latest_hint(self) -> np.ndarray | None:
        """The newest team-mate's hint (kept after the improver took it), then forgotten."""
        with self._hints_lock:
            hint, self._latest_hint = self._latest_hint, None
        return hint

    def take_hints(self) -> np.ndarray | None:
        with self._hints_lock:
            hints, self._hints = self._hints, []
            self.record.hints_used += len(hints)
        return np.array(hints) if hints else None

    def knowledge(self) -> list[Knowledge]:
        """Eq. (3) knowledge of this frame (none for a UAV)."""
        return []

    def paired_views(self, stamp_ns: int) -> list:
        """Team-mates' views of this instant: wait up to ``sync_wait_s`` for each live, sharing team-mate."""
        share_mode = self.config.share
        if share_mode not in ("raw", "features"):
            return []
        topic = Topic.IMAGE if share_mode == "raw" else Topic.FEATURES
        max_age = self.config.max_age_s

        def poll(timeout: float) -> None:
            rx = self.bus.recv(topic, timeout=timeout)
            while rx is not None:
                self.record.mate_latency_s.append((rx.received_ns - rx.stamp_ns) / NS)
                reason = (self.plausible.feature_set(rx.message) if topic == Topic.FEATURES
                          else self.plausible.camera(rx.message.camera))
                if not self.refused(topic, rx, reason):
                    try:
                        self.team.add(mate_view(rx.vehicle, rx.message, self.camera.extract))
                    except (ValueError, cv2.error) as err:  # a frame that does not decode: count it, carry on
                        self.bus.counters.count_rejected(topic.value, "undecodable")
                        self.emit({"event": "rejected", "vehicle": rx.vehicle, "reason": str(err)[:200]})
                rx = self.bus.recv(topic, timeout=0)

        poll(0)
        alive = self.bus.teammates()
        self.team.keep_only(alive)
        expected = self.team.sharing(alive, stamp_ns, max_age + self.period_s)
        self._report_staleness(alive, expected, stamp_ns)
        expected = self.team.on_clock(expected, lambda stamp: self.clock.index_of(stamp) is not None)
        if not self.record.frames:  # the first frame: the team waited for is expected before anything came from it
            expected |= set(self.config.wait_for) & set(alive)
        deadline = time.monotonic() + self.sync_wait_s
        wait_until(lambda: set(self.team.at(stamp_ns, expected)) >= expected, deadline, poll)
        found = self.team.at(stamp_ns, expected)
        # a team-mate whose frame of this instant did not come in time: its newest fresh one
        found.update(self.team.newest(expected - set(found), stamp_ns, max_age))
        return list(found.values())

    def _report_staleness(self, alive: frozenset[str], fresh: set[str], stamp_ns: int) -> None:
        """A live team-mate whose data went stale (frozen, or a cut link: nothing newer than ``--max-age`` and the
        frame in progress) is no longer waited for; say so once, with the age of its newest data at this frame,
        and again when its data are fresh again."""
        stale = set(alive) & self._sharing_mates - fresh
        for mate in sorted(stale - self._stale):
            self.record.stale_events += 1
            newest = self.team.newest_stamp_ns(mate)
            self.emit({"event": "stale", "vehicle": mate, "by": self.config.vehicle,
                       "age_s": None if newest is None else (stamp_ns - newest) / 1e9})
        for mate in sorted(self._stale & fresh):
            self.emit({"event": "fresh", "vehicle": mate, "by": self.config.vehicle})
        self._stale = stale
        self._sharing_mates |= fresh

    # -- the frame ------------------------------------------------------------------------------

    def frame(self, n: int) -> None:
        self._between_frames.clear()
        try:
            self._frame(n)
        finally:
            self._between_frames.set()

    def _frame(self, n: int) -> None:
        stamp = self.clock.stamp_ns(n)
        t_acquire = time.perf_counter()
        frame = self.camera.acquire(n, stamp)
        self.record.render_cpu_s += frame.render_cpu_s
        if self._image_ready is None:
            self._image_ready = t_acquire + frame.render_s
        mine = own_view(self.config.vehicle, stamp, frame.camera, frame.points, frame.labels)
        with self._estimator_lock:
            best = self.estimator.current_best
        shared = share(self.config.share, self.config.image_encoding, frame, mine, best)
        if shared is not None:
            self.publish(shared)
        hint_mode = self.config.share == "hint"
        inputs = FrameInputs(n, mine, self.paired_views(stamp), self.knowledge(),
                             self.take_hints() if hint_mode else None, frame.truth,
                             self.latest_hint() if hint_mode else None)
        # slices of a fixed number of generations (same views on every vehicle) are capped at a whole frame
        same_views = self.config.share in ("features", "raw")
        budget = (1.0 if same_views else SEARCH_SHARE_OF_FRAME) * self.period_s
        with self._estimator_lock:
            result = step(self.estimator, inputs, vehicle=self.config.vehicle,
                          target=self.scenario.spec.target.name, share_mode=self.config.share, budget_s=budget)
        for out in result.outbox:
            if out.topic == Topic.HINT.value:
                self.send_hint(out.fields["pose"])
            else:
                self.publish(out)
        result.event["scene_frame"] = frame.scene_frame  # the scenario's frame, or the source's frame number
        if frame.skipped is not None:  # the own view was not taken (a stale live input): say why, not "too few"
            result.event["skipped"] = frame.skipped
            if result.event.get("event") == "no-estimate":
                result.event["reason"] = f"no usable frame: {frame.skipped}"
        self.account(result)
        self.emit(result.event)

    def account(self, result) -> None:
        """The run record of one frame's result."""
        estimate, rec = result.estimate, self.record
        if estimate is None:
            return
        rec.frame_seconds.append(result.seconds)
        rec.multi_view_frames += len(result.inputs) > 1
        rec.estimates += 1
        rec.solves += int(estimate.solved)
        sol = estimate.solution
        if estimate.solved and rec.first_solve_s is None:
            rec.first_history = [float(f) for f in sol.history]
            rec.first_solve_s = result.seconds
        error, good = result.event.get("error"), result.event["good"]  # good: converged and confident
        if good and rec.first_good_s is None:  # the paper's time to a good pose: when the best first was good
            rec.first_good_s = (estimate.good_at or time.perf_counter()) - self._image_ready
        if good:
            rec.good += 1
            if error is not None:
                rec.errors.add(error)
            if rec.first_confirmed_s is None:
                rec.first_confirmed_s = time.perf_counter() - self._image_ready
        rec.last_pose, rec.last_error = list(result.outbox[0].fields["pose"]), error
        rec.poses.append(PoseRow(result.event["frame"], tuple(rec.last_pose), bool(good)))

    # -- between frames ---------------------------------------------------------------------------

    def send_hint(self, pose: np.ndarray) -> None:
        """Send ``pose`` as a hint unless that would exceed ``hint_rate_hz``."""
        with self._hint_send_lock:
            if not self._hint_schedule.due(time.monotonic()):
                return
            self.bus.publish_hint(pose)
            self.record.hints_published += 1

    def improve(self, stop: threading.Event) -> None:
        """The improver thread: between frames, generations on the latest views (and the search in progress) with
        the hints that arrived; in hint mode each good best goes out as a hint. One generation per slot of
        ``hint_rate_hz``; the slots that fell during a frame are made up after it."""
        period = 1.0 / self.config.hint_rate_hz
        hint_mode = self.config.share == "hint"
        schedule = self._generation_schedule
        while not stop.is_set() and not self._done.is_set():
            if not self._between_frames.wait(0.1):
                continue
            now = time.monotonic()
            if not schedule.due(now):
                self._done.wait(schedule.wait_s(now))
                continue
            with self._estimator_lock:
                estimate = self.estimator.generation(self.take_hints() if hint_mode else None, budget_s=period)
            if estimate is None:  # nothing to improve before the first estimate
                self._done.wait(0.01)
            # a search's best so far, or an unsure pose, is no hint
            elif estimate.good and estimate.solution.confident and hint_mode:
                self.send_hint(estimate.pose)


class GroundStation(CameraVehicle):
    """A fixed camera (paper Experiment 1) that holds the attitude within the airship's IMU reading (eq. 3)."""

    role = "ground-station"

    def subscribe(self) -> None:
        super().subscribe()
        if self.config.use_attitude:
            self.bus.subscribe(Topic.ATTITUDE)

    def knowledge(self) -> list[Knowledge]:
        if not self.config.use_attitude:
            return []
        target = self.scenario.spec.target.name
        for rx in self.bus.latest(Topic.ATTITUDE).values():
            if isinstance(rx.message, Attitude) and rx.message.body == target:
                if self.refused(Topic.ATTITUDE, rx, self.plausible.attitude(rx.message)):
                    continue
                return attitude_knowledge(rx.message, self.config.attitude_sigmas)
        return []


__all__ = ["CameraVehicle", "GroundStation", "SlotSchedule", "Vehicle"]
