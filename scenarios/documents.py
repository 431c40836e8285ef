"""The project's one document stack: every YAML or JSON file it reads goes through here.

Scenarios, target models, fleet scenarios, pose-problem files and camera files are all read by
:func:`read_mapping` and validated by :func:`validate`. Every failure is one line naming the file
and, for a validation failure, the field path, for example
``exp2.yaml: vehicles[1].camera.fx: must be > 0, got -800.0``.

The files are untrusted input, so reading is bounded before anything is parsed:

- only regular files (no FIFO, no ``/dev/zero``), at most :data:`MAX_FILE_BYTES`;
- YAML aliases may expand to at most :data:`MAX_EXPANDED_NODES` nodes (a 2 KB alias bomb expands to
  billions when walked);
- nesting deeper than :data:`MAX_DEPTH` is refused before construction (no RecursionError);
- duplicate keys are errors, and ``1e-3`` is a number (as in YAML 1.2 and JSON).
"""

from __future__ import annotations

import json
import os
import re
import stat
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, ValidationError, model_validator

from geometry import PARAM_NAMES, pose_from_matrix
from evopose_errors import EvoPoseError

T = TypeVar("T", bound=BaseModel)

#: Largest file read, bytes (a problem file at its limit of 16384 image points is ~0.8 MB of YAML).
MAX_FILE_BYTES = 8 * 1024 * 1024
#: Deepest nesting of mappings and lists.
MAX_DEPTH = 32
#: Most nodes a YAML document may have once its aliases are expanded.
MAX_EXPANDED_NODES = 2_000_000
#: Longest excerpt of an offending value quoted in a message.
MAX_QUOTE = 40


class DocumentError(EvoPoseError, ValueError):
    """A document that cannot be read or does not have the expected shape; the message is one line."""


class UnknownKey(ValueError):
    """Raised by a validator for a key the schema does not know; :func:`validation_message` names it as the field."""

    def __init__(self, key: Any, expected: list[str]) -> None:
        super().__init__(f"unknown key (expected {', '.join(expected)})")
        self.key = key


class Strict(BaseModel):
    """Base of every schema mapping: unknown keys are errors, numbers finite, values frozen."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True)


class Spec(BaseModel):
    """Base of a file's mappings where types are not coerced (the pose-problem file, camera calibration files):
    strict types, finite numbers, and an unknown key named with the known ones."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, frozen=True)

    @model_validator(mode="before")
    @classmethod
    def _known_keys(cls, data: Any) -> Any:
        if isinstance(data, dict):
            unknown = [key for key in data if key not in cls.model_fields]
            if unknown:
                raise UnknownKey(unknown[0], list(cls.model_fields))
        return data


class FullPoseSpec(Spec):
    """A pose ``(x, y, z, roll, pitch, yaw)``, metres and radians, every value given: the problem file's camera poses
    and hints, a ``--camera-pose`` file, a rendered dataset's camera and target poses."""

    x: float
    y: float
    z: float
    roll: float
    pitch: float
    yaw: float

    def vector(self) -> np.ndarray:
        """The pose as an array, shape (6,)."""
        return np.array([getattr(self, n) for n in PARAM_NAMES], float)

    @classmethod
    def of(cls, pose: np.ndarray) -> "FullPoseSpec":
        """The spec of a pose (6,) or a transform (4, 4)."""
        pose = np.asarray(pose, float)
        if pose.shape == (4, 4):
            pose = pose_from_matrix(pose)
        return cls(**{n: float(v) for n, v in zip(PARAM_NAMES, pose.reshape(6))})


class StrictLoader(yaml.SafeLoader):
    """Safe YAML with bounded nesting and a bounded alias expansion, rejecting duplicate keys."""

    def compose_node(self, parent, index):  # noqa: ANN001 - PyYAML's signature
        depth = getattr(self, "_depth", 0)
        if depth >= MAX_DEPTH:
            mark = self.peek_event().start_mark
            raise yaml.composer.ComposerError(None, None, f"nesting deeper than {MAX_DEPTH} levels", mark)
        self._depth = depth + 1
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth = depth

    def get_single_node(self):  # noqa: ANN201 - PyYAML's signature
        node = super().get_single_node()
        if node is not None:
            _check_expansion(node)
        return node


