"""Unit tests of evopose.problem: Model, View, Bounds (search box and eq. 3 constraints), PoseProblem."""

from __future__ import annotations

import numpy as np
import pytest

from evopose.camera import Camera
from geometry import PARAM_NAMES
from evopose.problem import Bounds, Model, PoseProblem, View
from geometry import angle_difference

PI = np.pi
TWO_PI = 2 * np.pi


def full_bounds() -> Bounds:
    """x, y, z boxes and full-turn angles."""
    return Bounds([-5, -4, 1, -PI, -PI, -PI], [5, 4, 20, PI, PI, PI])


def same_angle(a, b, atol=1e-12) -> bool:
    return bool(np.all(np.abs(angle_difference(a, b)) <= atol))


# --- Bounds validation ---------------------------------------------------------------------------

@pytest.mark.parametrize("i", range(6))
def test_bounds_lo_above_hi_names_the_parameter(i):
    lo = np.array([-1.0, -1, 1, -0.5, -0.5, -0.5])
    hi = np.array([1.0, 1, 2, 0.5, 0.5, 0.5])
    lo[i] = hi[i] + 0.1
    with pytest.raises(ValueError, match=rf"\b{PARAM_NAMES[i]}\b"):
        Bounds(lo, hi)


@pytest.mark.parametrize("lo, hi", [
    (np.zeros(5), np.ones(5)),
    (np.zeros(6), np.ones(7)),
    (np.zeros((2, 6)), np.ones((2, 6))),
])
def test_bounds_wrong_sizes(lo, hi):
    with pytest.raises(ValueError, match="6 values"):
        Bounds(lo, hi)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_bounds_non_finite(bad):
    lo, hi = np.zeros(6), np.ones(6)
    lo[2] = bad
    with pytest.raises(ValueError, match="finite"):
        Bounds(lo, hi)


def test_bounds_equal_lo_hi_is_a_fixed_parameter():
    b = Bounds([0, 0, 5, 0, 0, 0], [1, 1, 5, 0.1, 0.1, 0.1])
    np.testing.assert_array_equal(b.free, [True, True, False, True, True, True])
    np.testing.assert_array_equal(b.width, [1, 1, 0, 0.1, 0.1, 0.1])


def test_bounds_from_dict():
    b = Bounds.from_dict({"x": (-1, 1), "y": (-2, 2), "z": (3, 9), "pitch": (-0.5, 0.5)})
    np.testing.assert_array_equal(b.lo, [-1, -2, 3, -PI, -0.5, -PI])
    np.testing.assert_array_equal(b.hi, [1, 2, 9, PI, 0.5, PI])
    np.testing.assert_array_equal(b.periodic, [False, False, False, True, False, True])
    with pytest.raises(ValueError, match=r"missing.*\bz\b"):
        Bounds.from_dict({"x": (-1, 1), "y": (-2, 2)})
    with pytest.raises(ValueError, match="'rol'"):
        Bounds.from_dict({"x": (-1, 1), "y": (-2, 2), "z": (3, 9), "rol": (0, 1)})
    with pytest.raises(ValueError, match=r"\by\b"):
        Bounds.from_dict({"x": (-1, 1), "y": (2, -2), "z": (3, 9)})


def test_periodic_mask():
    b = Bounds([-10, -10, -10, -PI, 0, -0.5], [10, 10, 10, PI, TWO_PI, 0.5])
    # only angles spanning a full turn are periodic, never positions (however wide)
    np.testing.assert_array_equal(b.periodic, [False, False, False, True, True, False])
    almost = Bounds([0, 0, 0, -PI, -PI, -PI], [1, 1, 1, PI - 1e-3, PI, PI])
    np.testing.assert_array_equal(almost.periodic, [False, False, False, False, True, True])


# --- Bounds.project / contains ------------------------------------------------------------------

