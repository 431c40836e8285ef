"""What a vehicle measured over its run, in constant memory: errors against the truth, timings, counts."""

from __future__ import annotations

import statistics
import time
from collections import deque
from dataclasses import asdict, dataclass, field

import numpy as np

from agents.runs import POSE_COLUMNS, PoseRow
from geometry import PARAM_NAMES


def pose_dict(pose: np.ndarray) -> dict:
    """``{"x": .., ..., "yaw": ..}`` of a pose (6,)."""
    return {n: float(v) for n, v in zip(PARAM_NAMES, pose)}


#: Recent values kept for medians and percentiles (bounded: an agent's memory must not grow with its frames).
RECENT = 4096


class ErrorTotals:
    """Running mean and max of each error component over the frames in the right basin (converged and confident,
    precise or not: the paper's Table II averages such estimates, metres off for one helicopter alone), in
    constant memory. The run record counts those frames as ``in_right_basin`` beside the ``good`` ones (the
    whole verdict, precise too): docs/design.md, "Glossary"."""

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
    in_right_basin: int = 0  #: frames converged and confident, precise or not: the ones the errors average over
    converged: int = 0  #: (the target) estimates of its pose that converged; ``first_good_s``: the first of them
    set_aside: int = 0  #: frames good on their own that jumped off the published track (docs/design.md §2)
    solves: int = 0
    late_frames: int = 0
    halved_frames: int = 0  #: frames whose front-end ran on the image halved to keep the clock (vision.front_end_pace)
    stale_events: int = 0  #: times a live team-mate's data went stale (frozen or cut off)
    frame_errors: int = 0  #: frames whose estimate raised (a bug): the vehicle reset its estimator and went on
    multi_view_frames: int = 0
    first_good_s: float | None = None
    first_confirmed_s: float | None = None
    first_solve_s: float | None = None
    first_history: list = field(default_factory=list)
    render_cpu_s: float = 0.0  #: CPU seconds spent rendering simulated frames (0 with a real source)
    hints_published: int = 0
    hints_used: int = 0
    last_pose: list | None = None
    last_error: dict | None = None
    errors: ErrorTotals = field(default_factory=ErrorTotals)
    frame_seconds: deque = field(default_factory=lambda: deque(maxlen=RECENT))
    #: each frame's time from acquiring the image to publishing, and the front-end's share of it (the frame loop's
    #: ``timing_s``): what decides whether the clock's next tick is kept
    frame_total_s: deque = field(default_factory=lambda: deque(maxlen=RECENT))
    extract_s: deque = field(default_factory=lambda: deque(maxlen=RECENT))
    mate_latency_s: deque = field(default_factory=lambda: deque(maxlen=RECENT))  # team-mates' data: arrival - stamp
    #: the last :data:`RECENT` published poses (team agreement, errors over time)
    poses: deque[PoseRow] = field(default_factory=lambda: deque(maxlen=RECENT))

    def add_frame(self, event, image_ready_s: float) -> None:
        """Count one frame's :class:`agents.vehicle.events.FrameEvent`; ``image_ready_s`` is the
        ``perf_counter`` instant the run's first image existed (the paper's time to a good pose starts there)."""
        estimate = event.estimate
        if estimate is None:
            return
        self.frame_seconds.append(event.seconds)
        self.multi_view_frames += len(event.views) > 1
        self.estimates += 1
        self.solves += int(estimate.solved)
        if estimate.solved and self.first_solve_s is None:
            self.first_history = [float(f) for f in estimate.solution.history]
            self.first_solve_s = event.seconds
        good = event.trust.good
        if good and self.first_good_s is None:  # the paper's time to a good pose: when the best first matched closely
            self.first_good_s = (estimate.close_at or time.perf_counter()) - image_ready_s
        self.in_right_basin += int(event.trust.in_right_basin)
        if event.trust.in_right_basin and event.error is not None:
            self.errors.add(event.error)
        self.set_aside += int(event.trust.set_aside)
        if good:
            self.good += 1
            if self.first_confirmed_s is None:
                self.first_confirmed_s = time.perf_counter() - image_ready_s
        self.last_pose, self.last_error = list(event.pose), event.error
        self.poses.append(PoseRow(event.frame, tuple(event.pose), good, event.scene_frame))

    def summary(self) -> dict:
        out = {k: v for k, v in asdict(self).items()
               if k not in ("errors", "frame_seconds", "mate_latency_s", "poses", "frame_total_s", "extract_s")}
        out["pose_columns"] = list(POSE_COLUMNS)
        out["poses"] = [p.to_json() for p in self.poses]
        out.update(self.errors.summary())
        if self.frame_seconds:
            out["frame_seconds_median"] = statistics.median(self.frame_seconds)
        if self.frame_total_s:
            out["frame_total_s_median"] = statistics.median(self.frame_total_s)
            out["frame_total_s_max"] = max(self.frame_total_s)
            out["extract_s_median"] = statistics.median(self.extract_s)
        if self.mate_latency_s:
            latency = np.array(self.mate_latency_s)
            out["mate_latency_median_s"] = float(np.median(latency))
            out["mate_latency_p95_s"] = float(np.percentile(latency, 95))
        return out