def _check_expansion(root: yaml.Node) -> None:
    """Refuse a node graph whose aliases expand to more than :data:`MAX_EXPANDED_NODES` nodes.

    Anchors and aliases are allowed (``yaml.dump`` writes them for shared objects), but an alias bomb
    (each level referring to the one below ten times) is refused here, before it is walked.
    """
    size: dict[int, int] = {}
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, children_done = stack.pop()
        if id(node) in size:
            continue
        children = [] if isinstance(node, yaml.ScalarNode) else (
            [c for pair in node.value for c in pair] if isinstance(node, yaml.MappingNode) else list(node.value))
        if children_done:
            size[id(node)] = 1 + sum(size[id(c)] for c in children)
            if size[id(node)] > MAX_EXPANDED_NODES:
                raise yaml.composer.ComposerError(None, None, "aliases expand to more than "
                                                  f"{MAX_EXPANDED_NODES} nodes", node.start_mark)
        else:
            stack.append((node, True))
            stack.extend((c, False) for c in children if id(c) not in size)


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


def one_line(text: Any) -> str:
    """``text`` with every run of white space (newlines too) made one space."""
    return " ".join(str(text).split())


def read_bytes(path: str | Path, error: type[Exception] = DocumentError, max_bytes: int = MAX_FILE_BYTES) -> bytes:
    """The bytes of a regular file of at most ``max_bytes``; anything else raises ``error`` with one line.

    The size is checked on the open descriptor (no race with a file that grows), and at most
    ``max_bytes + 1`` bytes are ever read, so ``/dev/zero`` or a FIFO cannot take memory or hang.
    """
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as err:
        raise error(f"{path}: cannot read: {err.strerror or err}") from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            kind = "a directory" if stat.S_ISDIR(info.st_mode) else "not a regular file"
            raise error(f"{path}: cannot read: {kind}")
        if info.st_size > max_bytes:
            raise error(f"{path}: file is {info.st_size} bytes, more than the limit of {max_bytes}")
        with os.fdopen(fd, "rb", closefd=False) as f:
            data = f.read(max_bytes + 1)
    except OSError as err:
        raise error(f"{path}: cannot read: {err.strerror or err}") from None
    finally:
        os.close(fd)
    if len(data) > max_bytes:
        raise error(f"{path}: file is more than the limit of {max_bytes} bytes")
    return data


def json_object(pairs: list[tuple[str, Any]]) -> dict:
    out: dict = {}
    for key, value in pairs:
        if key in out:
            raise ValueError(f"duplicate key {key!r}")
        out[key] = value
    return out


def json_depth_ok(text: str) -> bool:
    """True when the brackets of a JSON text nest at most :data:`MAX_DEPTH` deep (strings skipped)."""
    depth, in_string, escaped = 0, False, False
    for ch in text:
        if in_string:
            escaped, in_string = (False, True) if escaped else (ch == "\\", ch != '"')
        elif ch == '"':
            in_string = True
        elif ch in "[{":
            depth += 1
            if depth > MAX_DEPTH:
                return False
        elif ch in "]}":
            depth -= 1
    return True


