"""The import rules of docs/architecture.md, checked on the code: each room imports only what it may.

Module-level imports are read with ``ast`` (imports inside functions are the CLI's lazy imports and are
allowed); the CLI's lightness and the problem file's independence from the renderer are checked in a
fresh interpreter.
"""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: room (a package or sub-package) -> project packages its modules may import at module level
ALLOWED = {
    "geometry": {"geometry"},
    "evopose": {"evopose", "geometry"},
    "protocol": {"protocol", "geometry"},
    "scenarios": {"scenarios", "evopose", "geometry"},
    "vision": {"vision", "scenarios", "evopose", "geometry"},
    "agents.runs": {"agents.runs", "geometry"},
    "agents.transport": {"agents.transport", "agents.errors", "protocol", "geometry"},
    "agents.vehicle": {"agents.vehicle", "agents.transport", "agents.problem", "agents.errors", "agents.runs",
                       "vision", "evopose", "protocol", "scenarios", "geometry"},
    "agents.tools": {"agents.tools", "agents.transport", "agents.problem", "agents.errors", "vision", "evopose",
                     "protocol", "scenarios", "geometry"},
    "agents.experiments": {"agents.experiments", "agents.errors", "agents.runs", "scenarios", "geometry"},
    "agents.problem": {"agents.problem", "agents.errors", "vision", "evopose", "scenarios", "geometry"},
    "agents.bridges": {"agents.bridges", "agents.transport", "agents.errors", "protocol", "scenarios", "geometry"},
    "agents.cli": {"agents.cli", "agents.errors", "agents.experiments", "agents.vehicle.config"},
}
PROJECT = ("geometry", "evopose", "vision", "protocol", "scenarios", "agents")
#: third-party libraries a room may import at module level (the rest of the project may import any)
THIRD_PARTY = {
    "geometry": {"numpy"},
    "evopose": {"numpy", "scipy", "numba"},   # the pose search: no image processing, no files (docs/design.md)
    "vision": {"numpy", "scipy", "cv2"},
    "protocol": {"numpy", "pydantic", "msgpack"},
    "agents.cli": {"typer", "rich"},
}


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _room(module: str) -> str | None:
    return max((room for room in ALLOWED if module == room or module.startswith(room + ".")), key=len,
               default=None)


def _top_level_imports(path: Path) -> list[str]:
    """Absolute names imported at module level (relative imports resolved)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = _module_name(path) if path.name == "__init__.py" else _module_name(path).rpartition(".")[0]
    names = []
    for node in tree.body:
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                module = ".".join([*base, node.module] if node.module else base)
            else:
                module = node.module or ""
            names.append(module)
            names += [f"{module}.{alias.name}" for alias in node.names]
    return names


def _modules() -> list[Path]:
    return sorted(p for pkg in PROJECT for p in (ROOT / pkg).rglob("*.py"))


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(ROOT)))
def test_each_room_imports_only_what_it_may(path):
    module = _module_name(path)
    room = _room(module)
    if room is None:
        return
    allowed = ALLOWED[room]
    for name in _top_level_imports(path):
        top = name.split(".")[0]
        if top in PROJECT:
            # ``from agents.vehicle import config`` names agents.vehicle (a face) and agents.vehicle.config
            ok = any(name == a or name.startswith(a + ".") or a.startswith(name + ".") for a in allowed)
            assert ok, f"{module} imports {name}; room {room} may import {sorted(allowed)}"
        elif room in THIRD_PARTY and top not in sys.stdlib_module_names and top != "__future__":
            assert top in THIRD_PARTY[room], f"{module} imports {top}; room {room} may import {THIRD_PARTY[room]}"


def _loaded_after(statement: str) -> set[str]:
    code = f"import sys; {statement}; print(' '.join(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return set(out.stdout.split())


def test_the_cli_imports_nothing_heavy_to_print_help():
    loaded = _loaded_after("from agents.cli.main import app")
    assert not loaded & {"numpy", "scipy", "numba", "cv2", "zenoh", "pydantic", "evopose", "scenarios", "geometry"}


def test_the_problem_file_contract_does_not_pull_in_the_renderer():
    loaded = _loaded_after("import agents.problem.problem_file, agents.problem.solve")
    assert "scenarios.render" not in loaded and "zenoh" not in loaded


def test_the_pose_search_reads_and_writes_no_files():
    """evopose/ is the search (eq. 1-4): images and files are vision's and the agents' (docs/architecture.md)."""
    io = re.compile(r"\bopen\(|\bPath\(|read_text|write_text|read_bytes|np\.load|np\.save|json\.load")
    found = [f"{p.relative_to(ROOT)}:{n}" for p in sorted((ROOT / "evopose").rglob("*.py"))
             for n, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) if io.search(line)]
    assert not found


def test_agents_keeps_at_most_four_modules_at_its_top_level():
    top = [p.name for p in (ROOT / "agents").glob("*.py")]
    assert len(top) <= 4, top


def test_no_module_is_over_450_lines():
    long = {str(p.relative_to(ROOT)): n for p in _modules()
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > 450}
    assert not long


def test_the_vehicle_runtime_holds_no_lock_and_dispatches_on_no_share_mode_string():
    """roles.py keeps the clock, the camera, the bus and the frame loop (docs/architecture.md): the vehicle's state
    has one owner, so no lock; the share mode's rules are one SharePolicy value (agents/vehicle/step.py), so no
    comparison with a mode or topic name."""
    source = (ROOT / "agents" / "vehicle" / "roles.py").read_text(encoding="utf-8")
    assert "Lock(" not in source and "improver" not in source
    names = ("none", "raw", "features", "hint", "image", "pose")
    compared = [n for n in names if f'== "{n}"' in source or f'"{n}" in' in source or f'== "{n}"'.replace('"', "'")
                in source]
    assert not compared, compared
