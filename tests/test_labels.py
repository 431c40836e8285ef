"""Colour-typed points (our extension of eq. 1): a point matches only marks of its own class, so at the paper's
image scale, where marks 3-5 px apart and 1-2 px of noise make untyped points ambiguous, the search finds the
right basin."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.problems import in_true_basin, make_paper_scale_problem
from evopose import Camera, Model, PoseObjective, PoseProblem, View, refine, solve
from evopose.fitness import matches
from evopose.problem import Bounds, label_coordinates


def _one_view(labels_model, labels_view):
    camera = Camera(fx=500, fy=500, cx=50, cy=50, width=100, height=100)
    model = Model(np.array([[-0.1, 0.0, 0.0], [0.1, 0.0, 0.0]]), labels=labels_model)
    # image points right where each mark projects at the pose below, in the opposite order of classes
    view = View(camera, np.array([[40.0, 50.0], [60.0, 50.0]]), labels=labels_view)
    bounds = Bounds(np.array([-1, -1, 4, -np.pi, -np.pi, -np.pi]), np.array([1, 1, 6, np.pi, np.pi, np.pi]))
    return PoseProblem(model, (view,), bounds)


def test_a_point_matches_only_marks_of_its_own_class():
    pose = np.array([0.0, 0.0, 5.0, 0.0, 0.0, 0.0])  # marks at u = 40 and 60
    same = PoseObjective(_one_view(np.array([0, 1]), np.array([0, 1])))
    swapped = PoseObjective(_one_view(np.array([0, 1]), np.array([1, 0])))
    untyped = PoseObjective(_one_view(np.array([0, 1]), None))
    assert same(pose[None])[0] == pytest.approx(0.0, abs=1e-9)
    assert untyped(pose[None])[0] == pytest.approx(0.0, abs=1e-9)  # a view without labels: the paper's eq. (1)
    assert swapped(pose[None])[0] == pytest.approx(swapped.no_match_fitness)  # nothing of its class within tau
    img_nn, _, mod_nn, _ = matches(swapped.project(0, pose[None]), swapped.problem.views[0].points, swapped.labels(0))
    assert list(img_nn[0]) == [1, 0] and list(mod_nn[0]) == [1, 0]  # nearest of the own class, 20 px away


def test_label_coordinates_are_zero_unless_both_sides_are_labelled():
    problem = _one_view(np.array([0, 3]), None)
    pz, mz = label_coordinates(problem.model, problem.views[0])
    assert not pz.any() and not mz.any()
    problem = _one_view(np.array([0, 3]), np.array([3, 0]))
    pz, mz = label_coordinates(problem.model, problem.views[0])
    assert pz[0] == mz[1] and pz[1] == mz[0] and mz[1] - mz[0] > 1e5


@pytest.mark.parametrize("labels", [np.array([0.5, 1.0]), np.array([0, -1]), np.array([0, 1, 2])])
def test_bad_labels_are_refused(labels):
    with pytest.raises(ValueError, match="labels must be 2 integers >= 0"):
        Model(np.zeros((2, 3)), labels=labels)
    with pytest.raises(ValueError, match="labels must be 2 integers >= 0"):
        View(Camera(fx=500, fy=500, cx=50, cy=50, width=100, height=100), np.zeros((2, 2)), labels=labels)


def test_colours_resolve_the_paper_scale_ambiguity():
    """The same seeded paper-scale problems (one camera, 0.5-2 px noise, 0-30 % clutter in the mark colours) with
    and without the marks' colours: untyped, eq. (1) prefers a wrong pose on some; typed, every one is right."""
    right = {False: 0, True: 0}
    for i in range(6):
        for labelled in (False, True):
            sp = make_paper_scale_problem(np.random.default_rng([7, i, 2]), cameras=("H1",), labelled=labelled)
            right[labelled] += bool(in_true_basin(sp, solve(sp.problem, seed=i).pose))
    assert right[True] == 6
    assert right[False] < 6


def test_one_class_everywhere_is_the_untyped_fitness():
    """The typed kernels (label axis) and the untyped ones (the paper's plane) agree when every point and mark is of
    one class: the label axis adds nothing between points of one class."""
    sp = make_paper_scale_problem(np.random.default_rng(5), cameras=("H1", "H2"))
    one_class = PoseProblem(Model(sp.problem.model.points, sp.problem.model.normals, np.full(18, 2)),
                            tuple(View(v.camera, v.points, v.weight, np.full(len(v.points), 2))
                                  for v in sp.problem.views), sp.problem.bounds)
    poses = sp.true_pose + np.random.default_rng(6).normal(0, 0.05, (64, 6))
    typed, untyped = PoseObjective(one_class), PoseObjective(sp.problem)
    assert typed.labels(0)[0].any()  # the typed path runs
    np.testing.assert_allclose(typed(poses), untyped(poses), rtol=1e-12)
    np.testing.assert_allclose(refine(typed, poses[:8])[1], refine(untyped, poses[:8])[1], rtol=1e-9)
