"""The solver regression check's truth columns (benchmarks/solver_regression.py): the oracle, the right basin and
whether a pose's error lies within its own covariance."""

from types import SimpleNamespace

import numpy as np

from benchmarks.problems import make_telephoto_box_problem
from benchmarks.solver_regression import COVERED_MAHALANOBIS, SEED, truth_checks


def test_a_pose_is_covered_by_its_covariance_only_where_its_error_lies_within_it():
    sp = make_telephoto_box_problem(np.random.default_rng([SEED, 0, 0]))   # the suite's first box
    tight = np.diag([0.002 ** 2] * 3 + [np.radians(0.1) ** 2] * 3)          # 2 mm, 0.1 deg
    oracle, basin, covered = truth_checks(sp, SimpleNamespace(pose=sp.true_pose.copy(), covariance=tight))
    assert oracle and basin and covered
    off = sp.true_pose.copy()
    off[0] += 0.02                                                             # 2 cm (~2 px): 10 sigma along x
    _, basin, covered = truth_checks(sp, SimpleNamespace(pose=off, covariance=tight))
    assert basin and not covered
    wide = tight * (0.04 / 0.002) ** 2                                         # 4 cm: half a sigma
    assert truth_checks(sp, SimpleNamespace(pose=off, covariance=wide))[2]
    assert 4.4 < COVERED_MAHALANOBIS < 4.6                                     # 3 sigma's 99.73 % over 6 parameters
