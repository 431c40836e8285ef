"""The import rules of docs/architecture.md, checked on the code: each room imports only what it may, no two
modules import each other (directly or round a longer loop), and no module imports another's private name.

Imports are read with ``ast``. The rooms' rules read module-level imports (imports inside functions are the
CLI's lazy imports and are allowed across rooms); the cycle and private-name rules read every import, inside
functions too. The CLI's lightness and the problem file's independence from the renderer are checked in a fresh
interpreter.
"""

from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: room (a package or sub-package) -> project packages its modules may import at module level
ALLOWED = {
    "evopose_errors": set(),
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
    # the start signal's writer beside its reader (agents/vehicle/start_signal.py: no numpy, no Zenoh)
    "agents.experiments": {"agents.experiments", "agents.errors", "agents.runs", "agents.vehicle.start_signal",
                           "scenarios", "geometry"},
    "agents.problem": {"agents.problem", "agents.errors", "vision", "evopose", "scenarios", "geometry"},
    "agents.bridges": {"agents.bridges", "agents.transport", "agents.errors", "protocol", "scenarios", "geometry"},
    "agents.cli": {"agents.cli", "agents.errors", "agents.experiments", "agents.vehicle.config"},
}
PROJECT = ("evopose_errors", "geometry", "evopose", "vision", "protocol", "scenarios", "agents")
#: the project's root exception (docs/design.md §2, "Errors"): every room may import it
EVERYWHERE = {"evopose_errors"}
#: third-party libraries a room may import at module level (the rest of the project may import any)
THIRD_PARTY = {
    "evopose_errors": set(),
    "geometry": {"numpy"},
    "evopose": {"numpy", "scipy", "numba"},   # the pose search: no image processing, no files (docs/design.md)
    "vision": {"numpy", "scipy", "cv2"},
    "protocol": {"numpy", "pydantic", "msgpack"},
    "agents.cli": {"typer", "rich"},
}


def _module_name(path: Path, root: Path = ROOT) -> str:
    parts = path.relative_to(root).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _room(module: str) -> str | None:
    return max((room for room in ALLOWED if module == room or module.startswith(room + ".")), key=len,
               default=None)


def _imports(path: Path, everywhere: bool = False, root: Path = ROOT) -> list[tuple[str, str | None, int]]:
    """``(module, name or None, line)`` of each import at module level, or ``everywhere`` (inside functions and
    classes too), relative imports resolved: ``from a.b import c`` gives ``("a.b", "c", line)``, ``import a.b``
    gives ``("a.b", None, line)``."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = _module_name(path, root) if path.name == "__init__.py" else _module_name(path, root).rpartition(".")[0]
    found = []
    for node in (ast.walk(tree) if everywhere else tree.body):
        if isinstance(node, ast.Import):
            found += [(alias.name, None, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                module = ".".join([*base, node.module] if node.module else base)
            else:
                module = node.module or ""
            found += [(module, alias.name, node.lineno) for alias in node.names]
    return found


def _top_level_imports(path: Path) -> list[str]:
    """Absolute names imported at module level (relative imports resolved)."""
    names = []
    for module, name, _ in _imports(path):
        names += [module] if name is None else [module, f"{module}.{name}"]
    return names


def _modules() -> list[Path]:
    return sorted(p for pkg in PROJECT for p in (ROOT / pkg).rglob("*.py"))


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(ROOT)))
def test_each_room_imports_only_what_it_may(path):
    module = _module_name(path)
    room = _room(module)
    if room is None:
        return
    allowed = ALLOWED[room] | EVERYWHERE
    for name in _top_level_imports(path):
        top = name.split(".")[0]
        if top in PROJECT:
            # ``from agents.vehicle import config`` names agents.vehicle (a face) and agents.vehicle.config
            ok = any(name == a or name.startswith(a + ".") or a.startswith(name + ".") for a in allowed)
            assert ok, f"{module} imports {name}; room {room} may import {sorted(allowed)}"
        elif room in THIRD_PARTY and top not in sys.stdlib_module_names and top != "__future__":
            assert top in THIRD_PARTY[room], f"{module} imports {top}; room {room} may import {THIRD_PARTY[room]}"


def import_graph(paths: list[Path], root: Path = ROOT) -> dict[str, set[str]]:
    """Project module -> the project modules it imports anywhere in it (``from pkg import mod`` names ``pkg.mod``
    when that is a module, else ``pkg``'s ``__init__``)."""
    modules = {_module_name(p, root): p for p in paths}
    graph = {}
    for module, path in modules.items():
        targets = set()
        for imported, name, _ in _imports(path, everywhere=True, root=root):
            if name is not None and f"{imported}.{name}" in modules:
                targets.add(f"{imported}.{name}")
            elif imported in modules:
                targets.add(imported)
        graph[module] = targets - {module}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm, iterative): each a set of
    modules that import one another round a loop."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, successors = work[-1]
            step = next(successors, None)
            if step is not None:
                if step not in index:
                    index[step] = low[step] = len(index)
                    stack.append(step)
                    on_stack.add(step)
                    work.append((step, iter(sorted(graph.get(step, ())))))
                elif step in on_stack:
                    low[node] = min(low[node], index[step])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def test_no_two_modules_import_each_other_not_even_inside_functions():
    assert not cycles(import_graph(_modules()))


def test_the_cycle_check_finds_a_loop_of_three_and_nothing_in_a_tree():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b", "c"}, "b": {"c"}, "c": set()}) == []