def _parse(path: Path, text: str, error: type[Exception]) -> Any:
    """The document in ``text``: JSON for a ``.json`` file, YAML otherwise."""
    if path.suffix.lower() == ".json":
        if not json_depth_ok(text):
            raise error(f"{path}: invalid JSON: nesting deeper than {MAX_DEPTH} levels")
        try:
            return json.loads(text, object_pairs_hook=json_object, parse_constant=no_constant)
        except json.JSONDecodeError as err:
            raise error(f"{path}:{err.lineno}:{err.colno}: invalid JSON: {err.msg}") from None
        except (ValueError, RecursionError) as err:
            raise error(f"{path}: invalid JSON: {one_line(err)}") from None
    try:
        return yaml.load(text, Loader=StrictLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.MarkedYAMLError as err:
        mark = err.problem_mark or err.context_mark
        where = f"{path}:{mark.line + 1}:{mark.column + 1}" if mark else str(path)
        raise error(f"{where}: invalid YAML: {one_line(err.problem or err.context or 'malformed')}") from None
    except (yaml.YAMLError, RecursionError) as err:
        raise error(f"{path}: invalid YAML: {one_line(err)}") from None


def no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a number JSON allows")


def read_mapping(path: str | Path, error: type[Exception] = DocumentError) -> dict:
    """The top-level mapping of a YAML or JSON file (JSON when the name ends in ``.json``).

    Raises
    ------
    error
        The file cannot be read, is too large or not a regular file, is not valid YAML/JSON, nests too
        deeply, uses YAML aliases, or its top level is not a mapping. The message is one line.
    """
    path = Path(path)
    data = read_bytes(path, error)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise error(f"{path}: cannot read: not UTF-8 text") from None
    document = _parse(path, text, error)
    if not isinstance(document, dict):
        got = "an empty document" if document is None else describe(document)
        raise error(f"{path}: top level must be a mapping, got {got}")
    return document


def describe(value: Any) -> str:
    """A short human description of an offending value: ``a list``, ``'abc'``, ``nan``.

    Containers are named, never printed: a value from an untrusted file may be huge.
    """
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, (list, tuple)):
        return "a list"
    if isinstance(value, (str, bytes)) and len(value) > MAX_QUOTE:
        value = value[:MAX_QUOTE]
    text = repr(value)
    return text if len(text) <= MAX_QUOTE else text[: MAX_QUOTE - 3] + "..."


def field_path(loc: tuple[int | str, ...]) -> str:
    """``("views", 0, "points", 3)`` -> ``views[0].points[3]``."""
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


#: Messages for pydantic error types; ``{input}`` is the offending value, other fields come from the error context.
_MESSAGES = {
    "missing": "required field missing",
    "extra_forbidden": "unknown key",
    "float_type": "expected a number, got {input}",
    "float_parsing": "expected a number, got {input}",
    "finite_number": "expected a finite number, got {input}",
    "int_type": "expected an integer, got {input}",
    "int_parsing": "expected an integer, got {input}",
    "int_from_float": "expected an integer, got {input}",
    "list_type": "expected a list, got {input}",
    "model_type": "expected a mapping, got {input}",
    "dict_type": "expected a mapping, got {input}",
    "too_short": "must not be empty",
    "too_long": "at most {max_length} entries, got {actual_length}",
    "greater_than": "must be > {gt}, got {input}",
    "greater_than_equal": "must be >= {ge}, got {input}",
    "less_than": "must be < {lt}, got {input}",
    "less_than_equal": "must be <= {le}, got {input}",
    "literal_error": "expected {expected}, got {input}",
    "enum": "expected {expected}, got {input}",
    "value_error": "{error}",
}


def validation_message(error: ValidationError) -> str:
    """One line for the first error of a pydantic validation: ``<field path>: <what is wrong>``."""
    first = error.errors(include_url=False)[0]
    loc = tuple(p for p in first["loc"] if not (isinstance(p, str) and ("[" in p or p.startswith("function-"))))
    ctx = first.get("ctx", {})
    cause = ctx.get("error")
    if isinstance(cause, UnknownKey):
        loc = (*loc, str(cause.key))
    template = _MESSAGES.get(first["type"])
    try:
        text = template.format(input=describe(first.get("input")), **ctx) if template else None
    except (KeyError, IndexError):
        text = None
    if text is None:
        text = first["msg"][:1].lower() + first["msg"][1:]
        if text.startswith("value error, "):
            text = text[len("value error, "):]
        elif "input" in first and first["type"] != "model_type":
            text += f", got {describe(first['input'])}"
    where = field_path(loc)
    return one_line(f"{where}: {text}" if where else text)


def validate(schema: type[T], document: dict, path: str | Path, error: type[Exception] = DocumentError) -> T:
    """``schema`` validated from ``document``; a failure raises ``error("<file>: <field>: <problem>")``."""
    try:
        return schema.model_validate(document)
    except ValidationError as err:
        raise error(f"{path}: {validation_message(err)}") from None
    except RecursionError:
        raise error(f"{path}: nesting too deep") from None

