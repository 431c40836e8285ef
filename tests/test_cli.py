"""`evopose solve`: the example files, the JSON contract, and malformed inputs (exit code 2). Most run the CLI's
``main`` in this process (tests/cli_run.py); the human-readable table and ``--help`` run as real subprocesses."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from benchmarks.problems import is_success, pose_errors
from examples.make_examples import EXAMPLES, EXAMPLES_DIR, IMU_TOLERANCE, generate, render
from geometry import PARAM_NAMES
from geometry import angle_difference
from tests.cli_run import run_cli as evopose

ROOT = Path(__file__).resolve().parents[1]
DESIGN_KEYS = {"pose", "fitness", "generations", "evaluations", "seconds", "converged"}
POSE_KEYS = {"x", "y", "z", "roll", "pitch", "yaw", "quaternion"}


def evopose_process(*args: str | Path, timeout: float = 120) -> subprocess.CompletedProcess:
    """Run ``python -m agents.cli ARGS`` from the repository root."""
    return subprocess.run([sys.executable, "-m", "agents.cli", *map(str, args)], cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout)


def solve_json(path: Path, *args: str) -> dict:
    result = evopose("solve", path, "--json", *args)
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    return json.loads(result.stdout)


def assert_design_shape(out: dict) -> None:
    assert DESIGN_KEYS <= set(out), sorted(out)
    assert set(out["pose"]) == POSE_KEYS
    assert all(isinstance(out["pose"][k], float) for k in PARAM_NAMES)
    q = out["pose"]["quaternion"]
    assert len(q) == 4 and math.isclose(sum(c * c for c in q), 1.0, rel_tol=1e-9)
    assert isinstance(out["fitness"], float) and isinstance(out["seconds"], float)
    assert isinstance(out["generations"], int) and isinstance(out["evaluations"], int)
    assert isinstance(out["converged"], bool)


# -- the examples -------------------------------------------------------------------------------

@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_example_solves_to_its_true_pose(name):
    out = solve_json(EXAMPLES_DIR / f"{name}.yaml")
    assert_design_shape(out)
    _, synthetic = render(name)
    estimate = np.array([out["pose"][k] for k in PARAM_NAMES])
    rot, pos = pose_errors(estimate, synthetic.true_pose, synthetic.symmetries,
                           synthetic.problem.model.points.mean(axis=0))
    assert is_success(rot, pos, synthetic.distance), (
        f"SOLVER ACCURACY (evopose/, not the CLI): examples/{name}.yaml solved to a pose "
        f"{math.degrees(rot):.1f} deg / {pos:.3f} m from the truth (distance {synthetic.distance:.1f} m; "
        f"success needs < 5 deg and < 5 %); fitness {out['fitness']:.3f}, stop {out.get('stop_reason')}")


def test_imu_constraints_hold_in_the_output():
    _, constraints = generate(EXAMPLES["airship_imu"])
    out = solve_json(EXAMPLES_DIR / "airship_imu.yaml")
    for name, (value, tolerance) in constraints.items():
        assert tolerance == IMU_TOLERANCE
        assert abs(angle_difference(out["pose"][name], value)) <= tolerance + 1e-9, (name, out["pose"][name], value)


def test_seed_reproduces_the_run():
    path = EXAMPLES_DIR / "random_points.yaml"
    first, second = (solve_json(path, "--seed", "5") for _ in range(2))
    assert first["pose"] == second["pose"] and first["evaluations"] == second["evaluations"]


def test_fitness_and_time_budget_options(tmp_path):
    document = yaml.safe_load((EXAMPLES_DIR / "pioneer_clutter.yaml").read_text(encoding="utf-8"))
    document["options"] = {"consensus": 0, "patience": 100000}  # only the time budget can stop it
    path = tmp_path / "problem.yaml"
    path.write_text(yaml.safe_dump(document), encoding="utf-8")
    out = solve_json(path, "--time-budget", "0.3", "--fitness", "paper")
    assert_design_shape(out)
    assert out["stop_reason"] == "time_budget" and out["seconds"] < 1.5


def test_table_output():
    result = evopose_process("solve", EXAMPLES_DIR / "random_points.yaml")
    assert result.returncode == 0, result.stderr
    for word in ("x", "roll", "°", "fitness", "generations", "time", "converged"):
        assert word in result.stdout


def test_console_script_help():
    script = Path(sys.executable).with_name("evopose")
    result = subprocess.run([script, "--help"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0 and "solve" in result.stdout


# -- malformed inputs: exit 2, one stderr line naming the field, no traceback --------------------------

VALID = """\
model: {points: [[0, 0, 0], [0.2, 0, 0], [0, 0.2, 0], [0, 0, 0.2]]}
views:
  - camera: {fx: 800, fy: 800, cx: 320, cy: 240, width: 640, height: 480}
    points: [[320, 240], [352, 240], [320, 272], [330, 250]]
