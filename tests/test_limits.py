"""Every file the project reads is read with limits, and every breach is one line and exit code 2 (issue 12):
alias bombs, deep nesting, special files, oversized problems, absurd magnitudes; JSON output is always valid."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from agents.cli.options import finite, json_line
from scenarios.documents import MAX_DEPTH, DocumentError, read_mapping

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "airship_imu.yaml"

ALIAS_BOMB = "\n".join(
    ['a: &a ["x","x","x","x","x","x","x","x","x"]']
    + [f"{chr(98 + i)}: &{chr(98 + i)} [" + ",".join([f"*{chr(97 + i)}"] * 9) + "]" for i in range(8)])


def evopose(*args, timeout=60):
    return subprocess.run([sys.executable, "-m", "agents.cli", *map(str, args)], cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout)


def one_line_exit_2(result, expected: str) -> None:
    assert result.returncode == 2, (result.returncode, result.stderr[-500:])
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and expected in lines[0], lines


def test_a_yaml_alias_bomb_is_refused_before_it_is_walked(tmp_path):
    path = tmp_path / "bomb.yaml"
    path.write_text(ALIAS_BOMB)
    assert path.stat().st_size < 2048
    with pytest.raises(DocumentError, match="aliases expand to more than"):
        read_mapping(path)
    for command in (("solve", path), ("scenario", "show", path), ("render", path)):
        one_line_exit_2(evopose(*command), "aliases expand")


def test_anchors_that_yaml_dump_writes_are_fine(tmp_path):
    shared = [1.0, 2.0]
    path = tmp_path / "shared.yaml"
    import yaml
    path.write_text(yaml.safe_dump({"a": shared, "b": shared}))
    assert "&" in path.read_text() and read_mapping(path) == {"a": shared, "b": shared}


@pytest.mark.parametrize("suffix, text", [(".yaml", "a: " + "[" * 100_000 + "]" * 100_000),
                                          (".json", '{"a": ' + "[" * 100_000 + "]" * 100_000 + "}")])
def test_deep_nesting_is_one_line_not_a_recursion_error(tmp_path, suffix, text):
    path = tmp_path / f"deep{suffix}"
    path.write_text(text)
    with pytest.raises(DocumentError, match=f"nesting deeper than {MAX_DEPTH}"):
        read_mapping(path)
    one_line_exit_2(evopose("solve", path), "nesting deeper than")


def test_special_files_are_refused(tmp_path):
    one_line_exit_2(evopose("solve", "/dev/zero"), "not a regular file")
    fifo = tmp_path / "problem.yaml"
    os.mkfifo(fifo)
    one_line_exit_2(evopose("solve", fifo, timeout=30), "not a regular file")
    one_line_exit_2(evopose("solve", tmp_path), "a directory")


def _problem(tmp_path, change) -> Path:
    import yaml
    document = yaml.safe_load(EXAMPLE.read_text())
    change(document)
    path = tmp_path / "problem.json"
    path.write_text(json.dumps(document))
    return path


@pytest.mark.parametrize("change, expected", [
    (lambda d: d.setdefault("options", {}).update(population=10**8), "options.population: at most 4096"),
    (lambda d: d["model"]["points"].__setitem__(0, [1e300, 0.0, 0.0]), "model.points[0]: coordinates must be"),
    (lambda d: d["views"][0].update(points=[[1.0, 2.0]] * 20000), "views[0].points: at most 16384 entries"),
    (lambda d: d.update(views=d["views"] * 40), "views: at most 32 entries"),
])
def test_problem_size_limits_are_one_line(tmp_path, change, expected):
    one_line_exit_2(evopose("solve", _problem(tmp_path, change)), expected)


def test_output_json_never_holds_nan():
    assert finite({"a": float("nan"), "b": [1.0, float("inf")], "c": "x"}) == {"a": None, "b": [1.0, None], "c": "x"}
    assert json.loads(json_line({"fitness": float("nan")})) == {"fitness": None}


def test_a_camera_looking_away_renders_no_marks_instead_of_failing(tmp_path):
    world = tmp_path / "away.yaml"
    world.write_text("extends: exp2\nname: away\nvehicles:\n  - {name: H1, camera: {look_at: [-60.0, 30.0, 12.0]}}\n")
    result = evopose("render", world, "--vehicle", "H1", "--out", tmp_path / "away.png", "--json")
    assert result.returncode == 0, result.stderr[-500:]
    assert json.loads(result.stdout)["marks"] == []
