"""The vehicle roles as classes, each running its frame loop on an open :class:`FleetBus` (paper §IV).

- :class:`CameraVehicle` (``uav``): per frame, acquire the image (marks extracted) -> publish
  :func:`agents.vehicle.step.share`'s message -> pair team-mates' views -> :func:`agents.vehicle.step.step` ->
  publish its messages. With hints (and alone), the frame loop runs generations in the time left until the next
  tick (:func:`agents.vehicle.step.idle`) and good bests leave as hints. One thread owns the vehicle's state: the
  frame loop; the bus's workers only queue what arrives.
- :class:`GroundStation`: a camera vehicle that also holds the attitude within the airship's IMU reading
  (eq. 3).
- :class:`~agents.vehicle.target_roles.Airship` and :class:`~agents.vehicle.target_roles.Target`: the roles of
  the target itself (its IMU attitude out, its own pose back; its true pose for observers).
"""

from __future__ import annotations

import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import replace

import cv2
import numpy as np

from evopose import SearchOptions
from evopose.cooperative import Cooperation, EstimatorState, Knowledge
from protocol import Attitude, Message, Topic
from protocol.hint import Hint
from scenarios.world import Scenario

from agents.errors import TeamNotMetError
from agents.transport.bus import FleetBus, Received
from agents.vehicle.config import AgentConfig
from agents.vehicle.frames import NS, fleet_clock
from agents.vehicle.hints import HintInbox
from agents.vehicle.memory import release_free_memory, reuse_frame_memory
from agents.vehicle.plausibility import Plausibility
from agents.vehicle.records import RunRecord
from agents.vehicle.cameras import open_camera
from agents.vehicle.sources import SourceEnded, SourceError
from agents.vehicle.step import FrameInputs, VehicleState, idle, share, share_policy, step
from agents.vehicle.team_views import (Staleness, TeamViews, attitude_knowledge, build_views, mate_view, own_view,
                                       wait_until)

