"""What one frame of a camera vehicle did, typed: the :class:`FrameEvent` that :func:`agents.vehicle.step.step`
returns, the run record counts (:meth:`agents.vehicle.records.RunRecord.add_frame`) and the agent prints as a JSON
line (``{"event": "frame", ...}`` or ``{"event": "no-estimate", ...}``)."""

from __future__ import annotations

from dataclasses import dataclass, replace

from evopose.cooperative import Estimate
from evopose.trust import Trust

from agents.vehicle.records import pose_dict


@dataclass(frozen=True)
class FrameEvent:
    """One frame's outcome. ``estimate`` is None when the frame had too few image points (``reason`` says so).

    Attributes
    ----------
    pose : tuple of 6 floats
        The published pose (canonical roll-pitch-yaw), ``world_from_target``.
    trust : Trust
        Whether to trust the estimate and why (:func:`evopose.trust.judge`, docs/design.md §2): its ``level``
        (searching, unsure, good), ``reason`` and the conditions it rests on.
    error : dict or None
        Against the simulator's truth (:func:`geometry.pose_error`), when there is one.
    scene_frame, skipped : set by the runtime: the source's frame shown; why the own view was not taken.
    """

    vehicle: str
    frame: int
    points: int
    reason: str | None = None
    stamp_ns: int = 0
    views: tuple[str, ...] = ()
    views_of_this_instant: bool = True
    #: the views whose point labels did not go into eq. (1) (their source's labels disagreed with the team's good
    #: poses, or none came while the search stalled: evopose/label_trust.py)
    unlabelled: tuple[str, ...] = ()
    knowledge: tuple[str, ...] = ()
    pose: tuple[float, ...] | None = None
    fitness: float = float("nan")
    mismatch: float = 1.0
    trust: Trust = Trust(False, False)
    solved: bool = False
    from_hint: bool = False
    seconds: float = 0.0
    #: generations of the search this estimate came from, so far (a search from scratch runs in slices, one a frame)
    generations: int = 0
    error: dict | None = None
    estimate: Estimate | None = None
    scene_frame: int | None = None
    skipped: str | None = None

    @classmethod
    def none(cls, vehicle: str, frame: int, points: int, reason: str) -> "FrameEvent":
        """A frame without an estimate."""
        return cls(vehicle, frame, points, reason=reason)

    @property
    def good(self) -> bool:
        return self.trust.good

    def from_source(self, scene_frame: int | None, skipped: str | None) -> "FrameEvent":
        """The event with the source's frame and, when the own view was not taken, why (not "too few")."""
        reason = self.reason
        if skipped is not None and self.estimate is None:
            reason = f"no usable frame: {skipped}"
        return replace(self, scene_frame=scene_frame, skipped=skipped, reason=reason)

    def to_json(self) -> dict:
        """The agent's JSON line."""
        if self.estimate is None:
            out = {"event": "no-estimate", "vehicle": self.vehicle, "frame": self.frame, "points": self.points,
                   "reason": self.reason}
        else:
            out = {"event": "frame", "vehicle": self.vehicle, "frame": self.frame, "stamp_ns": self.stamp_ns,
                   "points": self.points, "views": list(self.views),
                   "views_of_this_instant": self.views_of_this_instant, "unlabelled": list(self.unlabelled),
                   "knowledge": list(self.knowledge),
                   "pose": pose_dict(self.pose), "fitness": self.fitness, "mismatch": self.mismatch,
                   "trust": self.trust.level, "good": self.trust.good, "converged": self.trust.converged,
                   "confident": self.trust.confident, "precise": self.trust.precise,
                   "standing": self.trust.standing, "solved": self.solved,
                   "from_hint": self.from_hint, "seconds": self.seconds, "generations": self.generations}
            if not self.trust.good:  # why the estimate is not good (evopose.trust.Trust.reason)
                out["reason"] = self.trust.reason
            if self.error is not None:
                out["error"] = self.error
        out["scene_frame"] = self.scene_frame
        if self.skipped is not None:
            out["skipped"] = self.skipped
        return out


__all__ = ["FrameEvent"]
