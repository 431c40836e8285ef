"""Fuzzing every decoder and loader with hypothesis (issue 12): whatever the bytes, a decoder either returns a valid
message or raises its own one-line error class, never anything else, and never hangs or grows without bound.

Bounded for `make test` (FUZZ_EXAMPLES examples per target, ~30 s in all); `make fuzz` sets EVOPOSE_FUZZ_EXAMPLES
higher. Payloads mix pure noise, mutations of valid (golden) messages, and well-formed msgpack of random
structure, so that the fuzzer reaches past the first size and type checks.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import msgpack
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from protocol import ProtocolError, Topic, decode, decode_hint, decode_sample
from scenarios.documents import DocumentError, read_mapping, validate
from scenarios.errors import WorldError

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = ROOT / "tests" / "golden"
FUZZ_EXAMPLES = int(os.environ.get("EVOPOSE_FUZZ_EXAMPLES", "150"))
FUZZ = settings(max_examples=FUZZ_EXAMPLES, deadline=None, derandomize=os.environ.get("EVOPOSE_FUZZ_RANDOM") is None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])

GOLDEN_OF = {Topic.FEATURES: "features", Topic.IMAGE: "image_raw", Topic.ATTITUDE: "attitude", Topic.POSE: "pose",
             Topic.STATS: "stats", Topic.HINT: "hint"}

#: msgpack-able values of random structure (the fuzzer's idea of a message)
values = st.recursive(
    st.none() | st.booleans() | st.integers(-2**70, 2**70).filter(lambda i: -2**63 <= i < 2**64)
    | st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=40) | st.binary(max_size=64),
    lambda children: st.lists(children, max_size=8) | st.dictionaries(st.text(max_size=12), children, max_size=8),
    max_leaves=40)


def _mutations(base: bytes) -> st.SearchStrategy[bytes]:
    """``base`` with bytes flipped, cut, or extended."""
    @st.composite
    def mutate(draw) -> bytes:
        data = bytearray(base)
        for _ in range(draw(st.integers(1, 8))):
            if not data:
                break
            i = draw(st.integers(0, len(data) - 1))
            data[i] = draw(st.integers(0, 255))
        cut = draw(st.integers(0, len(data)))
        return bytes(data[:cut]) + draw(st.binary(max_size=16))
    return mutate()


def _payloads(topic: Topic) -> st.SearchStrategy[bytes]:
    base = (GOLDEN / f"{GOLDEN_OF[topic]}.bin").read_bytes()
    golden = msgpack.unpackb(base, raw=False) if topic != Topic.HINT else None
    structured = values.map(lambda v: msgpack.packb(v, use_bin_type=True))
    if isinstance(golden, dict):  # the golden message with one field replaced by anything
        structured = structured | st.builds(
            lambda key, value: msgpack.packb({**golden, key: value}, use_bin_type=True),
            st.sampled_from(sorted(golden)), values)
    return st.binary(max_size=512) | _mutations(base) | structured


@pytest.mark.parametrize("topic", list(GOLDEN_OF), ids=lambda t: t.value)
def test_every_decoder_returns_a_message_or_its_own_error(topic):
    @FUZZ
    @given(_payloads(topic))
    def check(payload: bytes) -> None:
        try:
            message = decode_hint(payload) if topic == Topic.HINT else decode(topic, payload)
        except ProtocolError as err:
            assert "\n" not in str(err)
            return
        assert message is not None

    check()


@FUZZ
@given(key=st.text(max_size=60) | st.sampled_from(["evopose/f/v/pose", "evopose/f/v/hint", "evopose/f/@alive/v",
                                                  "evopose/f/v/../pose", "evopose//v/features"]),
       payload=st.binary(max_size=64))
def test_keys_and_payloads_together(key, payload):
    try:
        decode_sample(key, payload)
    except ProtocolError:
        pass


def _document_files() -> list[Path]:
    return [ROOT / "scenarios" / "exp2.yaml", ROOT / "scenarios" / "models" / "pioneer.yaml",
            ROOT / "scenarios" / "fleet" / "exp2a-features.yaml", ROOT / "examples" / "airship_imu.yaml"]


def _loader(path: Path):
    """The project's loader of a file like ``path`` and the error classes it may raise."""
    from agents.problem.problem_file import ProblemFileError, load_problem
    from scenarios.fleet import load_fleet_scenario
    from scenarios.target import load_model
    from scenarios.world import load_scenario

    if path.parent.name == "examples":
        return load_problem, (ProblemFileError,)
    if path.parent.name == "models":
        return load_model, (WorldError,)
    if path.parent.name == "fleet":
        return load_fleet_scenario, (WorldError,)
    return load_scenario, (WorldError,)


@pytest.mark.parametrize("original", _document_files(), ids=lambda p: p.name)
def test_every_loader_fails_with_one_line_on_mutated_files(original, tmp_path_factory):
    load, errors = _loader(original)
    text = original.read_text()
    directory = tmp_path_factory.mktemp("fuzz")
    if original.parent.name == "fleet":  # keep the world reachable from the copy
        text = text.replace("world: exp2", f"world: {ROOT / 'scenarios' / 'exp2.yaml'}")
    if original.parent.name == "scenarios":
        text = text.replace("models/", f"{ROOT / 'scenarios' / 'models'}/")

    @FUZZ
    @given(_mutations(text.encode()) | values.map(lambda v: json.dumps(v, default=str).encode()))
    def check(data: bytes) -> None:
        path = directory / f"mutated{original.suffix}"
        path.write_bytes(data)
        try:
            load(path)
        except errors as err:
            assert "\n" not in str(err), str(err)

    check()


@FUZZ
@given(values)
def test_validation_messages_are_one_line_whatever_the_document(document):
    from agents.problem.problem_file import ProblemSpec

    if not isinstance(document, dict):
        document = {"model": document}
    try:
        validate(ProblemSpec, document, "fuzz.json")
    except DocumentError as err:
        assert "\n" not in str(err)


def test_a_valid_file_still_loads():
    for path in _document_files():
        load, _ = _loader(path)
        assert load(path) is not None
    assert isinstance(read_mapping(_document_files()[0]), dict)
