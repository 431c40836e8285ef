"""World files that extend another: ``extends: exp2`` takes that world and applies this file's keys on top.

:func:`read_world_document` is what :func:`scenarios.world.load_scenario` and the dataset writer read a world file
with; the merge rules are :func:`_merge`'s.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from .documents import read_mapping
from .errors import ScenarioError

#: Directory of the shipped worlds.
SCENARIOS_DIR = Path(__file__).resolve().parent

#: Longest chain of ``extends`` (a world extending a world extending ...).
MAX_EXTENDS = 4


def _merge(base: Any, override: Any) -> Any:
    """``override`` on top of ``base``: mappings merge key by key, lists of named mappings merge by ``name``
    (an override item changes the base item of its name, new names are appended), anything else is replaced."""
    if isinstance(base, dict) and isinstance(override, dict):
        out = dict(base)
        for key, value in override.items():
            out[key] = _merge(base[key], value) if key in base else value
        return out
    named = (isinstance(base, list) and isinstance(override, list)
             and all(isinstance(i, dict) and "name" in i for i in [*base, *override]))
    if named:
        out = [dict(i) for i in base]
        index = {item["name"]: k for k, item in enumerate(out)}
        for item in override:
            if item["name"] in index:
                out[index[item["name"]]] = _merge(out[index[item["name"]]], item)
            else:
                out.append(item)
        return out
    return override


def read_world_document(path: Path, depth: int = 0) -> dict:
    """A world file's mapping with its ``extends`` resolved: ``extends: exp2`` (a shipped name, or a file relative
    to this one) takes that world and applies this file's keys on top (see :func:`_merge`)."""
    document = read_mapping(path, ScenarioError)
    parent = document.pop("extends", None)
    if parent is None:
        return document
    if not isinstance(parent, str):
        raise ScenarioError(f"{path}: extends: expected a world name or file, got {type(parent).__name__}")
    if depth >= MAX_EXTENDS:
        raise ScenarioError(f"{path}: extends: more than {MAX_EXTENDS} levels (a cycle?)")
    parent_path = Path(parent)
    parent_path = (SCENARIOS_DIR / f"{parent}.yaml" if not parent_path.suffix
                   else parent_path if parent_path.is_absolute() else path.parent / parent_path)
    if not parent_path.is_file():
        raise ScenarioError(f"{path}: extends: no world {parent!r}")
    base = read_world_document(parent_path, depth + 1)
    model = base.get("target", {}).get("model") if isinstance(base.get("target"), dict) else None
    if isinstance(model, str) and Path(model).suffix:  # a model file of the base: relative to the base's folder
        base["target"]["model"] = str((parent_path.parent / model).resolve())
    return _merge(base, document)
