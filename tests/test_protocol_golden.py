"""Golden files pin the wire format: encoding the fixed messages must give these bytes exactly.

If this fails, the wire format changed. Either undo the change, or bump SCHEMA_VERSION, update
docs/protocol.md and rewrite the files with ``python -m tests.golden.make``.
"""

from __future__ import annotations

from pathlib import Path

import pytest

import protocol as p
from tests.golden.make import golden_messages, golden_path

DOC = Path(__file__).resolve().parents[1] / "docs" / "protocol.md"
GOLDEN = golden_messages()


@pytest.mark.parametrize("name", sorted(GOLDEN))
def test_encoding_matches_the_golden_file(name):
    assert p.encode(GOLDEN[name]) == golden_path(name).read_bytes(), f"wire format of {name} changed"


@pytest.mark.parametrize("name", sorted(GOLDEN))
def test_golden_file_decodes_to_the_message(name):
    assert p.decode(GOLDEN[name].TOPIC, golden_path(name).read_bytes()) == GOLDEN[name]


def _hex_lines(data: bytes) -> list[str]:
    return [" ".join(f"{b:02x}" for b in data[i:i + 16]) for i in range(0, len(data), 16)]


@pytest.mark.parametrize("name", ["hint", "features"])
def test_the_worked_examples_in_the_docs_are_the_golden_bytes(name):
    text = DOC.read_text(encoding="utf-8")
    for line in _hex_lines(golden_path(name).read_bytes()):
        assert line in text, f"docs/protocol.md worked example of {name} is out of date: missing {line!r}"