def test_project_clips_positions_and_wraps_periodic_angles():
    b = Bounds([-5, -4, 1, -PI, -0.5, 0.0], [5, 4, 20, PI, 0.5, TWO_PI])
    s = np.array([
        [7.0, -9.0, 0.5, 4.0, 0.7, -0.5],
        [-5.0, 4.0, 20.0, -PI - 0.25, -0.2, 7.0],
        [0.0, 0.0, 10.0, 13 * PI, 0.2, 1.0],
    ])
    s0 = s.copy()
    out = b.project(s)
    np.testing.assert_array_equal(s, s0)  # input untouched
    np.testing.assert_allclose(out[:, :3], [[5, -4, 1], [-5, 4, 20], [0, 0, 10]])
    np.testing.assert_allclose(out[:, 4], [0.5, -0.2, 0.2])                   # non-periodic angle: clipped
    np.testing.assert_allclose(out[:, 3], [4.0 - TWO_PI, PI - 0.25, -PI], atol=1e-12)  # wrapped into [lo, lo + 2 pi)
    np.testing.assert_allclose(out[:, 5], [TWO_PI - 0.5, 7.0 - TWO_PI, 1.0], atol=1e-12)
    assert np.all(out[:, [3, 5]] >= b.lo[[3, 5]]) and np.all(out[:, [3, 5]] < b.lo[[3, 5]] + TWO_PI)
    assert same_angle(out[:, 3], s[:, 3], atol=1e-9) and same_angle(out[:, 5], s[:, 5], atol=1e-9)
    assert b.contains(out).all()
    # points already inside are unchanged
    inside = b.uniform(50, np.random.default_rng(0))
    np.testing.assert_allclose(b.project(inside), inside, atol=1e-12)


def test_project_keeps_leading_axes():
    b = full_bounds()
    s = np.random.default_rng(1).uniform(-30, 30, (3, 4, 6))
    out = b.project(s)
    assert out.shape == (3, 4, 6)
    assert b.contains(out).all()
    np.testing.assert_array_equal(out[1, 2], b.project(s[1, 2]))


def test_contains():
    b = Bounds([-1, -1, 1, -PI, -0.5, -0.5], [1, 1, 2, PI, 0.5, 0.5])
    s = np.array([
        [0, 0, 1.5, 10.0, 0, 0],      # periodic roll: any value
        [1.1, 0, 1.5, 0, 0, 0],
        [0, 0, 1.5, 0, 0.6, 0],
        [0, 0, 2.0, 0, 0.5, -0.5],    # on the boundary
    ])
    np.testing.assert_array_equal(b.contains(s), [True, False, False, True])


# --- eq. (3): constrained ------------------------------------------------------------------------

def test_constrained_intersects_with_the_box():
    b = full_bounds()
    c = b.constrained("x", 4.0, 2.0)
    np.testing.assert_array_equal(c.lo, np.r_[2.0, b.lo[1:]])
    np.testing.assert_array_equal(c.hi, np.r_[5.0, b.hi[1:]])
    c = b.constrained("z", 10.0, 0.5)
    np.testing.assert_array_equal([c.lo[2], c.hi[2]], [9.5, 10.5])
    np.testing.assert_array_equal(np.delete(c.lo, 2), np.delete(b.lo, 2))
    np.testing.assert_array_equal(np.delete(c.hi, 2), np.delete(b.hi, 2))
    # the original is not modified (frozen dataclass, new object)
    np.testing.assert_array_equal(b.lo, full_bounds().lo)
    # a non-periodic angle range
    r = Bounds(b.lo, b.hi.copy()).constrained("pitch", 0.3, 0.1)
    np.testing.assert_allclose([r.lo[4], r.hi[4]], [0.2, 0.4])
    assert not r.periodic[4]


def test_constrained_tolerance_zero_fixes_the_parameter():
    b = full_bounds()
    c = b.constrained("roll", 0.25, 0.0).constrained("y", -1.5, 0)
    assert c.lo[3] == c.hi[3] == 0.25
    assert c.lo[1] == c.hi[1] == -1.5
    np.testing.assert_array_equal(c.free, [True, False, True, False, True, True])
    assert not c.periodic[3]
    s = c.project(np.random.default_rng(2).uniform(-10, 10, (20, 6)))
    np.testing.assert_array_equal(s[:, 3], 0.25)
    np.testing.assert_array_equal(s[:, 1], -1.5)
    u = c.uniform(20, np.random.default_rng(3))
    np.testing.assert_array_equal(u[:, 3], 0.25)
    np.testing.assert_array_equal(u[:, 1], -1.5)


@pytest.mark.parametrize("name, value, tol", [
    ("x", 10.0, 1.0),
    ("z", 0.0, 0.5),
    ("pitch", 1.0, 0.1),
])
def test_constraint_outside_the_range_raises(name, value, tol):
    b = Bounds([-5, -4, 1, -PI, -0.5, -PI], [5, 4, 20, PI, 0.5, PI])
    with pytest.raises(ValueError, match=rf"constraint on {name}.*outside"):
        b.constrained(name, value, tol)


