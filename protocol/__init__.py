"""EvoPose Fleet wire format: keys, messages, the msgpack codec and the 24-byte hint (docs/protocol.md).

Only pydantic, msgpack and numpy are used here, so any program can import it without Zenoh.
"""

from .codec import check_size, decode, decode_sample, encode
from .errors import InvalidMessage, InvalidName, MalformedPayload, OversizedPayload, ProtocolError, SchemaMismatch
from .hint import decode_hint, encode_hint
from .keys import (ALIVE, ROOT, Topic, TopicKey, alive_key, alive_selector, check_name, check_topic, fleet_selector,
                   parse_alive_key, parse_key, topic_key, topic_selector)
from .limits import HINT_SIZE, MAX_FEATURE_POINTS, SIZE_LIMITS, size_limit
from .messages import (MESSAGE_TYPES, PREVIOUS_SCHEMA_VERSION, SCHEMA_VERSION, Attitude, CameraInfo, FeatureSet, Hint,
                       ImageFrame, Message, Payload, PoseEstimate, Stats, pack_points, quaternion_from_euler,
                       unpack_points)
from .qos import QOS, TopicQoS

__all__ = [
    "ALIVE", "HINT_SIZE", "MAX_FEATURE_POINTS", "MESSAGE_TYPES", "PREVIOUS_SCHEMA_VERSION", "QOS", "ROOT",
    "SCHEMA_VERSION", "SIZE_LIMITS",
    "Attitude", "CameraInfo", "FeatureSet", "Hint", "ImageFrame", "InvalidMessage", "InvalidName",
    "MalformedPayload", "Message", "OversizedPayload", "Payload", "PoseEstimate", "ProtocolError",
    "SchemaMismatch", "Stats", "Topic", "TopicKey", "TopicQoS",
    "alive_key", "alive_selector", "check_name", "check_size", "check_topic", "decode", "decode_hint", "decode_sample", "encode",
    "encode_hint", "fleet_selector", "pack_points", "parse_alive_key", "parse_key", "quaternion_from_euler",
    "size_limit", "topic_key", "topic_selector", "unpack_points",
]
