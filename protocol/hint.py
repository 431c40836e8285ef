"""The 24-byte pose hint: six little-endian IEEE-754 float32 ``(x, y, z, roll, pitch, yaw)``.

No header, no version: who sent it is in the key (``evopose/<fleet>/<vehicle>/hint``) and it is
``world_from_target`` in metres and radians (docs/design.md §2). Byte ``4*i`` starts value ``i``.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .errors import InvalidMessage, MalformedPayload, OversizedPayload
from .keys import Topic
from .limits import HINT_SIZE

HINT_FORMAT = "<6f"
_HINT = struct.Struct(HINT_FORMAT)
assert _HINT.size == HINT_SIZE


def encode_hint(pose: np.ndarray | tuple[float, ...]) -> bytes:
    """Pack a pose, shape ``(6,)``, into exactly 24 bytes; raise ValueError if it is not 6 finite float32 values."""
    values = np.asarray(pose, dtype=float).reshape(-1)
    if values.shape != (6,):
        raise InvalidMessage(f"a hint is 6 values (x, y, z, roll, pitch, yaw), got shape {np.shape(pose)}",
                             topic=Topic.HINT)
    with np.errstate(over="ignore", invalid="ignore"):
        packed = values.astype("<f4")
    if not np.all(np.isfinite(packed)):
        raise InvalidMessage(f"hint values must be finite float32, got {values.tolist()}", topic=Topic.HINT)
    return packed.tobytes()


def decode_hint(payload: bytes) -> np.ndarray:
    """Unpack 24 bytes into a pose, float64 of shape ``(6,)``; raise a ProtocolError otherwise."""
    if len(payload) > HINT_SIZE:
        raise OversizedPayload(len(payload), HINT_SIZE, topic=Topic.HINT)
    if len(payload) != HINT_SIZE:
        raise MalformedPayload(f"a hint is exactly {HINT_SIZE} bytes, got {len(payload)}", topic=Topic.HINT)
    values = np.array(_HINT.unpack(payload), dtype=float)
    if not np.all(np.isfinite(values)):
        raise InvalidMessage(f"hint values must be finite, got {values.tolist()}", topic=Topic.HINT)
    return values


@dataclass(frozen=True)
class Hint:
    """A hint to send: ``world_from_target`` (6,) that goes out as the 24 bytes of :func:`encode_hint`."""

    pose: tuple[float, float, float, float, float, float]
    TOPIC: ClassVar[Topic] = Topic.HINT

    def payload(self) -> bytes:
        return encode_hint(self.pose)

