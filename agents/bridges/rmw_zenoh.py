"""The rmw_zenoh wire format, as plain functions: data keys, liveliness tokens, QoS strings, attachments, GIDs.

Verified against ros2/rmw_zenoh (``docs/design.md``; ``rmw_zenoh_cpp/src/detail/liveliness_utils.cpp``,
``attachment_helpers.cpp``, ``qos.cpp``, ``rmw_publisher_data.cpp``) and eclipse-zenoh/zenoh-cpp
(``include/zenoh/api/ext/serialization.hxx``); docs/ros2.md says which releases. No live ROS 2 install was
available to test against.

- Data key: ``<domain>/<topic without its leading and trailing />/<pkg>::msg::dds_::<Type>_/<RIHS01_hash>``.
- Liveliness token of a node: ``@ros2_lv/<domain>/<zid>/<nid>/<nid>/NN/<enclave>/<namespace>/<node>``; of a
  publisher: ``@ros2_lv/<domain>/<zid>/<nid>/<eid>/MP/<enclave>/<namespace>/<node>/<topic>/<dds type>/<hash>/<qos>``,
  each name mangled (``/`` -> ``%``; the default enclave and namespace ``/`` become ``%``).
- QoS string: ``<reliability>:<durability>:<history>,<depth>:<deadline s>,<ns>:<lifespan s>,<ns>:<liveliness>,<s>,<ns>``
  with every value equal to rmw_zenoh's default left empty (``::,10:,:,:,,`` is KEEP_LAST 10, RELIABLE, VOLATILE).
  The default durability was TRANSIENT_LOCAL until #521 (Jazzy 0.2.3, March 2025): Jazzy 0.2.0-0.2.2 read an empty
  durability as transient local, so ``legacy`` tokens write it out (``:2:,10:,:,:,,``), which every release reads
  as volatile.
- Attachment of every published sample (zenoh-cpp ``ext::Serializer``): ``int64`` sequence number (from 1),
  ``int64`` source timestamp (ns since the epoch), both little-endian, then the 16-byte GID as a sequence: its
  length as LEB128 (one byte, 16) and the bytes: 33 bytes. The keyed layout of rmw_zenoh_cpp 0.2.0-0.2.3 (Jazzy,
  before #605) is available as ``legacy``: each value preceded by its name as a length-prefixed string.
- GID of an entity: XXH3-128 of its liveliness token key, the low 64 bits then the high 64 bits, little-endian.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum, StrEnum

#: Hermetic admin space of the liveliness tokens (``*`` and ``**`` never match it).
ADMIN_SPACE = "@ros2_lv"
#: Bytes of an entity GID (RMW_GID_STORAGE_SIZE since Iron).
GID_SIZE = 16
_LEGACY_KEYS = ("sequence_number", "source_timestamp", "source_gid")


class EntityKind(StrEnum):
    NODE = "NN"
    PUBLISHER = "MP"
    SUBSCRIPTION = "MS"
    SERVICE = "SS"
    CLIENT = "SC"


class Reliability(IntEnum):  # rmw_qos_reliability_policy_e
    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2


class Durability(IntEnum):  # rmw_qos_durability_policy_e
    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2


class History(IntEnum):  # rmw_qos_history_policy_e
    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2


@dataclass(frozen=True)
class QoS:
    """The QoS an endpoint announces (deadline, lifespan and liveliness are always rmw_zenoh's defaults here)."""

    depth: int = 10
    reliability: Reliability = Reliability.RELIABLE
    durability: Durability = Durability.VOLATILE
    history: History = History.KEEP_LAST

    def keyexpr(self, *, legacy: bool = False) -> str:
        """The token's QoS chunk, as ``qos_to_keyexpr`` writes it; ``legacy``: the durability always written out,
        for Jazzy 0.2.0-0.2.2, whose default (an empty field) was transient local (:data:`LEGACY_DURABILITY`)."""
        def differs(value: int, default: int) -> str:
            return "" if value == default else str(int(value))

        d = RMW_ZENOH_DEFAULT
        durability = str(int(self.durability)) if legacy else differs(self.durability, d.durability)
        return (f"{differs(self.reliability, d.reliability)}:{durability}:"
                f"{differs(self.history, d.history)},{differs(self.depth, d.depth)}:,:,:,,")

    @classmethod
    def parse(cls, text: str) -> "QoS":
        """Inverse of :meth:`keyexpr` (the deadline, lifespan and liveliness parts are ignored); an empty field is
        today's default (a token of Jazzy 0.2.0-0.2.2 with an empty durability meant :data:`LEGACY_DURABILITY`)."""
        parts = text.split(":")
        if len(parts) < 6:
            raise ValueError(f"QoS chunk {text!r} needs 6 ':'-separated parts")
        history, _, depth = parts[2].partition(",")
        d = RMW_ZENOH_DEFAULT
        return cls(depth=int(depth) if depth else d.depth,
                   reliability=Reliability(int(parts[0])) if parts[0] else d.reliability,
                   durability=Durability(int(parts[1])) if parts[1] else d.durability,
                   history=History(int(history)) if history else d.history)


#: rmw_zenoh's defaults (qos.cpp): KEEP_LAST 42, RELIABLE, VOLATILE; the reference of the QoS string.
RMW_ZENOH_DEFAULT = QoS(depth=42)
#: The default durability of rmw_zenoh_cpp before #521 (qos.cpp ``RMW_ZENOH_DEFAULT_DURABILITY``; Jazzy 0.2.0-0.2.2).
LEGACY_DURABILITY = Durability.TRANSIENT_LOCAL
#: rclcpp's default publisher QoS (KEEP_LAST 10, RELIABLE, VOLATILE): ``::,10:,:,:,,``.
DEFAULT_QOS = QoS(depth=10)
#: tf2_ros.TransformBroadcaster's QoS (KEEP_LAST 100).
TF_QOS = QoS(depth=100)
#: rclcpp's SensorDataQoS (KEEP_LAST 5, BEST_EFFORT): images.
SENSOR_QOS = QoS(depth=5, reliability=Reliability.BEST_EFFORT)


def mangle(name: str) -> str:
    return name.replace("/", "%")


def demangle(name: str) -> str:
    return name.replace("%", "/")


def dds_type_name(msgtype: str) -> str:
    """``geometry_msgs/msg/Pose`` -> ``geometry_msgs::msg::dds_::Pose_`` (the type as DDS and rmw_zenoh name it)."""
    package, kind, name = msgtype.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def ros_type_name(dds_name: str) -> str:
    """Inverse of :func:`dds_type_name`."""
    package, kind, dds, name = dds_name.split("::")
    if dds != "dds_" or not name.endswith("_"):
        raise ValueError(f"{dds_name!r} is not a DDS type name pkg::msg::dds_::Type_")
    return f"{package}/{kind}/{name[:-1]}"


def _strip_slashes(name: str) -> str:  # liveliness_utils.cpp strip_slashes: one leading, one trailing
    start = 1 if name.startswith("/") else 0
    end = len(name) - 1 if name.endswith("/") else len(name)
    return name[start:end]


def topic_key(domain: int, topic: str, msgtype: str, type_hash: str) -> str:
    """The data key of ``topic`` (fully qualified, e.g. ``/fleet/H1/target_pose``) of ``msgtype``."""
    return f"{int(domain)}/{_strip_slashes(topic)}/{dds_type_name(msgtype)}/{type_hash}"


@dataclass(frozen=True)
class Node:
    """A ROS 2 node's identity: name, namespace (``/`` when none) and SROS enclave (``/`` when none)."""

    name: str
    namespace: str = "/"
    enclave: str = "/"


def node_token(domain: int, zid: str, node_id: int, node: Node) -> str:
    """The liveliness token key of ``node`` (entity id = node id)."""
    return "/".join((ADMIN_SPACE, str(int(domain)), zid, str(node_id), str(node_id), EntityKind.NODE.value,
                     mangle(node.enclave), mangle(node.namespace), mangle(node.name)))


def endpoint_token(kind: EntityKind, domain: int, zid: str, node_id: int, entity_id: int, node: Node, topic: str,
                   msgtype: str, type_hash: str, qos: QoS, *, legacy: bool = False) -> str:
    """The liveliness token key of a publisher (``MP``) or subscription (``MS``) of ``node`` (``legacy``: for Jazzy
    0.2.0-0.2.3, the durability written out, :meth:`QoS.keyexpr`)."""
    return "/".join((ADMIN_SPACE, str(int(domain)), zid, str(node_id), str(entity_id), EntityKind(kind).value,
                     mangle(node.enclave), mangle(node.namespace), mangle(node.name), mangle(topic),
                     mangle(dds_type_name(msgtype)), mangle(type_hash), qos.keyexpr(legacy=legacy)))


def gid(token_key: str) -> bytes:
    """The 16-byte GID rmw_zenoh derives from an entity's liveliness token key (XXH3-128, low then high half)."""
    import xxhash

    return xxhash.xxh3_128_intdigest(token_key.encode()).to_bytes(GID_SIZE, "little")


@dataclass(frozen=True)
class Entity:
    """A parsed liveliness token."""

    key: str
    kind: EntityKind
    domain: int
    zid: str
    node_id: str
    entity_id: str
    node: Node
    topic: str | None = None
    dds_type: str | None = None
    type_hash: str | None = None
    qos: QoS | None = None

    @property
    def msgtype(self) -> str | None:
        return None if self.dds_type is None else ros_type_name(self.dds_type)

    @property
    def data_key(self) -> str | None:
        """The data key this publisher puts on (subscription listens on)."""
        if self.topic is None:
            return None
        return f"{self.domain}/{_strip_slashes(self.topic)}/{self.dds_type}/{self.type_hash}"

    @property
    def gid(self) -> bytes:
        return gid(self.key)


def parse_token(key: str) -> Entity:
    """Parse a liveliness token key; raise ValueError if it is not one of rmw_zenoh's."""
    parts = str(key).split("/")
    if len(parts) < 9 or parts[0] != ADMIN_SPACE or any(not p for p in parts):
        raise ValueError(f"{key!r} is not an rmw_zenoh liveliness token")
    kind = EntityKind(parts[5])
    node = Node(demangle(parts[8]), demangle(parts[7]), demangle(parts[6]))
    common = dict(key=str(key), kind=kind, domain=int(parts[1]), zid=parts[2], node_id=parts[3],
                  entity_id=parts[4], node=node)
    if kind is EntityKind.NODE:
        return Entity(**common)
    if len(parts) != 13:
        raise ValueError(f"{key!r}: an endpoint token has 13 chunks, got {len(parts)}")
    return Entity(**common, topic=demangle(parts[9]), dds_type=demangle(parts[10]), type_hash=demangle(parts[11]),
                  qos=QoS.parse(parts[12]))


# -- the attachment ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class Attachment:
    """What rmw_zenoh attaches to each sample: sequence number, source timestamp (ns), publisher GID."""

    sequence_number: int
    source_timestamp: int
    source_gid: bytes

    def __post_init__(self) -> None:
        if len(self.source_gid) != GID_SIZE:
            raise ValueError(f"a GID has {GID_SIZE} bytes, got {len(self.source_gid)}")


def _leb128(n: int) -> bytes:
    out = bytearray()
    while True:
        byte, n = n & 0x7F, n >> 7
        out.append(byte | (0x80 if n else 0))
        if not n:
            return bytes(out)


def _read_leb128(data: bytes, at: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        if at >= len(data) or shift > 63:
            raise ValueError("truncated sequence length in the attachment")
        byte = data[at]
        value, at, shift = value | (byte & 0x7F) << shift, at + 1, shift + 7
        if not byte & 0x80:
            return value, at


def _sized(data: bytes) -> bytes:
    return _leb128(len(data)) + data


def encode_attachment(attachment: Attachment, *, legacy: bool = False) -> bytes:
    """The attachment bytes (33 of them; ``legacy``: the keyed layout of rmw_zenoh_cpp 0.2.0-0.2.3)."""
    seq, stamp = struct.pack("<q", attachment.sequence_number), struct.pack("<q", attachment.source_timestamp)
    if not legacy:
        return seq + stamp + _sized(attachment.source_gid)
    names = [_sized(name.encode()) for name in _LEGACY_KEYS]
    return names[0] + seq + names[1] + stamp + names[2] + _sized(attachment.source_gid)


def decode_attachment(data: bytes | bytearray | memoryview) -> Attachment:
    """Parse either layout of :func:`encode_attachment`; raise ValueError on anything else."""
    data = bytes(data)
    if data.startswith(_sized(_LEGACY_KEYS[0].encode())):
        at, values = 0, []
        for name in _LEGACY_KEYS:
            expected = _sized(name.encode())
            if data[at:at + len(expected)] != expected:
                raise ValueError(f"attachment: expected the key {name!r}")
            at += len(expected)
            if name != "source_gid":
                if at + 8 > len(data):
                    raise ValueError("attachment truncated")
                values.append(struct.unpack_from("<q", data, at)[0])
                at += 8
        size, at = _read_leb128(data, at)
        gid_bytes = data[at:at + size]
        if size != GID_SIZE or len(gid_bytes) != size or at + size != len(data):
            raise ValueError("attachment: bad source_gid")
        return Attachment(values[0], values[1], gid_bytes)
    if len(data) < 17:
        raise ValueError(f"attachment of {len(data)} bytes is too short")
    seq, stamp = struct.unpack_from("<qq", data, 0)
    size, at = _read_leb128(data, 16)
    if size != GID_SIZE or at + size != len(data):
        raise ValueError(f"attachment: GID sequence of {size} bytes in {len(data)} bytes")
    return Attachment(seq, stamp, data[at:])
