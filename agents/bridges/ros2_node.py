"""A minimal ROS 2 node in the rmw_zenoh format over an open Zenoh session: its liveliness token, and publishers
that announce themselves with theirs and attach sequence number, timestamp and GID to every sample; and the
liveliness tokens of subscriptions (``MS``: the data themselves are received elsewhere, e.g. by
:class:`~agents.bridges.ros_sources.TopicFeed`), so that ``ros2 topic info`` lists the node as a subscriber.

As rmw_zenoh_cpp does (rmw_publisher_data.cpp): the Zenoh publisher is declared before its token, the token is
undeclared before the publisher; sequence numbers start at 1; a RELIABLE publisher puts reliably with congestion
control DROP (BLOCK only for KEEP_ALL); entity ids count up from the node's id within the process's context.
"""

from __future__ import annotations

import threading
import time

import zenoh

from agents.bridges.rmw_zenoh import (DEFAULT_QOS, Attachment, EntityKind, History, Node, QoS, Reliability,
                                      encode_attachment, endpoint_token, gid, node_token, topic_key)


def _endpoint(entity, kind: EntityKind, owner: "Ros2Node", entity_id: int, topic: str, msgtype: str,
              type_hash: str, qos: QoS) -> None:
    """What a publisher and a subscription both are: a topic's data key, its liveliness token key (``MP`` or
    ``MS``) and the GID derived from it."""
    entity.topic, entity.msgtype, entity.type_hash, entity.qos = topic, msgtype, type_hash, qos
    entity.key = topic_key(owner.domain, topic, msgtype, type_hash)
    entity.token_key = endpoint_token(kind, owner.domain, owner.zid, owner.node_id, entity_id, owner.node, topic,
                                      msgtype, type_hash, qos, legacy=owner.legacy_attachment)
    entity.gid = gid(entity.token_key)


class Ros2Publisher:
    """One ROS 2 publisher: ``publish`` puts CDR bytes on the data key with the attachment."""

    def __init__(self, session: zenoh.Session, owner: "Ros2Node", entity_id: int, topic: str, msgtype: str,
                 type_hash: str, qos: QoS) -> None:
        _endpoint(self, EntityKind.PUBLISHER, owner, entity_id, topic, msgtype, type_hash, qos)
        self._legacy = owner.legacy_attachment
        self._lock = threading.Lock()
        self._sequence_number = 1
        reliable = qos.reliability == Reliability.RELIABLE
        block = reliable and qos.history == History.KEEP_ALL
        self._publisher = session.declare_publisher(
            self.key, congestion_control=zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP,
            reliability=zenoh.Reliability.RELIABLE if reliable else zenoh.Reliability.BEST_EFFORT)
        self._token = session.liveliness().declare_token(self.token_key)

    def publish(self, cdr: bytes | memoryview, source_timestamp_ns: int | None = None) -> int:
        """Put one serialized message (CDR with its 4-byte encapsulation header); its size in bytes."""
        with self._lock:
            seq = self._sequence_number
            self._sequence_number += 1
        stamp = time.time_ns() if source_timestamp_ns is None else int(source_timestamp_ns)
        attachment = encode_attachment(Attachment(seq, stamp, self.gid), legacy=self._legacy)
        self._publisher.put(bytes(cdr), attachment=attachment)
        return len(cdr)

    @property
    def matched(self) -> bool:
        """Whether some subscriber (a ROS 2 subscription, a recorder) matches the data key now."""
        return bool(self._publisher.matching_status.matching)

    def close(self) -> None:
        self._token.undeclare()
        self._publisher.undeclare()


class Ros2Subscription:
    """The liveliness token of one ROS 2 subscription (``MS``): the same key as a publisher's with ``MS`` for
    ``MP`` (liveliness_utils.cpp); declared on creation, undeclared by :meth:`close`."""

    def __init__(self, session: zenoh.Session, owner: "Ros2Node", entity_id: int, topic: str, msgtype: str,
                 type_hash: str, qos: QoS) -> None:
        _endpoint(self, EntityKind.SUBSCRIPTION, owner, entity_id, topic, msgtype, type_hash, qos)
        self._token = session.liveliness().declare_token(self.token_key)
        self._closed = False

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._token.undeclare()


class Ros2Node:
    """A ROS 2 node on ``session``; publishers are made (once per topic) by :meth:`publisher`.

    Parameters
    ----------
    session : zenoh.Session
        Open session; not closed here.
    node : Node
        Name, namespace, enclave.
    domain : int
        ``ROS_DOMAIN_ID``.
    node_id : int
        The node's id in this process's context (rmw_zenoh counts nodes and entities from 0).
    legacy_attachment : bool
        For Jazzy's rmw_zenoh_cpp 0.2.0-0.2.3: attach the keyed layout instead of today's, and write each token's
        durability out (0.2.0-0.2.2 read an empty one as transient local; :meth:`QoS.keyexpr`).
    """

    def __init__(self, session: zenoh.Session, node: Node, *, domain: int = 0, node_id: int = 0,
                 legacy_attachment: bool = False) -> None:
        self.session, self.node, self.domain, self.node_id = session, node, int(domain), node_id
        self.legacy_attachment = legacy_attachment
        self.zid = str(session.info.zid())
        self.token_key = node_token(self.domain, self.zid, node_id, node)
        self._token = session.liveliness().declare_token(self.token_key)
        self._next_entity_id = node_id + 1
        self._publishers: dict[str, Ros2Publisher] = {}
        self._subscriptions: list[Ros2Subscription] = []
        self._lock = threading.Lock()

    def publisher(self, topic: str, msgtype: str, type_hash: str, qos: QoS = DEFAULT_QOS) -> Ros2Publisher:
        """The publisher of ``topic`` (declared, with its token, on first use)."""
        with self._lock:
            found = self._publishers.get(topic)
            if found is not None:
                if found.msgtype != msgtype:
                    raise ValueError(f"{topic} is already published as {found.msgtype}, not {msgtype}")
                return found
            entity_id = self._next_entity_id
            self._next_entity_id += 1
            made = self._publishers[topic] = Ros2Publisher(self.session, self, entity_id, topic, msgtype, type_hash,
                                                           qos)
            return made

    def subscription(self, topic: str, msgtype: str, type_hash: str, qos: QoS = DEFAULT_QOS) -> Ros2Subscription:
        """Announce a subscription of ``topic`` (its ``MS`` token, with the next entity id)."""
        with self._lock:
            entity_id = self._next_entity_id
            self._next_entity_id += 1
            made = Ros2Subscription(self.session, self, entity_id, topic, msgtype, type_hash, qos)
            self._subscriptions.append(made)
            return made

    def subscriptions(self) -> list[Ros2Subscription]:
        with self._lock:
            return list(self._subscriptions)

    def publishers(self) -> list[Ros2Publisher]:
        with self._lock:
            return list(self._publishers.values())

    def close(self) -> None:
        """Undeclare every publisher and subscription token, then the node's token (the session stays open)."""
        with self._lock:
            publishers, self._publishers = list(self._publishers.values()), {}
            subscriptions, self._subscriptions = self._subscriptions, []
        for endpoint in [*publishers, *subscriptions]:
            endpoint.close()
        self._token.undeclare()

    def __enter__(self) -> "Ros2Node":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
