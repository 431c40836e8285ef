"""The published pose of a track: eq. (2)'s good frames fused by their covariances (docs/design.md §2, "Published
pose").

Eq. (2) warm-starts each frame from the last, and each frame's pose is judged on its own views. At the paper's
scale (the Pioneer ~25 px, its marks 3-5 px apart) one frame knows its rotation to 2.5-4.6 deg (1 sigma), and on
the hardest lighting a few frames land 7-10 deg off *within their own basin*: the truth lies ~4 sigma away under
the frame's covariance, no rival pose fits distinctly better, and the per-frame tracking gate
(:func:`evopose.trust.track_confidence`) lets the jump through at 2-3 sigma. The target cannot tilt that
fast (its model file's ``motion``), and the frames before knew its tilt to ~1 deg together.

So what a vehicle publishes is the track's estimate: every good frame is fused into a
:class:`evopose.uncertainty.TrackReference` (a Kalman update of a random walk whose steps are the target's motion
per frame, ``ConfidenceRules.track_motion``), and the fused pose and covariance go out. A good frame that lies more
than ``sigmas`` from the track (under the sum of both covariances) is set aside: published as it is, not good, and
the track stands; after ``most_set_aside`` such frames in a row the track restarts from the frame (the target is
not where the track said). The track is *settled*, and what it publishes good, once its fused rotation sigma is
within ``ConfidenceRules.max_published_rotation_sigma`` (from the target model file's ``good_within``: 2.5 deg for
the Pioneer, within 5 deg at two sigmas); a single frame at the paper's scale knows it to 3-4 deg, enough to be
fused, not to be published alone. Frames that are not good
only age the track: its covariance grows by the motion per
elapsed frame, so after a loss the track constrains what the target cannot have changed (a ground robot's tilt)
and leaves the rest to the new frames. Pure numpy: the state is a frozen value, replaced by :meth:`PoseFilter.step`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .covariance import deviation
from .trust import settled
from .uncertainty import TrackReference, mahalanobis

__all__ = ["FilteredPose", "PoseFilter"]


@dataclass(frozen=True, eq=False)
class FilteredPose:
    """What :meth:`PoseFilter.step` publishes for one frame.

    Attributes
    ----------
    pose : array (6,)
        ``world_from_target`` ``(x, y, z, roll, pitch, yaw)``: the track's fused pose on a fused frame, else the
        frame's own.
    covariance : array (6, 6)
        Of ``pose``, in the ROS convention (:func:`evopose.covariance.deviation`'s coordinates).
    on_track : bool
        The frame was fused into the track (or began it): a good frame stays good. False for a good frame set
        aside (it jumped away from the track) and for a frame that was not good.
    track_frames : int
        Frames fused into the track so far (0 without a track).
    jump_sigmas : float
        The frame's Mahalanobis distance from the track (nan when there was no track or the frame was not good).
    settled : bool
        On the track, and the track knows its rotation to ``PoseFilter.most_rotation_sigma``
        (:func:`evopose.trust.settled`). False whenever ``on_track`` is False. Whether what is published is good
        is :func:`evopose.trust.judge`'s (its ``standing``).
    """

    pose: np.ndarray
    covariance: np.ndarray
    on_track: bool
    track_frames: int = 0
    jump_sigmas: float = float("nan")
    settled: bool = False


@dataclass(frozen=True, eq=False)
class PoseFilter:
    """One vehicle's published track (see the module): constant rules and the track so far.

    Attributes
    ----------
    motion : array (6,)
        1-sigma change of each coordinate per frame (metres, then radians about the fixed X, Y, Z axes):
        ``ConfidenceRules.track_motion``, from the target model file's ``motion`` at the vehicle's frame rate.
    sigmas : float
        A good frame further than this Mahalanobis distance from the track is set aside
        (``ConfidenceRules.track_sigmas``).
    most_set_aside : int
        Frames set aside in a row before the track restarts from the next one (``ConfidenceRules.track_set_aside``).
    most_rotation_sigma : float
        The track is settled (its pose good) once its worst rotation 1-sigma is within this (radians,
        ``ConfidenceRules.max_published_rotation_sigma``).
    track : TrackReference or None
        The fused estimate, as of frame ``frame``.
    frame : float
        The instant the track was last predicted to, in frames (of the period ``motion`` is per): the instant an
        image was taken, so that team-mates who took their views of one instant at different ticks age their
        tracks alike.
    """

    motion: np.ndarray
    sigmas: float = 4.0
    most_set_aside: int = 3
    most_rotation_sigma: float = float("inf")
    track: TrackReference | None = None
    frame: float = 0.0

    @classmethod
    def of_rules(cls, rules) -> "PoseFilter":
        """A filter with the tracking gate's rules (:class:`evopose.trust.ConfidenceRules`)."""
        return cls(np.asarray(rules.track_motion, float), float(rules.track_sigmas), int(rules.track_set_aside),
                   float(rules.max_published_rotation_sigma))

    def _settled(self, covariance: np.ndarray) -> bool:
        """Whether a track of ``covariance`` (6, 6) knows its rotation well enough (:func:`evopose.trust.settled`)."""
        return settled(covariance, self.most_rotation_sigma)

    def _aged(self, frame: float) -> TrackReference | None:
        """The track predicted to ``frame``: its covariance grown by the motion of each elapsed frame."""
        if self.track is None:
            return None
        elapsed = max(float(frame) - self.frame, 0.0)
        return self.track.predicted(self.motion * np.sqrt(elapsed)) if elapsed > 0 else self.track

    def step(self, frame: float, pose: np.ndarray, covariance: np.ndarray, good: bool
             ) -> tuple["PoseFilter", FilteredPose]:
        """The next filter and what to publish for the estimate ``pose`` (6,) with ``covariance`` (6, 6) of the
        image taken at ``frame`` (in frames; need not be whole), judged ``good`` on its own (converged, confident
        and precise)."""
        pose = np.asarray(pose, float).reshape(6)
        covariance = np.asarray(covariance, float).reshape(6, 6)
        track = self._aged(frame)
        aged = replace(self, track=track, frame=max(float(frame), self.frame))
        own = FilteredPose(pose, covariance, False, 0 if track is None else track.frames)
        if not good or not np.all(np.isfinite(covariance)):
            return aged, own
        if track is None:
            started = TrackReference.of(pose, covariance)
            return replace(aged, track=started), FilteredPose(pose, covariance, True, 1,
                                                              settled=self._settled(covariance))
        jump = float(mahalanobis(deviation(pose, track.pose), track.covariance + covariance)[0])
        if jump <= self.sigmas:
            fused = track.fused(pose, covariance)
            return replace(aged, track=fused), FilteredPose(fused.pose, fused.covariance, True, fused.frames, jump,
                                                            self._settled(fused.covariance))
        kept = track.passed_over(self.most_set_aside)
        if kept is None:  # the track no longer stands for the target: it restarts here, this frame not yet good
            kept = TrackReference.of(pose, covariance)
        return replace(aged, track=kept), replace(own, jump_sigmas=jump, track_frames=kept.frames)
