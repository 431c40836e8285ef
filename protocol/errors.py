"""The protocol's exceptions: one root, :class:`ProtocolError`, with precise subclasses.

Every subclass carries a short machine-readable ``reason`` (used as a counter name by receivers)
and the ``topic`` it concerns, when known. Receivers catch :class:`ProtocolError`, count
``err.reason`` and keep running: a bad message is never fatal (docs/design.md §4).
"""

from __future__ import annotations

from evopose_errors import EvoPoseError


class ProtocolError(EvoPoseError, ValueError):
    """Root of every wire-format error."""

    reason: str = "invalid"

    def __init__(self, message: str, *, topic: str | None = None) -> None:
        super().__init__(f"{topic}: {message}" if topic else message)
        self.topic = topic


class InvalidName(ProtocolError):
    """A fleet or vehicle name, a topic or a key expression that the protocol does not allow."""

    reason = "bad_key"


class OversizedPayload(ProtocolError):
    """A payload longer than its topic's size limit; rejected before any decoding."""

    reason = "oversized"

    def __init__(self, size: int, limit: int, *, topic: str | None = None) -> None:
        super().__init__(f"payload of {size} bytes exceeds the {limit}-byte limit", topic=topic)
        self.size, self.limit = size, limit


class MalformedPayload(ProtocolError):
    """Bytes that are not what the topic's encoding requires (bad msgpack, not a map, wrong hint length)."""

    reason = "malformed"


class SchemaMismatch(ProtocolError):
    """A message whose ``schema`` version this program does not speak."""

    reason = "schema"

    def __init__(self, got: object, expected: int, *, topic: str | None = None) -> None:
        super().__init__(f"schema version {got!r} is not supported (this program speaks {expected})", topic=topic)
        self.got, self.expected = got, expected


class InvalidMessage(ProtocolError):
    """Well-formed msgpack whose fields fail validation (missing, wrong type, out of range, inconsistent)."""

    reason = "invalid"
