"""Delivery policy per topic, as plain data (the agents map it onto Zenoh's QoS enums).

``block``: the publisher waits when the transmission queue is full instead of dropping
(Zenoh ``CongestionControl.BLOCK``); used for everything small that must arrive.
Images use ``DROP``: a late frame is worthless and must never stall the hints; receivers keep
them in a small ring buffer. ``express`` sends without batching (lowest latency).
``priority`` is the name of a Zenoh priority (``REAL_TIME`` highest ... ``BACKGROUND`` lowest).
"""

from __future__ import annotations

from dataclasses import dataclass

from .keys import Topic


@dataclass(frozen=True)
class TopicQoS:
    """How one topic is published and received."""

    block: bool        #: congestion control BLOCK (True) or DROP (False)
    express: bool      #: no batching
    priority: str      #: Zenoh priority name
    ring: bool = False  #: receivers keep only the newest few samples


QOS: dict[Topic, TopicQoS] = {
    Topic.HINT: TopicQoS(block=True, express=True, priority="INTERACTIVE_HIGH"),
    Topic.ATTITUDE: TopicQoS(block=True, express=True, priority="INTERACTIVE_HIGH"),
    Topic.POSE: TopicQoS(block=True, express=False, priority="INTERACTIVE_LOW"),
    Topic.FEATURES: TopicQoS(block=True, express=False, priority="DATA_HIGH"),
    Topic.IMAGE: TopicQoS(block=False, express=False, priority="DATA_LOW", ring=True),
    Topic.STATS: TopicQoS(block=False, express=False, priority="BACKGROUND"),
}