@pytest.mark.parametrize("value, tol", [(0.0, -0.1), (np.nan, 0.1), (0.0, np.inf), (np.inf, 0.0)])
def test_constraint_bad_numbers_raise(value, tol):
    with pytest.raises(ValueError, match="constraint on x"):
        full_bounds().constrained("x", value, tol)


def test_constraint_on_unknown_parameter_raises():
    with pytest.raises(ValueError):
        full_bounds().constrained("heading", 0.0, 0.1)


def test_angle_constraint_on_non_periodic_range_is_taken_modulo_a_turn():
    b = Bounds([-5, -4, 1, -0.5, -0.5, -0.5], [5, 4, 20, 0.5, 0.5, 0.5])
    c = b.constrained("roll", TWO_PI + 0.1, 0.05)
    np.testing.assert_allclose([c.lo[3], c.hi[3]], [0.05, 0.15], atol=1e-12)
    c = b.constrained("yaw", -TWO_PI - 0.45, 0.1)
    np.testing.assert_allclose([c.lo[5], c.hi[5]], [-0.5, -0.35], atol=1e-12)


def test_angle_constraint_near_pi_on_periodic_angle_box():
    b = full_bounds()
    value, tol = PI - 0.02, 0.05          # the admissible yaw straddles +-pi: [pi - 0.07, -pi + 0.03]
    c = b.constrained("yaw", value, tol)
    assert c.free[5] and not c.periodic[5]
    assert c.width[5] == pytest.approx(2 * tol)
    assert c.lo[5] <= value <= c.hi[5]
    assert same_angle(c.lo[5], value - tol) and same_angle(c.hi[5], value + tol)
    # tolerance 0 at exactly +-pi fixes yaw at that angle
    f = b.constrained("yaw", -PI, 0.0)
    assert not f.free[5] and same_angle(f.lo[5], PI)


def test_angle_constraint_near_pi_accepts_the_equivalent_angle():
    """A yaw reported as -pi + 0.01 (e.g. by euler_from_rotation or a hint) is pi + 0.01, inside the box
    [pi - 0.07, pi + 0.03]: ``project`` must keep that orientation (not clip it to the far end of the
    box) and ``contains`` must accept it."""
    c = full_bounds().constrained("yaw", PI - 0.02, 0.05)
    s = np.array([[0, 0, 5, 0, 0, -PI + 0.01], [0, 0, 5, 0, 0, PI - 0.05]])
    out = c.project(s)
    assert same_angle(out[:, 5], s[:, 5], atol=1e-12), f"project changed the orientation: {out[:, 5]}"
    assert np.all((out[:, 5] >= c.lo[5]) & (out[:, 5] <= c.hi[5]))
    np.testing.assert_array_equal(c.contains(s), [True, True])
    # and an angle outside the admissible arc goes to its nearest end (here -pi + 0.1 -> pi + 0.03)
    far = c.project(np.array([0, 0, 5, 0, 0, -PI + 0.1]))
    assert same_angle(far[5], c.hi[5])


def test_angle_constraint_on_non_periodic_angle_accepts_the_equivalent_angle():
    """The same for a box that does not straddle +-pi: roll 0.1 + 2 pi is roll 0.1, inside [-0.5, 0.5]."""
    b = Bounds([-5, -4, 1, -0.5, -0.5, -0.5], [5, 4, 20, 0.5, 0.5, 0.5])
    out = b.project(np.array([0, 0, 5, 0.1 + TWO_PI, -0.2 - TWO_PI, 0.0]))
    np.testing.assert_allclose(out[3:5], [0.1, -0.2], atol=1e-12)


def test_periodic_constraint_with_a_full_turn_tolerance_stays_periodic():
    c = full_bounds().constrained("roll", 0.3, PI)
    assert c.periodic[3]
    assert c.width[3] == pytest.approx(TWO_PI)


# --- Bounds.uniform ---------------------------------------------------------------------------------

