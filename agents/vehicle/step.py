"""A camera vehicle's per-frame decision, pure: what it shares, what it estimates, what it publishes.

No Zenoh, no clock, no threads: :func:`share` turns the own frame into the message team-mates get, and
:func:`step` turns one frame's inputs (own view, team-mates' paired views, eq. 3 knowledge, hints) into
an estimate and an *outbox* of messages to publish. The runtime (:mod:`agents.vehicle.roles`) gathers the
inputs from the bus and publishes the outbox; tests call :func:`step` directly.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from evopose.cooperative import CooperativeEstimator, Estimate, Knowledge
from geometry import matrix_from_pose, pose_from_matrix

from agents.vehicle.frames import Frame
from agents.vehicle.records import pose_dict
from geometry import pose_error
from agents.vehicle.team_views import MateView, build_views, encode_image


#: Generations a search from scratch runs per frame when team-mates share the same views (25-100 ms each).
GENERATIONS_PER_FRAME = 1
#: Hint mode: a team-mate's pose whose mismatch on the own views is at most this much higher than the own
#: best's is taken (the own views cannot tell the two apart; the team-mate sees from elsewhere).
HINT_MARGIN = 0.1


@dataclass(frozen=True)
class Outgoing:
    """A message to publish: its topic (a ``protocol.Topic`` value), its acquisition stamp and its fields.

    The transport adds the header (sender, sequence number); a ``hint`` carries ``{"pose": (6,)}``.
    """

    topic: str
    stamp_ns: int
    fields: Mapping = field(default_factory=dict)


def share(mode: str, encoding: str, frame: Frame, own: MateView, best: np.ndarray | None = None) -> Outgoing | None:
    """What the own frame gives team-mates: its points with the camera and the own ``best`` pose so far
    (``features``), or the image (``raw``)."""
    if mode == "features":
        fields = {"camera": own.camera, "points": own.points.astype("<f4").tobytes()}
        if own.labels is not None:
            fields["labels"] = own.labels.astype(np.uint8).tobytes()
        if best is not None:
            fields["best"] = tuple(float(v) for v in best)
        return Outgoing("features", own.stamp_ns, fields)
    if mode == "raw":
        h, w = frame.image.shape[:2]
        channels = 1 if frame.image.ndim == 2 else 3
        data = (np.ascontiguousarray(frame.image).tobytes() if encoding == "raw"
                else encode_image(frame.image, encoding))
        return Outgoing("image", own.stamp_ns, {"camera": own.camera, "encoding": encoding, "width": w, "height": h,
                                                "channels": channels, "data": data})
    return None


def _covariance(solution) -> tuple[float, ...] | None:
    """The solution's 6x6 covariance as 36 floats (row-major, ROS order), or None when it is not finite."""
    cov = np.asarray(getattr(solution, "covariance", np.full((6, 6), np.inf)), float)
    return tuple(float(v) for v in cov.ravel()) if cov.shape == (6, 6) and np.all(np.isfinite(cov)) else None


@dataclass(frozen=True)
class FrameInputs:
    """Everything one frame's estimate depends on.

    Attributes
    ----------
    index : int
        Frame number on the fleet's clock.
    own : MateView
        The own image points (N, 2) with the own camera.
    mates : sequence of MateView
        Team-mates' views paired with this frame (eq. 4).
    knowledge : sequence of Knowledge
        Eq. (3) constraints (an IMU attitude).
    hints : array (H, 6) or None
        Team-mates' poses received since the last frame.
    truth : array (6,)
        The simulator's true target pose: for the frame event's error only, never for the estimate.
    latest_hint : array (6,) or None
        The newest hint of a team-mate (hint mode), weighed against the own best with :data:`HINT_MARGIN`.
    """

    index: int
    own: MateView
    mates: Sequence[MateView] = ()
    knowledge: Sequence[Knowledge] = ()
    hints: np.ndarray | None = None
    truth: np.ndarray | None = None
    latest_hint: np.ndarray | None = None


