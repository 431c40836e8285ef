"""A camera vehicle's frame as one transition, pure: ``step(state, inputs) -> (state', messages, FrameEvent)``.

No Zenoh, no threads, and no clock of its own: the time is an input (:attr:`FrameInputs.clock`), and so is every
random stream (the estimator state's), so the same state and inputs give the same result, as the search is ask/tell
(docs/architecture.md, "A frame's path"). The state is
frozen (:class:`VehicleState`: the vehicle's constant rules and its :class:`evopose.cooperative.EstimatorState`);
every rule that depends on ``--share`` is one :class:`SharePolicy` value; whether to trust the estimate is
:func:`evopose.trust.judge`'s (one :class:`evopose.trust.Trust`). The runtime (:mod:`agents.vehicle.roles`) acquires the
frame, publishes :func:`share`'s message, pairs team-mates' views, calls :func:`step` and publishes what it returns;
between frames it calls :func:`idle`. Tests call all three directly.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from evopose.cooperative import Cooperation, Estimate, EstimatorState, Knowledge
from evopose.label_trust import LabelTrust
from evopose.pose_filter import PoseFilter
from evopose.trust import judge
from geometry import canonical_pose, pose_error
from protocol import FeatureSet, ImageFrame, Message, PoseEstimate, Topic
from protocol.hint import Hint

from agents.vehicle.events import FrameEvent
from agents.vehicle.frames import Frame
from agents.vehicle.team_views import MateView, build_views, encode_image

#: When team-mates share the same views, a search from scratch runs a fixed number of generations per frame (so
#: their bests agree): as many as POINTS_PER_FRAME image points in all allow, 1 to MAX_GENERATIONS_PER_FRAME. A
#: search from scratch makes 256-1024 fresh starts (SearchOptions.min_starts, _loose; up to 4x on a small problem;
#: in these slices never fewer, evopose/cooperative.py's Cooperation._optimiser), ~51 a generation: 20-80
#: generations, which at one a frame outlast a 2 s sequence. Four on two paper-scale views
#: take 24-36 ms of a 100 ms frame (benchmarks/bench_photoreal_fleet.py, "frame ms"). POINTS_PER_FRAME is a
#: frame of REFERENCE_FRAME_PERIOD_S (the paper's ~10 fps); a faster clock allows proportionally fewer points a
#: frame, so a slice keeps its share of the tick (at 30 fps a third: 1-2 generations).
POINTS_PER_FRAME, MAX_GENERATIONS_PER_FRAME, REFERENCE_FRAME_PERIOD_S = 160, 4, 0.1
#: Hint mode: a team-mate's pose whose mismatch on the own views is at most this much higher than the own
#: best's is taken (the own views cannot tell the two apart; the team-mate sees from elsewhere).
HINT_MARGIN = 0.1
#: Share of a frame's period a search from scratch may take in the frame loop (the rest: render, extract, share).
SEARCH_SHARE_OF_FRAME = 0.5
#: The front-end looks for the target around the vehicle's last good pose (vision.window) for at most this many
#: frames after it (the target may have left the window since; a window without the target falls back to the whole
#: image, vision.extract). Also while a search from scratch runs, the track lost: the target is rarely lost from
#: the image then, and the frames of a search are the ones with the least time to spare. Two agents in one process
#: (no time budget) on the 63 rendered datasets of datasets/photoreal, looks, looks-long and photoreal-long: 438 good
#: frames of 728 with the window as on the whole image (+2 on one look, -2 on another), 586 right, none confidently
#: wrong. On 57 of them, with an earlier scorer: the same with or without the window kept through a search; looking
#: near the last published pose when none was good lost 4 right frames, near a closely matching one 4 good frames.
FOLLOW_FRAMES = 5


@dataclass(frozen=True)
class SharePolicy:
    """Every rule that depends on the share mode (``--share``), decided once (:func:`share_policy`).

    Attributes
    ----------
    mode : str
        ``none``, ``raw``, ``features`` or ``hint``.
    shares : Topic or None
        What the own frame becomes for team-mates (``image``, ``features``), and what theirs are paired with it.
    takes_hints, sends_hints : bool
        Team-mates' hints join the search; a good estimate goes out as a hint (the paper's Experiment 2(b)).
    idle_generations : bool
        Generations run between frames on the last views (not when team-mates must compute the same pose).
    same_views : bool
        Every vehicle has the same views (raw images, feature sets): a search from scratch runs a fixed number
        of generations per frame (so team-mates' bests agree) within the whole frame, not half of it.
    """

    mode: str
    shares: Topic | None
    takes_hints: bool
    sends_hints: bool
    idle_generations: bool
    same_views: bool

    def generations_per_frame(self, points: int, period_s: float | None = None) -> int | None:
        """Generations of a search per frame on views of ``points`` image points in all, at a frame period of
        ``period_s`` seconds (None: :data:`REFERENCE_FRAME_PERIOD_S`); None: by time."""
        if not self.same_views:
            return None
        allowed = POINTS_PER_FRAME * (1.0 if period_s is None else period_s / REFERENCE_FRAME_PERIOD_S)
        return int(np.clip(allowed // max(points, 1), 1, MAX_GENERATIONS_PER_FRAME))

    @property
    def search_share_of_frame(self) -> float:
        return 1.0 if self.same_views else SEARCH_SHARE_OF_FRAME

    @property
    def candidate_margin(self) -> float:
        """Weighing a team-mate's pose against the own best: the fittest wins (0), or the hint margin."""
        return HINT_MARGIN if self.takes_hints else 0.0


POLICIES = {
    "none": SharePolicy("none", None, False, False, True, False),
    "raw": SharePolicy("raw", Topic.IMAGE, False, False, False, True),
    "features": SharePolicy("features", Topic.FEATURES, False, False, False, True),
    "hint": SharePolicy("hint", None, True, True, True, False),
}


def share_policy(mode: str) -> SharePolicy:
    """The policy of a share mode; ValueError naming the modes otherwise."""
    if mode not in POLICIES:
        raise ValueError(f"share mode must be one of {', '.join(POLICIES)}, got {mode!r}")
    return POLICIES[mode]


@dataclass(frozen=True)
class VehicleState:
    """What a camera vehicle carries from frame to frame: its constant rules and its estimator's state."""

    cooperation: Cooperation
    policy: SharePolicy
    vehicle: str
    target: str
    image_encoding: str = "raw"
    estimator: EstimatorState = field(default_factory=EstimatorState)
    #: the published track (None until the first frame: made from the cooperation's tracking rules)
    published: PoseFilter | None = None
    #: the fleet clock's period: the track ages by the frames between the instants its images were taken (None: by
    #: the frame numbers, for a state without a clock)
    frame_period_s: float | None = None
    #: whose point labels go into eq. (1): their agreement with the good poses so far (evopose/label_trust.py)
    labels: LabelTrust = field(default_factory=LabelTrust)
    #: the last good published pose (6,) and its frame number: where the front-end looks for the target (:meth:`near`)
    follow: tuple[np.ndarray, int] | None = None

    @property
    def best(self) -> np.ndarray | None:
        """The own best pose now (6,), or None."""
        return self.estimator.current_best

    def near(self, index: int) -> np.ndarray | None:
        """The pose the front-end looks for the target near in frame ``index`` (:mod:`vision.window`): the last good
        published one, at most :data:`FOLLOW_FRAMES` frames before; None (the whole image) before any and after
        that."""
        if self.follow is None:
            return None
        pose, frame = self.follow
        return pose if 0 < index - frame <= FOLLOW_FRAMES else None


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
    budget_s : float or None
        Seconds a search from scratch may take in this frame (None: until it stops).
    clock : callable () -> float
        The time, seconds (``time.perf_counter`` at run time): the frame's seconds, the search's deadline and the
        instants it records are read on it, never on a clock of the step's own.
    """

    index: int
    own: MateView
    mates: Sequence[MateView] = ()
    knowledge: Sequence[Knowledge] = ()
    hints: np.ndarray | None = None
    truth: np.ndarray | None = None
    latest_hint: np.ndarray | None = None
    budget_s: float | None = None
    clock: Callable[[], float] = time.perf_counter


def _header(state: VehicleState, stamp_ns: int) -> dict:
    """A message's header before the bus numbers it (``seq`` 0; :meth:`FleetBus.send` sets the sender's next)."""
    return {"sender": state.vehicle, "seq": 0, "stamp_ns": stamp_ns}


def share(state: VehicleState, frame: Frame, own: MateView) -> Message | None:
    """What the own frame gives team-mates: its points with the camera and the own best pose so far
    (``features``), or the image (``raw``); None in the other modes."""
    if state.policy.shares is Topic.FEATURES:
        best = state.best
        return FeatureSet(**_header(state, own.stamp_ns), camera=own.camera,
                          points=own.points.astype("<f4").tobytes(),
                          labels=None if own.labels is None else own.labels.astype(np.uint8).tobytes(),
                          best=None if best is None else tuple(float(v) for v in best))
    if state.policy.shares is Topic.IMAGE:
        h, w = frame.image.shape[:2]
        data = (np.ascontiguousarray(frame.image).tobytes() if state.image_encoding == "raw"
                else encode_image(frame.image, state.image_encoding))
        return ImageFrame(**_header(state, own.stamp_ns), camera=own.camera, encoding=state.image_encoding,
                          width=w, height=h, channels=1 if frame.image.ndim == 2 else 3, data=data)
    return None


def _covariance(cov: np.ndarray) -> tuple[float, ...] | None:
    """A 6x6 covariance as 36 floats (row-major, ROS order), or None when it is not finite."""
    cov = np.asarray(cov, float)
    return tuple(float(v) for v in cov.ravel()) if cov.shape == (6, 6) and np.all(np.isfinite(cov)) else None


def step(state: VehicleState, inputs: FrameInputs) -> tuple[VehicleState, list[Message | Hint], FrameEvent]:
    """One frame of a camera vehicle: eq. (1)-(4) on the own and team-mates' views, with knowledge and hints.

    The estimate is published as a ``pose`` (``good``: the :class:`evopose.trust.Trust` is good); with
    ``sends_hints`` an estimate in the right basin also goes out as a hint. Team-mates' ``best`` poses (sent with
    their feature sets) are weighed against the own best on this frame's eq. (4): the fitter one is tracked, so that
    vehicles with the same views publish the same pose. ``inputs.budget_s`` bounds a search from scratch in this frame: an unfinished search is
    resumed later and its best so far is published, not good.
    """
    own, policy = inputs.own, state.policy
    labelled, used = build_views([own, *inputs.mates])   # the labels as sent: measured against a good pose
    dropped = {v for v, view in zip(used, labelled) if view.labels is not None and not state.labels.labelled(v)}
    views = [replace(view, labels=None) if v in dropped else view for v, view in zip(used, labelled)]
    if not views:
        return state, [], FrameEvent.none(state.vehicle, inputs.index, len(own.points), "too few image points")
    t0 = inputs.clock()
    candidates = [m.best for m in inputs.mates if m.best is not None]
    margin = 0.0
    if inputs.latest_hint is not None:  # hints: a team-mate's pose that fits the own views about as well wins
        candidates, margin = [*candidates, inputs.latest_hint], policy.candidate_margin
    # the instant the own images were taken, in frame periods: the track ages by it (evopose/pose_filter.py) and
    # eq. (2)'s prediction moves by it, so a vehicle that processed an instant a tick late publishes what its
    # team-mates do
    taken = inputs.index if state.frame_period_s is None else own.stamp_ns / (state.frame_period_s * 1e9)
    estimator, estimate = state.cooperation.estimate(
        state.estimator, views, knowledge=inputs.knowledge, hints=inputs.hints, frame=inputs.index, instant=taken,
        budget_s=inputs.budget_s, candidates=np.array(candidates) if candidates else None, candidate_margin=margin,
        generations=policy.generations_per_frame(sum(len(view.points) for view in views), state.frame_period_s),
        clock=inputs.clock)
    seconds = inputs.clock() - t0
    sol = estimate.solution
    # what goes out is the track's fused pose (evopose/pose_filter.py): a good frame that jumped off it is set aside
    published = state.published or PoseFilter.of_rules(state.cooperation.options.confidence)
    published, out = published.step(taken, sol.pose, sol.covariance, judge(sol).good)
    trust = judge(sol, searching=estimator.searching, published=out)
    pose = canonical_pose(out.pose)  # pitch within +-90 deg
    state = replace(state, estimator=estimator, published=published,
                    labels=state.labels.after(state.cooperation.model, labelled, used, out.pose, trust.good),
                    follow=(pose, inputs.index) if trust.good else state.follow)
    mates = tuple(v for v in used if v != state.vehicle)
    messages: list[Message | Hint] = [PoseEstimate(
        **_header(state, own.stamp_ns), target=state.target, pose=tuple(float(v) for v in pose),
        fitness=float(sol.fitness), mismatch=estimate.mismatch, converged=trust.converged,
        generations=int(sol.generations), seconds=seconds, from_hint=bool(sol.from_hint), inputs=mates,
        good=trust.good, covariance=_covariance(out.covariance))]
    if policy.sends_hints and trust.in_right_basin:  # a hint need not be precise: the mate's selection judges it
        messages.append(Hint(tuple(float(v) for v in pose)))
    event = FrameEvent(
        vehicle=state.vehicle, frame=inputs.index, points=len(own.points), stamp_ns=own.stamp_ns, views=tuple(used),
        # a team-mate's view of an earlier instant (it was late) differs from the one its owner used
        views_of_this_instant=all(m.stamp_ns == own.stamp_ns for m in inputs.mates if m.vehicle in used),
        unlabelled=tuple(v for v in used if v in dropped),
        knowledge=tuple(k.name for k in inputs.knowledge), pose=tuple(float(v) for v in pose),
        fitness=float(sol.fitness), mismatch=estimate.mismatch, trust=trust, solved=estimate.solved,
        from_hint=bool(sol.from_hint), seconds=seconds, generations=int(sol.generations),
        error=None if inputs.truth is None else pose_error(pose, inputs.truth), estimate=estimate)
    return state, messages, event


def idle(state: VehicleState, hints: np.ndarray | None, budget_s: float | None,
         clock: Callable[[], float] = time.perf_counter) -> tuple[VehicleState, list[Hint], Estimate | None]:
    """One generation between frames (:meth:`Cooperation.generation`) with the hints that arrived; a best in the
    right basin (converged and confident, precise or not) goes out as a hint when the policy sends hints (a
    search's best so far, or an unsure pose, is no hint)."""
    estimator, estimate = state.cooperation.generation(state.estimator, hints, budget_s, clock)
    state = replace(state, estimator=estimator)
    if estimate is not None and state.policy.sends_hints and judge(estimate.solution).in_right_basin:
        return state, [Hint(tuple(float(v) for v in estimate.pose))], estimate
    return state, [], estimate


__all__ = ["FOLLOW_FRAMES", "FrameInputs", "POLICIES", "SharePolicy", "VehicleState", "idle", "share", "share_policy",
           "step"]
