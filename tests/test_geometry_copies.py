"""The pose convention lives in one module, :mod:`geometry` (docs/design.md §2): a copy anywhere else fails here.

The source of every project module, test, benchmark and example is scanned for the tell-tale lines of the
rotation ``Rz(yaw) Ry(pitch) Rx(roll)``, its quaternion, its inverse, angle wrapping and the geodesic angle.
A new copy must import :mod:`geometry` instead.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import geometry

ROOT = Path(__file__).resolve().parents[1]
HOME = ROOT / "geometry"
#: Blender's interpreter runs this file with stdlib and bpy only; its one wrap is the sun's azimuth into [0, 2 pi).
EXEMPT = {ROOT / "scenarios" / "photoreal" / "blender_job.py"}
SCANNED = ("geometry", "evopose", "protocol", "scenarios", "agents", "benchmarks", "examples", "tests")

#: name -> pattern of one copy (whitespace-insensitive where it matters)
COPIES = {
    "rotation entry Rz Ry Rx": re.compile(r"cy\s*\*\s*sp\s*\*\s*sr\s*-\s*sy\s*\*\s*cr"),
    "quaternion from Euler angles": re.compile(r"sr\s*\*\s*cp\s*\*\s*cy\s*-\s*cr\s*\*\s*sp\s*\*\s*sy"),
    "Euler angles from a quaternion": re.compile(r"2\s*\*\s*\(\s*w\s*\*\s*x\s*\+\s*y\s*\*\s*z\s*\)"),
    "Euler angles from a rotation matrix": re.compile(r"arctan2\(\s*-\s*R\[\.\.\., 2, 0\]"),
    "angle wrapping": re.compile(r"\+\s*(np|math)\.pi\s*\)\s*%\s*\(?\s*(2\s*\*\s*(np|math)\.pi|(np|math)\.tau)"),
    "geodesic angle": re.compile(r"\(\s*(np\.)?trace\([^)]*\)\s*-\s*1(\.0)?\s*\)\s*/\s*2"),
}


def _sources() -> list[Path]:
    files = [p for d in SCANNED for p in (ROOT / d).rglob("*.py")]
    return sorted(p for p in files if HOME not in p.parents and p not in EXEMPT and p.name != Path(__file__).name)


def copies_in(text: str) -> list[str]:
    """Names of the convention's pieces that ``text`` types out."""
    return [name for name, pattern in COPIES.items() if pattern.search(text)]


@pytest.mark.parametrize("name", sorted(COPIES))
def test_the_geometry_module_itself_holds_each_piece(name):
    text = (HOME / "__init__.py").read_text(encoding="utf-8")
    assert name in copies_in(text), f"the pattern for {name!r} no longer matches geometry: the guard is blind"


def test_the_guard_catches_a_typed_out_copy():
    copy = ("cr, sr = math.cos(roll), math.sin(roll)\n"
            "R01 = cy * sp * sr - sy * cr\n"
            "d = (a - b + np.pi) % (2 * np.pi) - np.pi\n")
    assert copies_in(copy) == ["rotation entry Rz Ry Rx", "angle wrapping"]


def test_no_module_outside_geometry_copies_the_pose_convention():
    found = {str(p.relative_to(ROOT)): names for p in _sources() if (names := copies_in(p.read_text(encoding="utf-8")))}
    assert not found, f"import geometry instead of typing the convention out again: {found}"


def test_the_compiled_projection_uses_the_same_rotation():
    from evopose.projection import rotation_into

    rpy = np.random.default_rng(3).uniform(-np.pi, np.pi, (20, 3))
    R = np.empty((3, 3))
    for roll, pitch, yaw in rpy:
        rotation_into(roll, pitch, yaw, R)
        np.testing.assert_allclose(R, geometry.rotation_from_euler([roll, pitch, yaw]), atol=1e-12)


def test_quaternions_round_trip_through_every_form():
    rng = np.random.default_rng(5)
    rpy = geometry.random_rotations(200, rng)
    q = geometry.quaternion_from_euler(rpy)
    np.testing.assert_allclose(geometry.quaternion_from_rotation(geometry.rotation_from_euler(rpy)), q, atol=1e-12)
    np.testing.assert_allclose(geometry.rotation_from_euler(geometry.euler_from_quaternion(q)),
                               geometry.rotation_from_euler(rpy), atol=1e-9)
    assert np.all(q[:, 3] >= 0) and np.allclose(np.linalg.norm(q, axis=1), 1)


def test_pose_error_compares_the_same_rotation_written_two_ways():
    pose = np.array([1.0, 2.0, 3.0, 0.3, 0.2, 0.1])
    other_triple = np.r_[pose[:3], pose[3] + np.pi, np.pi - pose[4], pose[5] + np.pi]  # same rotation
    np.testing.assert_allclose(geometry.rotation_from_euler(other_triple[3:]),
                               geometry.rotation_from_euler(pose[3:]), atol=1e-12)
    error = geometry.pose_error(other_triple, pose)
    assert max(error.values()) < 1e-9
    assert float(geometry.rotation_error(other_triple, pose)) < 1e-7
    moved = geometry.pose_error(pose + [0.3, 0.4, 0, 0, 0, np.radians(2)], pose)
    assert moved["position"] == pytest.approx(0.5) and moved["yaw"] == pytest.approx(2.0)


def test_rotation_vectors_agree_with_scipy():
    """geometry's rotation vectors are scipy's ``Rotation.from_rotvec`` / ``as_rotvec`` (which the covariance used
    before; docs/design.md §2, "Lazy imports"), within rounding, down to tiny angles and up to a half turn."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(8)
    axes = rng.normal(size=(600, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.concatenate([[0.0, 1e-12, 1e-4, 1e-3, 1.0001e-3], rng.uniform(0, np.pi - 1e-3, 590),
                             np.pi - rng.uniform(1e-9, 1e-4, 5)])
    v = axes * angles[:, None]
    np.testing.assert_allclose(geometry.rotation_from_rotvec(v), Rotation.from_rotvec(v).as_matrix(), atol=1e-14)
    R = geometry.rotation_from_euler(geometry.random_rotations(500, rng))
    np.testing.assert_allclose(geometry.rotvec_from_rotation(R), Rotation.from_matrix(R).as_rotvec(), atol=1e-13)
    np.testing.assert_allclose(geometry.rotvec_from_rotation(geometry.rotation_from_rotvec(v[:-5])), v[:-5],
                               atol=1e-12)
    assert geometry.rotvec_from_rotation(np.eye(3)).shape == (3,)