search: {x: [-1, 1], y: [-1, 1], z: [2, 8]}
"""

MALFORMED_FILES = {
    "missing model": (VALID.split("\n", 1)[1], "model: required field missing"),
    "points of wrong shape": (VALID.replace("[330, 250]", "[330, 250, 1]"),
                              "views[0].points[3]: expected 2 numbers [u, v], got 3"),
    "NaN in points": (VALID.replace("[330, 250]", "[.nan, 250]"), "views[0].points[3][0]: expected a finite number"),
    "empty points": (VALID.replace("points: [[320, 240], [352, 240], [320, 272], [330, 250]]", "points: []"),
                     "views[0].points: must not be empty"),
    "bounds lo > hi": (VALID.replace("z: [2, 8]", "z: [8, 2]"), "search.z: lo 8.0 > hi 2.0"),
    "non-mapping YAML": ("- model\n- views\n", "top level must be a mapping"),
    "invalid YAML": (VALID + "search: {x: [0, 1]\n", "invalid YAML"),
    "unknown search parameter": (VALID.replace("z: [2, 8]", "z: [2, 8], heading: [0, 1]"),
                                 "search.heading: unknown key"),
    "negative tolerance": (VALID + "constraints: {roll: {value: 0.1, tolerance: -0.002}}\n",
                           "constraints.roll.tolerance: must be >= 0"),
    "constraint outside the search range": (VALID + "constraints: {z: {value: 9.5, tolerance: 0.5}}\n",
                                            "constraints.z: constraint on z"),
}


def assert_usage_error(result: subprocess.CompletedProcess, expected: str) -> None:
    assert result.returncode == 2, (result.returncode, result.stderr)
    assert "Traceback" not in result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("error: ") and expected in lines[0], lines[0]
    assert result.stdout == ""


@pytest.mark.parametrize("text, expected", MALFORMED_FILES.values(), ids=MALFORMED_FILES.keys())
def test_malformed_file_exits_2_naming_the_field(tmp_path, text, expected):
    path = tmp_path / "problem.yaml"
    path.write_text(text, encoding="utf-8")
    assert_usage_error(evopose("solve", path, "--json"), expected)


def test_nonexistent_file(tmp_path):
    assert_usage_error(evopose("solve", tmp_path / "missing.yaml"), "missing.yaml: cannot read: No such file")


def test_unreadable_file(tmp_path):
    path = tmp_path / "problem.yaml"
    path.write_bytes(b"\x80\x81 not text")
    assert_usage_error(evopose("solve", path), "problem.yaml: cannot read: not UTF-8 text")
    assert_usage_error(evopose("solve", tmp_path), "cannot read")


@pytest.mark.parametrize("args, expected", [
    (("solve",), "Missing argument"),
    (("solve", "p.yaml", "--fitness", "fast"), "--fitness"),
    (("solve", "p.yaml", "--seed", "-1"), "--seed"),
    (("solve", "p.yaml", "--time-budget", "soon"), "--time-budget"),
    (("solve", "p.yaml", "--verbose"), "--verbose"),
    (("teleport",), "No such command"),
])
def test_bad_arguments_exit_2(args, expected):
    assert_usage_error(evopose(*args), expected)
