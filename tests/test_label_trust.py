"""Labels trusted by their agreement with the team's good poses (:mod:`evopose.label_trust`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from benchmarks.problems import make_paper_scale_problem
from evopose.label_trust import MIN_AGREEMENT, SEARCH_FRAMES, LabelTrust, label_agreement


def _labelled_view():
    sp = make_paper_scale_problem(np.random.default_rng(5), cameras=("H1",), noise=0.3, clutter=0.0, missing=0.0,
                                  labelled=True)
    return sp.problem.model, sp.problem.views[0], sp.true_pose


def test_at_the_true_pose_right_labels_agree_and_shuffled_ones_do_not():
    model, view, pose = _labelled_view()
    right, matched = label_agreement(model, view, pose)
    assert matched >= 0.8 * len(view.points) and right == matched
    classes = np.unique(model.labels)
    wrong = replace(view, labels=(np.searchsorted(classes, view.labels) + 1) % len(classes))   # every label moved on
    assert label_agreement(model, wrong, pose) == (0, matched)
    assert label_agreement(model, replace(view, labels=None), pose) == (0, 0)


def test_unmeasured_labels_are_used_until_the_search_stalls_then_measured_ones_by_their_agreement():
    model, view, pose = _labelled_view()
    classes = np.unique(model.labels)
    wrong = replace(view, labels=(np.searchsorted(classes, view.labels) + 1) % len(classes))
    trust = LabelTrust()
    for _ in range(SEARCH_FRAMES):
        assert trust.labelled("H1")
        trust = trust.after(model, [view], ["H1"], pose, good=False)
    assert not trust.labelled("H1")                       # no good pose with them: eq. (1) without labels
    measured = trust.after(model, [view, wrong], ["H1", "H2"], pose, good=True)
    assert measured.frames_without_good == 0
    assert measured.agreement("H1") == 1.0 and measured.labelled("H1")
    assert measured.agreement("H2") == 0.0 and not measured.labelled("H2")
    assert measured.agreement("H3") is None and measured.labelled("H3")   # unmeasured, and the search is not stalled
    # agreement pools the good frames: one right frame does not outweigh three wrong ones
    pooled = LabelTrust()
    for _ in range(3):
        pooled = pooled.after(model, [wrong], ["H1"], pose, good=True)
    pooled = pooled.after(model, [view], ["H1"], pose, good=True)
    assert pooled.agreement("H1") == 0.25 < MIN_AGREEMENT and not pooled.labelled("H1")