def test_uniform_within_box_and_reproducible():
    b = Bounds([-5, -4, 1, -PI, -0.5, 0.1], [5, 4, 20, PI, 0.5, 0.1])
    s = b.uniform(5000, np.random.default_rng(10))
    assert s.shape == (5000, 6)
    assert np.all(s >= b.lo) and np.all(s <= b.hi)
    np.testing.assert_array_equal(s[:, 5], 0.1)
    # spread over the box: near both ends, mean at the centre
    free = b.free
    assert np.all(s[:, free].min(axis=0) < b.lo[free] + 0.01 * b.width[free])
    assert np.all(s[:, free].max(axis=0) > b.hi[free] - 0.01 * b.width[free])
    np.testing.assert_allclose(s[:, free].mean(axis=0), ((b.lo + b.hi) / 2)[free], atol=0.03 * b.width[free].max())
    np.testing.assert_array_equal(s, b.uniform(5000, np.random.default_rng(10)))
    assert not np.array_equal(s, b.uniform(5000, np.random.default_rng(11)))


# --- Model, View, PoseProblem -----------------------------------------------------------------------

@pytest.mark.parametrize("points, match", [
    (np.zeros((4, 2)), r"model\.points.*\(4, 2\)"),
    (np.zeros((0, 3)), r"model\.points.*\(0, 3\)"),
    (np.zeros(3), r"model\.points.*\(3,\)"),
    (np.array([[0, 0, np.nan]]), r"model\.points must be finite"),
])
def test_model_validation(points, match):
    with pytest.raises(ValueError, match=match):
        Model(points)


def test_model_normals():
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    m = Model(pts, np.array([[0, 0, 2.0], [3, 0, 0], [0, -0.5, 0]]))
    np.testing.assert_allclose(m.normals, [[0, 0, 1], [1, 0, 0], [0, -1, 0]])
    assert m.points.dtype == float
    with pytest.raises(ValueError, match=r"model\.normals.*\(3, 3\)"):
        Model(pts, np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"model\.normals"):
        Model(pts, np.array([[0, 0, 1.0], [0, 0, 0], [1, 0, 0]]))
    with pytest.raises(ValueError, match=r"model\.normals"):
        Model(pts, np.array([[0, 0, np.nan], [0, 0, 1], [1, 0, 0]]))


def test_model_radius():
    m = Model(np.array([[1, 1, 1], [3, 1, 1], [2, 1, 1.0]]))
    assert m.radius == pytest.approx(1.0)
    assert Model(np.array([[2.0, 3.0, 4.0]])).radius > 0


def test_view_validation():
    cam = Camera(500, 500, 320, 240)
    v = View(cam, [[1, 2], [3, 4]], weight=0.25)
    assert v.points.shape == (2, 2) and v.points.dtype == float and v.weight == 0.25
    assert View(cam, [[1, 2]], weight=0.0).weight == 0.0
    with pytest.raises(ValueError, match=r"view points.*\(2, 3\)"):
        View(cam, np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"view points.*\(0, 2\)"):
        View(cam, np.zeros((0, 2)))
    with pytest.raises(ValueError, match="view points must be finite"):
        View(cam, np.array([[1.0, np.inf]]))
    for w in (-0.1, np.nan, np.inf):
        with pytest.raises(ValueError, match="view weight"):
            View(cam, np.zeros((1, 2)), weight=w)


def test_pose_problem():
    cam = Camera(500, 500, 320, 240)
    model = Model(np.zeros((1, 3)))
    view = View(cam, np.zeros((1, 2)))
    with pytest.raises(ValueError, match="at least one view"):
        PoseProblem(model, (), full_bounds())
    p = PoseProblem(model, [view], full_bounds())
    assert isinstance(p.views, tuple) and p.hints.shape == (0, 6)
    q = p.with_hints([1, 2, 3, 0.1, 0.2, 0.3])
    np.testing.assert_array_equal(q.hints, [[1, 2, 3, 0.1, 0.2, 0.3]])
    assert p.hints.shape == (0, 6)
    assert p.with_views([view, view]).views == (view, view)
    with pytest.raises(ValueError, match="hints must be finite"):
        p.with_hints([1, 2, 3, 0.1, np.nan, 0.3])


def test_angle_difference():
    np.testing.assert_allclose(angle_difference(PI - 0.1, -PI + 0.1), -0.2, atol=1e-12)
    np.testing.assert_allclose(angle_difference(-PI + 0.1, PI - 0.1), 0.2, atol=1e-12)
    np.testing.assert_allclose(angle_difference([0.3, 7.0], [0.1, 0.0]), [0.2, 7.0 - TWO_PI], atol=1e-12)
