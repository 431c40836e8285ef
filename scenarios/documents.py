"""Strict YAML reading and one-line validation messages for the world's files (models, scenarios).

A duplicate key, an unknown key or a wrong type is an error naming the file and the field path,
for example ``exp2.yaml: vehicles[1].camera.fx: must be > 0, got -800.0``.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, ValidationError

T = TypeVar("T", bound=BaseModel)


class Strict(BaseModel):
    """Base of every schema mapping: unknown keys are errors, numbers finite, values frozen."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True)


class StrictLoader(yaml.SafeLoader):
    """Safe YAML that rejects duplicate keys and reads ``1e-3`` as a number (as YAML 1.2 and JSON do).

    Shared by every YAML file of the project (also the pose-problem file, :mod:`agents.documents`).
    """


def _construct_mapping(loader: StrictLoader, node: yaml.MappingNode, deep: bool = False) -> dict:
    loader.flatten_mapping(node)
    seen = set()
    for key_node, _ in node.value:
        if isinstance(key_node, yaml.ScalarNode):
            key = loader.construct_object(key_node, deep=deep)
            if key in seen:
                raise yaml.constructor.ConstructorError(None, None, f"duplicate key {key!r}", key_node.start_mark)
            seen.add(key)
    return loader.construct_mapping(node, deep=deep)


StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)
StrictLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float", re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"))


def one_line(text: str) -> str:
    return " ".join(str(text).split())


def read_yaml_mapping(path: str | Path, error: type[Exception]) -> dict:
    """The top-level mapping of a YAML (or JSON) file; any problem raises ``error`` with one line naming the file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise error(f"{path}: cannot read: {err.strerror or err}") from None
    except UnicodeDecodeError:
        raise error(f"{path}: cannot read: not UTF-8 text") from None
    try:
        document = yaml.load(text, Loader=StrictLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.MarkedYAMLError as err:
        mark = err.problem_mark or err.context_mark
        where = f"{path}:{mark.line + 1}:{mark.column + 1}" if mark else str(path)
        raise error(f"{where}: invalid YAML: {one_line(err.problem or err.context or 'malformed')}") from None
    except yaml.YAMLError as err:
        raise error(f"{path}: invalid YAML: {one_line(err)}") from None
    if not isinstance(document, dict):
        raise error(f"{path}: top level must be a mapping, got {type(document).__name__}")
    return document


def field_path(loc: tuple[int | str, ...]) -> str:
    """``("vehicles", 0, "camera")`` -> ``vehicles[0].camera``."""
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


def validation_line(err: ValidationError) -> str:
    """``<field path>: <what is wrong>`` for the first error of a validation."""
    first = err.errors(include_url=False)[0]
    loc = tuple(p for p in first["loc"] if not (isinstance(p, str) and ("[" in p or p.startswith("function-"))))
    msg = first["msg"]
    if first["type"] == "extra_forbidden":
        msg = "unknown key"
    elif first["type"] == "missing":
        msg = "required field missing"
    elif msg.startswith("Value error, "):
        msg = msg[len("Value error, "):]
    else:
        msg = msg[:1].lower() + msg[1:]
        if "input" in first and first["type"] not in ("model_type",):
            shown = repr(first["input"])
            if len(shown) <= 40:
                msg += f", got {shown}"
    where = field_path(loc)
    return one_line(f"{where}: {msg}" if where else msg)


def validate(schema: type[T], document: dict, path: str | Path, error: type[Exception]) -> T:
    """``schema`` validated from ``document``; a failure raises ``error("<file>: <field>: <problem>")``."""
    try:
        return schema.model_validate(document)
    except ValidationError as err:
        raise error(f"{path}: {validation_line(err)}") from None