@dataclass(frozen=True)
class StepResult:
    """What :func:`step` decided: the estimate (None without enough points), the outbox, the frame event."""

    estimate: Estimate | None
    inputs: tuple[str, ...]
    seconds: float
    outbox: tuple[Outgoing, ...]
    event: dict


def step(estimator: CooperativeEstimator, inputs: FrameInputs, *, vehicle: str, target: str, share_mode: str,
         budget_s: float | None = None) -> StepResult:
    """One frame of a camera vehicle: eq. (1)-(4) on the own and team-mates' views, with knowledge and hints.

    The estimate is published as a ``pose`` (``converged`` only when the estimator judges it good); in hint
    mode a good estimate also goes out as a ``hint``. Team-mates' ``best`` poses (sent with their feature sets)
    are weighed against the own best on this frame's eq. (4): the fitter one is tracked, so that vehicles with
    the same views publish the same pose. ``budget_s`` bounds the time a search from scratch may
    take in this frame: an unfinished search is resumed later and its best so far is published, not good.
    """
    own = inputs.own
    views, used = build_views([own, *inputs.mates])
    if not views:
        event = {"event": "no-estimate", "vehicle": vehicle, "frame": inputs.index, "points": len(own.points),
                 "reason": "too few image points"}
        return StepResult(None, (), 0.0, (), event)
    t0 = time.perf_counter()
    candidates = [m.best for m in inputs.mates if m.best is not None]
    margin = 0.0
    if inputs.latest_hint is not None:  # hints: a team-mate's pose that fits the own views about as well wins
        candidates, margin = [*candidates, inputs.latest_hint], HINT_MARGIN
    # the same views on every vehicle (raw images, feature sets): slices of a fixed number of generations, so that
    # team-mates' searches advance alike and their best so far agree; otherwise slices of time
    generations = GENERATIONS_PER_FRAME if share_mode in ("features", "raw") else None
    estimate = estimator.estimate(views, knowledge=inputs.knowledge, hints=inputs.hints, frame=inputs.index,
                                  budget_s=budget_s, candidates=np.array(candidates) if candidates else None,
                                  candidate_margin=margin, generations=generations)
    seconds = time.perf_counter() - t0
    sol = estimate.solution
    # good = the search judged it good and it is confident (no distinct pose fits nearly as well)
    good = bool(estimate.good and getattr(sol, "confident", False))
    pose = pose_from_matrix(matrix_from_pose(np.asarray(sol.pose, float)))  # canonical: pitch within +-90 deg
    mates = tuple(v for v in used if v != vehicle)
    outbox = [Outgoing("pose", own.stamp_ns, {
        "target": target, "pose": tuple(float(v) for v in pose), "fitness": float(sol.fitness),
        "mismatch": estimate.mismatch, "converged": estimate.good, "generations": int(sol.generations),
        "seconds": seconds, "from_hint": bool(sol.from_hint), "inputs": mates, "confident": good,
        "covariance": _covariance(sol)})]
    if share_mode == "hint" and good:
        outbox.append(Outgoing("hint", own.stamp_ns, {"pose": pose}))
    event = {"event": "frame", "vehicle": vehicle, "frame": inputs.index, "stamp_ns": own.stamp_ns,
             "points": len(own.points), "views": list(used),
             # a team-mate's view of an earlier instant (it was late) differs from the one its owner used
             "views_of_this_instant": all(m.stamp_ns == own.stamp_ns for m in inputs.mates if m.vehicle in used),
             "knowledge": [k.name for k in inputs.knowledge],
             "pose": pose_dict(pose), "fitness": float(sol.fitness), "mismatch": estimate.mismatch,
             "good": good, "converged": estimate.good, "solved": estimate.solved, "searching": estimator.searching,
             "from_hint": bool(sol.from_hint), "seconds": seconds}
    if inputs.truth is not None:
        event["error"] = pose_error(pose, inputs.truth)
    return StepResult(estimate, tuple(used), seconds, tuple(outbox), event)


__all__ = ["FrameInputs", "Outgoing", "StepResult", "share", "step"]
