"""The fleet's frame clock and a vehicle's simulated camera.

Every agent of a fleet acquires frame ``n`` at ``epoch_ns + n / fps`` (wall clock, ns since the Unix
epoch), so two vehicles' frames of the same instant carry the same ``stamp_ns`` and a receiver can pair
them (the feature sets of eq. 4 must describe the same instant for a moving target). The default
epoch is 0: any two agents with synchronised clocks agree on frame numbers without talking.
A scenario has a finite number of frames; frame ``n`` shows scenario frame ``n mod frames``.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import numpy as np

from evopose import Camera
from scenarios.render import render_frame

from vision.extract import FeatureExtractor, feature_extractor, resolve_features
from scenarios.world import Scenario

NS = 1_000_000_000


@dataclass(frozen=True)
class FrameClock:
    """Frame ``n`` is due at ``epoch_ns + round(n * 1e9 / fps)``."""

    fps: float
    epoch_ns: int = 0

    def __post_init__(self) -> None:
        if not self.fps > 0:
            raise ValueError(f"fps must be > 0, got {self.fps}")

    def stamp_ns(self, n: int) -> int:
        return self.epoch_ns + round(n * NS / self.fps)

    def index_at(self, t_ns: int) -> int:
        """The last frame due at or before ``t_ns``."""
        return int(np.floor((t_ns - self.epoch_ns) * self.fps / NS))

    def index_of(self, stamp_ns: int) -> int | None:
        """The frame whose stamp is ``stamp_ns`` (within 1 ms), or None if it is not a frame stamp."""
        n = round((stamp_ns - self.epoch_ns) * self.fps / NS)
        return n if abs(self.stamp_ns(n) - stamp_ns) <= 1_000_000 else None

    def wait_next(self, after: int | None, stop: threading.Event) -> int | None:
        """Sleep until the frame after ``after`` is due (the newest due frame if we are late); None if stopped.

        When ``after`` is None the next frame to come (frame 0 at the earliest) is waited for.
        """
        now = time.time_ns()
        due = self.index_at(now)
        n = max(due + 1, 0) if after is None else max(after + 1, due)
        delay = (self.stamp_ns(n) - now) / NS
        if delay > 0 and stop.wait(delay):
            return None
        return None if stop.is_set() else n


def fleet_clock(fps: float | None, scenario: Scenario, epoch_ns: int) -> FrameClock:
    """An agent's clock: ``--fps`` (default: the scenario's) from ``--epoch-ns`` (the vehicle's frame loop, and the
    ticks a dataset's frames were taken at)."""
    return FrameClock(fps or scenario.spec.fps, epoch_ns)


@dataclass(frozen=True)
class Frame:
    """One acquired frame.

    Attributes
    ----------
    index : int
        Fleet frame number (see :class:`FrameClock`).
    scene_frame : int
        The scenario frame shown.
    stamp_ns : int
        Acquisition time, ns since the Unix epoch.
    image : array (H, W, 3) uint8, BGR
    camera : Camera
        With its ``world_from_camera`` at acquisition.
    points : array (N, 2)
        Extracted feature points (mark centres), pixels.
    labels : int array (N,) or None
        Each point's colour class (its index in the model's palette: the label it is matched by, our extension
        of eq. 1); None for untyped points (corners).
    skipped : str or None
        Why a live source gave no usable image at this tick (e.g. its newest image is stale): no points then.
    truth : array (6,) or None
        ``world_from_target`` ground truth, for evaluation only; None from a real source (no ground truth).
    render_s : float
        Seconds the simulation took to render the image (what a real camera would not cost); for a real
        source the seconds its read took.
    render_cpu_s : float
        CPU seconds of the rendering thread for it (0 for a real source): what the simulator, not the vehicle,
        cost; unlike ``render_s`` it does not grow while the thread waits for a core.
    extract_s : float
        Seconds the front-end took to find the marks in it (the vehicle's own work, unlike ``render_s``).
    halved : bool
        Whether the front-end ran on the image halved to keep the camera's rate (:mod:`vision.front_end_pace`).
    """

    index: int
    scene_frame: int
    stamp_ns: int
    image: np.ndarray
    camera: Camera
    points: np.ndarray
    truth: np.ndarray | None
    render_s: float = 0.0
    labels: np.ndarray | None = None
    skipped: str | None = None
    render_cpu_s: float = 0.0
    extract_s: float = 0.0
    halved: bool = False


def default_extractor(scenario: Scenario) -> FeatureExtractor:
    """The agents' default front-end for ``scenario`` (``--features auto``): the marks by their contrast when the
    world has a camera model (its images are a camera's), else by the preset hue bands."""
    kind = resolve_features("auto", camera_images=scenario.render.camera_model is not None)
    return feature_extractor(kind, scenario.model, scenario.bounds() if scenario.spec.search else None)


class SimulatedCamera:
    """A vehicle's camera in a scenario: renders the frame, extracts the target's marks with their colours with
    ``extract`` (``image (H, W, 3), camera, near -> (points (N, 2), labels (N,) or None)``,
    :class:`vision.extract.FeatureExtractor`)."""

    def __init__(self, scenario: Scenario, vehicle: str,
                 extract: FeatureExtractor | None = None) -> None:
        self.scenario = scenario
        self.vehicle = scenario.vehicle(vehicle).name
        self.extract = extract if extract is not None else default_extractor(scenario)

    def scene_frame(self, index: int) -> int:
        return index % self.scenario.frames

    def acquire(self, index: int, stamp_ns: int, near: np.ndarray | None = None) -> Frame:
        """Frame ``index``; ``near``: the pose the target is expected near (the front-end looks around it first)."""
        scene = self.scene_frame(index)
        t0, cpu0 = time.perf_counter(), time.thread_time()
        rendered = render_frame(self.scenario, scene, self.vehicle)
        render_s, render_cpu_s = time.perf_counter() - t0, time.thread_time() - cpu0
        t1 = time.perf_counter()
        points, labels = self.extract(rendered.image, rendered.camera, near)
        return Frame(index, scene, stamp_ns, rendered.image, rendered.camera, points,
                     self.scenario.target_pose(scene), render_s, labels, render_cpu_s=render_cpu_s,
                     extract_s=time.perf_counter() - t1, halved=getattr(self.extract, "halved", False))

    def close(self) -> None:
        """Nothing to release (a real source closes its device or file)."""
