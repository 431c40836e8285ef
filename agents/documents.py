"""Reading YAML/JSON documents strictly, and turning validation failures into one precise line.

Every failure is a :class:`DocumentError` whose message is a single line: a file-level
problem names the file (``problem.yaml:3:7: invalid YAML: ...``), a validation failure
names the field path (``views[0].points[3]: expected 2 numbers [u, v], got 3``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from scenarios.documents import StrictLoader

#: Longest excerpt of an offending value quoted in a message.
MAX_QUOTE = 40


class DocumentError(ValueError):
    """A document that cannot be read or does not have the expected shape; the message is one line."""


class UnknownKey(ValueError):
    """Raised by a validator for a key the schema does not know; :func:`validation_message` names it as the field."""

    def __init__(self, key: Any, expected: list[str]) -> None:
        super().__init__(f"unknown key (expected {', '.join(expected)})")
        self.key = key


def _json_object(pairs: list[tuple[str, Any]]) -> dict:
    out: dict = {}
    for key, value in pairs:
        if key in out:
            raise ValueError(f"duplicate key {key!r}")
        out[key] = value
    return out


def _parse(path: Path, text: str) -> Any:
    """The document in ``text``: JSON for a ``.json`` file, YAML otherwise."""
    if path.suffix.lower() == ".json":
        try:
            return json.loads(text, object_pairs_hook=_json_object)
        except json.JSONDecodeError as err:
            raise DocumentError(f"{path}:{err.lineno}:{err.colno}: invalid JSON: {err.msg}") from None
        except ValueError as err:
            raise DocumentError(f"{path}: invalid JSON: {err}") from None
    try:
        return yaml.load(text, Loader=StrictLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.MarkedYAMLError as err:
        mark = err.problem_mark or err.context_mark
        where = f"{path}:{mark.line + 1}:{mark.column + 1}" if mark else str(path)
        problem = err.problem or err.context or "malformed document"
        raise DocumentError(f"{where}: invalid YAML: {problem}") from None
    except yaml.YAMLError as err:
        raise DocumentError(f"{path}: invalid YAML: {_one_line(str(err))}") from None


def read_mapping(path: str | Path) -> dict:
    """The top-level mapping of a YAML or JSON file.

    Raises
    ------
    DocumentError
        The file cannot be read, is not valid YAML/JSON, or its top level is not a mapping.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise DocumentError(f"{path}: cannot read: {err.strerror or err}") from None
    except UnicodeDecodeError:
        raise DocumentError(f"{path}: cannot read: not UTF-8 text") from None
    document = _parse(path, text)
    if not isinstance(document, dict):
        got = "an empty document" if document is None else describe(document)
        raise DocumentError(f"{path}: top level must be a mapping, got {got}")
    return document


def describe(value: Any) -> str:
    """A short human description of an offending value: ``a list``, ``'abc'``, ``nan``."""
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, (list, tuple)):
        return "a list"
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
    "float_type": "expected a number, got {input}",
    "finite_number": "expected a finite number, got {input}",
    "int_type": "expected an integer, got {input}",
    "list_type": "expected a list, got {input}",
    "model_type": "expected a mapping, got {input}",
    "too_short": "must not be empty",
    "greater_than": "must be > {gt}, got {input}",
    "greater_than_equal": "must be >= {ge}, got {input}",
    "literal_error": "expected {expected}, got {input}",
    "value_error": "{error}",
}


def validation_message(error: ValidationError) -> str:
    """One line for the first error of a pydantic validation: ``<field path>: <what is wrong>``."""
    first = error.errors(include_url=False)[0]
    loc = first["loc"]
    cause = first.get("ctx", {}).get("error")
    if isinstance(cause, UnknownKey):
        loc = (*loc, str(cause.key))
    template = _MESSAGES.get(first["type"])
    if template is None:
        text = first["msg"][:1].lower() + first["msg"][1:]
    else:
        text = template.format(input=describe(first.get("input")), **first.get("ctx", {}))
    where = field_path(loc)
    return _one_line(f"{where}: {text}" if where else text)


def _one_line(text: str) -> str:
    return " ".join(text.split())