def test_the_import_graph_reads_imports_inside_functions(tmp_path):
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "one.py").write_text("def f():\n    from pkg.two import g\n", encoding="utf-8")
    (tmp_path / "pkg" / "two.py").write_text("from . import one\n", encoding="utf-8")
    graph = import_graph([tmp_path / "pkg" / "one.py", tmp_path / "pkg" / "two.py"], root=tmp_path)
    assert graph == {"pkg.one": {"pkg.two"}, "pkg.two": {"pkg.one"}} and cycles(graph)


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_module_imports_another_modules_private_name(path):
    """A name with a leading underscore is its module's own: one module importing it from another means the two
    are one idea split by size, or the name is part of the other's interface and should say so."""
    module = _module_name(path)
    private = [f"line {line}: from {imported} import {name}" for imported, name, line in _imports(path, everywhere=True)
               if name is not None and name.startswith("_") and not name.startswith("__") and imported != module
               and imported.split(".")[0] in PROJECT]
    assert not private, f"{module} imports private names: {private}"


def _loaded_after(statement: str, env: dict[str, str] | None = None) -> set[str]:
    code = f"import sys; {statement}; print(' '.join(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120, env=env)
    assert out.returncode == 0, out.stderr
    return set(out.stdout.split())


def test_the_cli_imports_nothing_heavy_to_print_help():
    loaded = _loaded_after("from agents.cli.main import app")
    assert not loaded & {"numpy", "scipy", "numba", "cv2", "zenoh", "pydantic", "evopose", "scenarios", "geometry"}


#: Packages a camera vehicle does not use, each some megabytes resident once imported (docs/design.md §2,
#: "Lazy imports"). scipy among them: the refinement solves its 6 x 6 steps itself (evopose/refine_kernel.py).
NOT_FOR_A_CAMERA_VEHICLE = {"scipy", "matplotlib", "PIL", "rosbags", "mcap", "foxglove", "websockets",
                            "cryptography", "agents.bridges", "agents.tools", "agents.experiments"}


def test_a_camera_vehicle_warmed_up_has_imported_nothing_it_does_not_use():
    """Its warm-up runs every path a frame takes (render, extract, search, tracking, a generation between frames),
    so a heavy import that crept into any of them shows here."""
    loaded = _loaded_after("from agents.vehicle.agent import load_world; "
                           "from agents.vehicle.config import AgentConfig; "
                           "from agents.vehicle.roles import CameraVehicle; "
                           "config = AgentConfig(fleet='lazy', vehicle='H1', scenario='exp2', share='features'); "
                           "CameraVehicle.warm_up(config, load_world(config))")
    assert "evopose.solver" in loaded and "cv2" in loaded  # it did run
    # numba's JIT (kernels not compiled ahead of time) imports scipy itself
    unused = NOT_FOR_A_CAMERA_VEHICLE - ({"scipy"} if "numba" in loaded else set())
    assert not {m for m in loaded if m in unused or m.split(".")[0] in unused or ".".join(m.split(".")[:2]) in unused}


def test_a_camera_vehicle_with_the_compiled_kernels_never_imports_numba():
    """With the kernels compiled ahead of time (make install), an agent's imports and warm-up load neither numba nor
    llvmlite: about 110 MB resident (docs/design.md §2, "Compiled kernels"). Skipped when they are not built, unless
    EVOPOSE_REQUIRE_AOT is set (make test)."""
    from evopose.kernel_backend import load_aot

    if load_aot() is None:
        assert not os.environ.get("EVOPOSE_REQUIRE_AOT"), "the compiled kernels are not built (make install)"
        pytest.skip("the compiled kernels are not built (python -m evopose.kernel_build)")
    env = {k: v for k, v in os.environ.items() if k != "EVOPOSE_KERNELS"}
    loaded = _loaded_after("from agents.vehicle.agent import load_world; "
                           "from agents.vehicle.config import AgentConfig; "
                           "from agents.vehicle.roles import CameraVehicle; "
                           "config = AgentConfig(fleet='aot', vehicle='H1', scenario='exp2', share='features'); "
                           "CameraVehicle.warm_up(config, load_world(config))", env=env)
    assert "evopose.solver" in loaded and "evopose.kernels_aot" in loaded  # it did run, compiled ahead of time
    assert not {m for m in loaded if m.split(".")[0] in ("numba", "llvmlite")}


def test_the_problem_file_contract_does_not_pull_in_the_renderer():
    loaded = _loaded_after("import agents.problem.problem_file, agents.problem.solve")
    assert "scenarios.render" not in loaded and "zenoh" not in loaded


#: evopose/'s modules that touch files, none of them the search's data: whether the compiled kernels are current
#: (their sources, the processor) and building them (docs/design.md §2, "Compiled kernels").
KERNEL_BUILD = {"evopose/kernel_backend.py", "evopose/kernel_build.py"}


def test_the_pose_search_reads_and_writes_no_files():
    """evopose/ is the search (eq. 1-4): images and files are vision's and the agents' (docs/architecture.md)."""
    io = re.compile(r"\bopen\(|\bPath\(|read_text|write_text|read_bytes|np\.load|np\.save|json\.load")
    found = [f"{p.relative_to(ROOT)}:{n}" for p in sorted((ROOT / "evopose").rglob("*.py"))
             if str(p.relative_to(ROOT)) not in KERNEL_BUILD
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


def test_every_error_class_of_the_project_derives_from_the_one_root():
    """The CLI's error edge catches one type (agents/cli/main.py): every package's ``...Error`` is an EvoPoseError."""
    import importlib

    from evopose_errors import EvoPoseError

    errors = [(_module_name(path), node.name) for path in _modules()
              for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
              if isinstance(node, ast.ClassDef) and node.name.endswith("Error")]
    assert len(errors) >= 20  # the check is not vacuous
    outside = [f"{module}.{name}" for module, name in errors
               if not issubclass(getattr(importlib.import_module(module), name), EvoPoseError)]
    assert not outside
