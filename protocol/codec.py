"""Encode and decode payloads: the 24-byte hint, msgpack maps for every other topic.

:func:`decode` checks, in this order, and raises the matching :class:`ProtocolError`:
the topic (InvalidName), the payload size against the topic's limit (OversizedPayload, before any
parsing), msgpack with per-object limits and no trailing bytes (MalformedPayload), a map with
a ``version`` equal to :data:`SCHEMA_VERSION` or :data:`PREVIOUS_SCHEMA_VERSION` (SchemaMismatch; a previous
version's document is upgraded, :func:`upgraded`), then the model's fields (InvalidMessage, naming the first bad
field).
"""

from __future__ import annotations

from typing import Any

import msgpack
from pydantic import ValidationError

from .errors import InvalidMessage, MalformedPayload, OversizedPayload, SchemaMismatch
from .hint import decode_hint, encode_hint
from .keys import Topic, TopicKey, check_topic, parse_key
from .limits import MAX_ARRAY_LEN, MAX_MAP_LEN, MAX_STR_LEN, SIZE_LIMITS
from .messages import MESSAGE_TYPES, PREVIOUS_SCHEMA_VERSION, SCHEMA_VERSION, Hint, Message, Payload


def encode(message: Payload) -> bytes:
    """The payload of ``message`` for its topic (``message.TOPIC``).

    Raises
    ------
    OversizedPayload
        The encoding exceeds the topic's size limit (the receiver would reject it).
    """
    topic = message.TOPIC
    if isinstance(message, Hint):
        return encode_hint(message.pose)
    payload = msgpack.packb(message.model_dump(mode="python"), use_bin_type=True)
    check_size(topic, len(payload))
    return payload


def check_size(topic: Topic | str, size: int) -> None:
    """Raise :class:`OversizedPayload` if ``size`` bytes exceed ``topic``'s limit."""
    limit = SIZE_LIMITS[Topic(topic)]
    if size > limit:
        raise OversizedPayload(size, limit, topic=str(topic))


def unpack(topic: Topic, payload: bytes) -> Any:
    """msgpack-unpack ``payload`` with per-object limits; raise :class:`MalformedPayload` on any defect."""
    try:
        return msgpack.unpackb(payload, raw=False, use_list=False, strict_map_key=True,
                               max_bin_len=SIZE_LIMITS[topic], max_str_len=MAX_STR_LEN,
                               max_array_len=MAX_ARRAY_LEN, max_map_len=MAX_MAP_LEN, max_ext_len=0)
    except msgpack.ExtraData:
        raise MalformedPayload("trailing bytes after the msgpack map", topic=topic) from None
    except (ValueError, TypeError, msgpack.UnpackException) as err:  # includes OutOfData, FormatError, StackError
        detail = str(err) or type(err).__name__
        raise MalformedPayload(f"not valid msgpack ({detail})", topic=topic) from None


_MSGPACK_TYPE = {tuple: "an array", str: "a string", bytes: "bin", int: "an integer", float: "a float",
                 bool: "a boolean", type(None): "nil"}


def _first_error(err: ValidationError) -> str:
    first = err.errors()[0]
    where = ".".join(str(part) for part in first["loc"]) or "message"
    more = f" (and {err.error_count() - 1} more)" if err.error_count() > 1 else ""
    return f"field {where!r}: {first['msg']}{more}"


def decode(topic: Topic | str, payload: bytes | bytearray | memoryview) -> Payload:
    """The message carried by ``payload`` on ``topic``; see the module docstring for the checks."""
    topic = check_topic(topic)
    check_size(topic, len(payload))
    payload = bytes(payload)
    cls = MESSAGE_TYPES[topic]
    if cls is Hint:
        return Hint(pose=tuple(decode_hint(payload)))
    document = unpack(topic, payload)
    if not isinstance(document, dict):
        raise MalformedPayload(f"expected a msgpack map, got {_MSGPACK_TYPE.get(type(document), 'a scalar')}",
                               topic=topic)
    if "version" not in document:
        raise InvalidMessage("missing field 'version'", topic=topic)
    if type(document["version"]) is not int or document["version"] not in (SCHEMA_VERSION, PREVIOUS_SCHEMA_VERSION):
        raise SchemaMismatch(document["version"], SCHEMA_VERSION, topic=topic)
    document = upgraded(topic, document)
    try:
        return cls.model_validate(document, strict=True)
    except ValidationError as err:
        raise InvalidMessage(_first_error(err), topic=topic) from None


#: Fields renamed from :data:`PREVIOUS_SCHEMA_VERSION` to :data:`SCHEMA_VERSION`, per topic: old -> new.
RENAMED_SINCE_PREVIOUS: dict[Topic, dict[str, str]] = {Topic.POSE: {"confident": "good"}}


def upgraded(topic: Topic, document: dict) -> dict:
    """A decoded map of :data:`PREVIOUS_SCHEMA_VERSION` as :data:`SCHEMA_VERSION` says it (its fields renamed);
    a current one as it is. Version 2 -> 3: ``pose``'s ``confident``, which carried the sender's good verdict,
    became ``good``."""
    if document.get("version") != PREVIOUS_SCHEMA_VERSION:
        return document
    renamed = RENAMED_SINCE_PREVIOUS.get(topic, {})
    # a field the previous version did not have (one named like a new field) was ignored then and is ignored now
    out = {renamed.get(key, key): value for key, value in document.items() if key not in renamed.values()}
    out["version"] = SCHEMA_VERSION
    return out


def decode_sample(key: str, payload: bytes | bytearray | memoryview) -> tuple[TopicKey, Payload]:
    """Parse a data ``key`` and decode its ``payload``; a message's ``sender`` must be the key's vehicle.

    Raises
    ------
    InvalidName
        ``key`` is not ``evopose/<fleet>/<vehicle>/<topic>``.
    ProtocolError
        Any :func:`decode` error; InvalidMessage if ``sender`` differs from the key.
    """
    topic_key = parse_key(key)
    message = decode(topic_key.topic, payload)
    if isinstance(message, Message) and message.sender != topic_key.vehicle:
        raise InvalidMessage(f"sender {message.sender!r} differs from the key's vehicle {topic_key.vehicle!r}",
                             topic=topic_key.topic)
    return topic_key, message
