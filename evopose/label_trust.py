"""Whether a team-mate's point labels are worth their constraint: their agreement with the team's good poses.

Labels are our extension of eq. (1) (:func:`evopose.problem.label_coordinates`): a labelled point matches only marks
of its own class. That is worth much when labels are right and costs much when they are not: a point with a wrong
label cannot reach its mark and counts as a false point. A camera's labels come from colour, which some cameras keep
and others lose (a flat, desaturated JPEG-50 stream at the paper's scale: 44 % of 2-4 px marks labelled right,
docs/cameras.md), and nothing in one frame tells which (the front-end's own confidence does not). The team's pose
does: at a good pose each labelled point's nearest projected mark says which class it is, so the share of points
whose label is their mark's measures the labels (docs/design.md, "Labels trusted per track").

A source's labels are used while unmeasured, unless the team has had no good pose for :data:`SEARCH_FRAMES` frames
(then the points go without labels: eq. (1) as the paper has it); once measured, while their agreement over the good
frames so far is at least :data:`MIN_AGREEMENT`. State: one frozen :class:`LabelTrust`, one writer (the vehicle's
frame step); it depends only on the views and the published poses, so vehicles that share their views keep the same.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from .fitness import project_into_view
from .problem import Model, View

#: Least share of a source's matched points whose label is their mark's for its labels to be used. Reasoned, not
#: fitted: a wrong label makes a false point, and the search holds its verdict with ~20 % false points (the
#: confidence benchmark's clutter). A one-off fleet run with every label dropped (a switch not kept in the code;
#: benchmarks/bench_photoreal_fleet.py on the nine paper-scale worlds, CHANGELOG.md) agrees: 82 % right labels
#: helped (62 vs 58 % of frames good in the reference look), 44 % hurt (0 vs 18 % through flat-cool).
MIN_AGREEMENT = 0.7
#: Frames without a good pose after which unmeasured labels are dropped (a sequence's first good pose takes one or
#: two frames when the labels are right).
SEARCH_FRAMES = 2
#: An image point is its nearest projected mark's when within this many pixels (the marks of a 25 px target lie
#: 3-5 px apart; a found mark is placed to 0.3-0.5 px).
MATCH_PX = 1.5


@dataclass(frozen=True)
class LabelTrust:
    """Per source vehicle: ``right`` and ``matched`` counts of its labelled points over the good frames so far;
    ``frames_without_good`` since the last good pose (or the start)."""

    right: Mapping[str, int] = field(default_factory=dict)
    matched: Mapping[str, int] = field(default_factory=dict)
    frames_without_good: int = 0

    def agreement(self, vehicle: str) -> float | None:
        """The share of ``vehicle``'s matched points whose label was their mark's (None: none matched yet)."""
        n = self.matched.get(vehicle, 0)
        return self.right.get(vehicle, 0) / n if n else None

    def labelled(self, vehicle: str) -> bool:
        """Whether ``vehicle``'s labels go into eq. (1) this frame."""
        a = self.agreement(vehicle)
        return self.frames_without_good < SEARCH_FRAMES if a is None else a >= MIN_AGREEMENT

    def after(self, model: Model, views: Sequence[View], vehicles: Sequence[str], pose: np.ndarray,
              good: bool) -> LabelTrust:
        """The trust after a frame: ``views`` (the sources' views with the labels they sent, in the order of
        ``vehicles``) measured at ``pose`` (6,) when it is ``good``."""
        if not good:
            return LabelTrust(self.right, self.matched, self.frames_without_good + 1)
        right, matched = dict(self.right), dict(self.matched)
        for vehicle, view in zip(vehicles, views):
            r, m = label_agreement(model, view, pose)
            right[vehicle], matched[vehicle] = right.get(vehicle, 0) + r, matched.get(vehicle, 0) + m
        return LabelTrust(right, matched, 0)


def label_agreement(model: Model, view: View, pose: np.ndarray, match_px: float = MATCH_PX) -> tuple[int, int]:
    """At ``pose`` (6,): how many of the ``view``'s labelled points lie within ``match_px`` of a visible projected
    mark (their nearest), and how many of those carry that mark's label; (0, 0) for an unlabelled view or model."""
    if view.labels is None or model.labels is None or not len(view.points):
        return 0, 0
    proj = project_into_view(model, view, np.asarray(pose, float)[None, :])
    usable = proj.usable[0]
    if not usable.any():
        return 0, 0
    marks = np.stack([proj.u[0][usable], proj.v[0][usable]], axis=1)                  # (M', 2)
    d = np.linalg.norm(view.points[:, None, :] - marks[None, :, :], axis=2)           # (P, M')
    nearest = np.argmin(d, axis=1)
    near = d[np.arange(len(d)), nearest] <= match_px
    same = np.asarray(view.labels)[near] == np.asarray(model.labels)[usable][nearest[near]]
    return int(same.sum()), int(near.sum())


__all__ = ["MATCH_PX", "MIN_AGREEMENT", "SEARCH_FRAMES", "LabelTrust", "label_agreement"]
