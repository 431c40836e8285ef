"""Per-topic payload size limits, in bytes, checked before any decoding (docs/design.md §4).

A receiver compares ``len(payload)`` with :data:`SIZE_LIMITS` first and rejects a longer payload
without allocating or parsing it; msgpack is then unpacked with per-object limits no larger
than the payload limit, so a small payload cannot claim a huge string, array or map either.
"""

from __future__ import annotations

from .keys import Topic

KIB = 1024
MIB = 1024 * KIB

#: Exact size of a hint payload: six little-endian float32.
HINT_SIZE = 24
#: Most feature points one FeatureSet may carry.
MAX_FEATURE_POINTS = 16_384
#: Bytes per packed feature point: two little-endian float32 (u, v).
FEATURE_POINT_SIZE = 8
#: Bytes per feature point's colour label (uint8), when the sender sends labels.
FEATURE_LABEL_SIZE = 1
#: Largest raw image: 1920 x 1080 x 3 bytes fits, with room for the header.
MAX_IMAGE_BYTES = 8 * MIB

#: Largest payload accepted per topic, bytes.
SIZE_LIMITS: dict[Topic, int] = {
    Topic.IMAGE: MAX_IMAGE_BYTES,
    Topic.FEATURES: 16 * KIB + MAX_FEATURE_POINTS * (FEATURE_POINT_SIZE + FEATURE_LABEL_SIZE),
    Topic.HINT: HINT_SIZE,
    Topic.ATTITUDE: 1 * KIB,
    Topic.POSE: 4 * KIB,
    Topic.STATS: 16 * KIB,
}

#: Longest msgpack string (names, enum values) inside any message, bytes.
MAX_STR_LEN = 256
#: Longest msgpack array (poses, distortion, name lists) inside any message.
MAX_ARRAY_LEN = 64
#: Largest msgpack map (a message, a camera, a counter table) inside any message.
MAX_MAP_LEN = 64


def size_limit(topic: Topic | str) -> int:
    """Largest payload accepted on ``topic``, bytes."""
    return SIZE_LIMITS[Topic(topic)]