Emit = Callable[[dict], None]
#: Frames estimated before joining (a search, then tracking), so that no frame compiles a kernel.
WARM_UP_FRAMES = 3


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
        self.clock = fleet_clock(config.fps, scenario, config.epoch_ns)
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
                                      "unless --multicast)", missing)
        self.emit({"event": "ready", "vehicle": self.config.vehicle, "role": self.role, "share": self.config.share,
                   "fps": self.clock.fps})
        n = None
        while not stop.is_set() and (self.config.frames is None or self.record.frames < self.config.frames):
            nxt = self.next_frame(n, stop)
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

    def next_frame(self, n: int | None, stop: threading.Event) -> int | None:
        """Wait for the clock's frame after ``n`` (None: stopped); roles that work between frames do it here."""
        return self.clock.wait_next(n, stop)

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
        self.policy = share_policy(config.share)
        self.sync_wait_s = self.period_s / 2 if config.sync_wait_s is None else config.sync_wait_s
        self.team = TeamViews()
        self.staleness = Staleness()
        self.camera = open_camera(config, scenario, bus)  # the renderer, or a real source (--source; ROS topics on
        # the bus's session)
        self.plausible = Plausibility(scenario.bounds(), config.operating_radius_m, config.max_clock_offset_s)
        self.state = VehicleState(
            Cooperation(scenario.model.evopose_model(), scenario.bounds(),
                        SearchOptions(time_budget=config.time_budget_s, view_weights=config.view_weights,
                                      confidence=scenario.model.confidence_rules(self.period_s)),
                        config.seed),
            self.policy, config.vehicle, scenario.spec.target.name, config.image_encoding,
            frame_period_s=self.period_s)
        self.hints = HintInbox()
        # slots missed during a frame are made up after it (at most a frame period's worth)
        burst = max(int(config.hint_rate_hz * self.period_s), 1)
        self._hint_schedule = SlotSchedule(config.hint_rate_hz, burst)
        self._generation_schedule = SlotSchedule(config.hint_rate_hz, burst)
        self._image_ready: float | None = None  # perf_counter when the first frame's image existed

    # -- set-up ---------------------------------------------------------------------------------

    def subscribe(self) -> None:
        if self.policy.shares is not None:
            self.bus.subscribe(self.policy.shares)
        if self.policy.takes_hints:
            self.bus.subscribe(Topic.HINT, self._on_hint)

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
            rules = Cooperation(scenario.model.evopose_model(), scenario.bounds(),
                                SearchOptions(max_generations=1, min_starts=1))
            state = EstimatorState()
            for k in range(WARM_UP_FRAMES):
                best = state.current_best
                state, _ = rules.estimate(state, views, frame=k, candidates=None if best is None else best[None])
            rules.generation(state, budget_s=0.0)
        release_free_memory()  # what the one-off work (ground texture, compilation) freed
        reuse_frame_memory()  # then the frames' arrays from the heap, not one mapping each (agents/vehicle/memory.py)

    def run(self, stop: threading.Event) -> dict:
        first = getattr(self.camera, "first_stamp_ns", lambda: None)()  # a recording on the fleet's common clock
        if first is not None:  # plays its first frame's instant first, however late it starts (PlaybackClock)
            self._play_at(first)
        try:
            summary = super().run(stop)
            source = getattr(self.camera, "summary_fields", None)  # a dataset: which, and whether the target is in it
            if source is not None:
                summary.update(source())
                if not summary["target_visible"]:  # no target in the images: every good frame is a false positive
                    summary["false_positives"] = summary["good"]
            return summary
        finally:
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

    def _on_hint(self, rx: Received) -> None:  # bus worker thread: check and queue only
        if not self.refused(Topic.HINT, rx, self.plausible.pose_in_box(rx.message.pose)):
            self.hints.put(rx.message.pose)

    def take_hints(self) -> np.ndarray | None:
        """Every hint waiting (H, 6), counted as used."""
        hints = self.hints.take_all()
        self.record.hints_used += 0 if hints is None else len(hints)
        return hints

    def knowledge(self) -> list[Knowledge]:
        """Eq. (3) knowledge of this frame (none for a UAV)."""
        return []

    def paired_views(self, stamp_ns: int, near: np.ndarray | None = None) -> list:
        """Team-mates' views of this instant: wait up to ``sync_wait_s`` (the first frame: ``max_age_s``) for each live,
        sharing team-mate. A team-mate's raw image is searched around ``near`` first, as the own image was: team-mates
        that published the same pose find the same points in one image."""
        topic = self.policy.shares
        if topic is None:
            return []
        max_age = self.config.max_age_s

        def poll(timeout: float) -> None:
            rx = self.bus.recv(topic, timeout=timeout)
            while rx is not None:
                self.record.mate_latency_s.append((rx.received_ns - rx.stamp_ns) / NS)
                reason = (self.plausible.feature_set(rx.message) if topic == Topic.FEATURES
                          else self.plausible.camera(rx.message.camera))
                if not self.refused(topic, rx, reason):
                    try:
                        self.team.add(mate_view(rx.vehicle, rx.message, self.camera.extract, near))
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
        wait_s = self.sync_wait_s
        if not self.record.frames:  # the first frame: the team waited for is expected before anything came from it
            # (its camera vehicles: the target, waited for too, has no view to share and was waited for in vain),
            expected |= set(self.config.wait_for) & set(alive) & {v.name for v in self.scenario.spec.vehicles}
            # and given up to max_age: team-mates start their first frame as unevenly as processes start (imports,
            # first calls); a first frame solved alone is a first pose the team does not share
            wait_s = max(wait_s, max_age)
        deadline = time.monotonic() + wait_s
        wait_until(lambda: set(self.team.at(stamp_ns, expected)) >= expected, deadline, poll)
        found = self.team.at(stamp_ns, expected)
        # a team-mate whose frame of this instant did not come in time: its newest fresh one
        found.update(self.team.newest(expected - set(found), stamp_ns, max_age))
        return list(found.values())

    def _report_staleness(self, alive: frozenset[str], fresh: set[str], stamp_ns: int) -> None:
        """Say once when a live team-mate's data went stale (with the age of its newest data at this frame), and
        again when they are fresh (:class:`Staleness`)."""
        self.staleness, stale, back = self.staleness.update(alive, fresh)
        for mate in stale:
            self.record.stale_events += 1
            newest = self.team.newest_stamp_ns(mate)
            self.emit({"event": "stale", "vehicle": mate, "by": self.config.vehicle,
                       "age_s": None if newest is None else (stamp_ns - newest) / 1e9})
        for mate in back:
            self.emit({"event": "fresh", "vehicle": mate, "by": self.config.vehicle})

    def _play_at(self, stamp_ns: int) -> None:
        """The instant this vehicle is at is ``stamp_ns``'s: a recording played behind the wall clock judges
        team-mates' data there, and that instant does not pass the next frame's while this one is worked on
        (agents/transport/playback.py)."""
        self.bus.playback.play_behind(time.time_ns() - stamp_ns, until_ns=stamp_ns + int(self.period_s * NS))

    # -- the frame ------------------------------------------------------------------------------

    def frame(self, n: int) -> None:
        # how late the frame starts after its tick and where its time goes, in the frame's JSON line (``timing_s``):
        # a tick is skipped when a frame ends after the tick after next (Vehicle.run)
        late_s = (time.time_ns() - self.clock.stamp_ns(n)) / NS
        t_acquire, cpu0 = time.perf_counter(), time.thread_time()
        # the front-end looks around the last good pose first (vision.window): a fraction of the image's pixels
        near = self.state.near(n)
        frame = self.camera.acquire(n, self.clock.stamp_ns(n), near=near)
        stamp = frame.stamp_ns  # when the image was taken: tick n's, or a recording's own instant (dataset_source)
        self._play_at(stamp)
        self.record.render_cpu_s += frame.render_cpu_s
        if self._image_ready is None:
            self._image_ready = t_acquire + frame.render_s
        mine = own_view(self.config.vehicle, stamp, frame.camera, frame.points, frame.labels)
        shared = share(self.state, frame, mine)
        if shared is not None:
            self.bus.send(shared)
        takes = self.policy.takes_hints
        t_pair = time.perf_counter()
        paired = self.paired_views(stamp, near)
        t_step = time.perf_counter()
        inputs = FrameInputs(n, mine, paired, self.knowledge(), self.take_hints() if takes else None,
                             frame.truth, self.hints.take_latest() if takes else None,
                             self.policy.search_share_of_frame * self.period_s)
        try:
            self.state, messages, event = step(self.state, inputs)
        except Exception as err:  # noqa: BLE001 -- a bug in one frame's estimate must not ground the vehicle:
            self.record.frame_errors += 1  # reported; the estimate starts afresh (its state may be what raised)
            self.emit({"event": "frame-error", "vehicle": self.config.vehicle, "frame": n,
                       "error": f"{type(err).__name__}: {err}"[:500]})
            self.state = replace(self.state, estimator=EstimatorState(), published=None, follow=None)
            return
        for message in messages:
            self.send(message)
        event = event.from_source(frame.scene_frame, frame.skipped)
        self.record.add_frame(event, self._image_ready)
        t_end = time.perf_counter()
        self.record.frame_total_s.append(t_end - t_acquire)
        self.record.extract_s.append(frame.extract_s)
        self.record.halved_frames += bool(frame.halved)
        self.emit({**event.to_json(), "timing_s": {
            "late": late_s, "image": frame.render_s, "extract": frame.extract_s,
            "share": t_pair - t_acquire - frame.render_s - frame.extract_s, "pair": t_step - t_pair,
            "step": t_end - t_step, "total": t_end - t_acquire, "cpu": time.thread_time() - cpu0},
            **({"front_end": "halved"} if frame.halved else {})})

    def send(self, message: Message | Hint) -> None:
        """Publish a message of :func:`step` or :func:`idle`; hints no faster than ``hint_rate_hz``."""
        if message.TOPIC is Topic.HINT:
            if not self._hint_schedule.due(time.monotonic()):
                return
            self.record.hints_published += 1
        self.bus.send(message)

    # -- between frames ---------------------------------------------------------------------------

    def next_frame(self, n: int | None, stop: threading.Event) -> int | None:
        """Until the next tick, when the policy says so: generations on the latest views with the hints that
        arrived (:func:`agents.vehicle.step.idle`), one per slot of ``hint_rate_hz``; the slots that fell during
        a frame are made up after it. The frame has priority: no generation starts once the tick is due."""
        if self.policy.idle_generations and n is not None:
            due_ns = self.clock.stamp_ns(n + 1)
            schedule, budget = self._generation_schedule, 1.0 / self.config.hint_rate_hz
            while not stop.is_set() and time.time_ns() < due_ns:
                now = time.monotonic()
                if not schedule.due(now):
                    stop.wait(min(schedule.wait_s(now), max(due_ns - time.time_ns(), 0) / NS))
                    continue
                self.state, messages, estimate = idle(self.state, self.take_hints() if self.policy.takes_hints
                                                      else None, budget)
                for message in messages:
                    self.send(message)
                if estimate is None:  # nothing to improve before the first estimate
                    stop.wait(min(0.01, max(due_ns - time.time_ns(), 0) / NS))
        return super().next_frame(n, stop)


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
