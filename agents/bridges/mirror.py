"""``evopose ros2``: mirror a fleet onto ROS 2 topics in the rmw_zenoh format (docs/ros2.md).

One Zenoh session: a :class:`~agents.bridges.tap.FleetTap` on the fleet's keys, and a ROS 2 node
``/<fleet>/evopose_mirror`` (:class:`~agents.bridges.ros2_node.Ros2Node`) whose publishers are declared, with their
liveliness tokens, the first time a fleet message needs them (:mod:`agents.bridges.translate`). ROS 2 nodes on the
same Zenoh network (rmw_zenoh_cpp, e.g. through ``rmw_zenohd`` or ``evopose router``) then see the topics with
``ros2 topic list``, ``echo`` and ``hz``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import replace

from protocol.codec import decode_sample
from protocol.errors import ProtocolError

from agents.bridges import names, ros_msgs
from agents.bridges.rmw_zenoh import Node
from agents.bridges.ros2_node import Ros2Node
from agents.bridges.tap import FleetTap, RawSample
from agents.bridges.translate import translate
from agents.transport.session import SessionOptions, open_session

log = logging.getLogger(__name__)

#: The mirror node's name (its namespace is the fleet's ROS name).
NODE_NAME = "evopose_mirror"
#: The fleet vehicle whose hints come from ROS (``--hints-from``).
HINT_VEHICLE = "ros"
#: How an observer retries an endpoint that does not answer yet (Zenoh's default backs off to several seconds, so
#: one started before the fleet could miss a short run): every 0.1 s, growing to 0.5 s.
OBSERVER_RETRY = {"period_init_ms": 100, "period_max_ms": 500, "period_increase_factor": 1.5}


def observer_options(options: SessionOptions) -> SessionOptions:
    """``options`` with :data:`OBSERVER_RETRY` for the endpoints to connect to (unless ``extra`` sets one)."""
    return replace(options, extra={"connect/retry": OBSERVER_RETRY, **options.extra})


class Mirror:
    """Translate each fleet sample and publish it on ``node``; counts per ROS topic (``published``)."""

    def __init__(self, node: Ros2Node, emit: Callable[[dict], None] | None = None) -> None:
        self.node, self._emit = node, emit
        self.published: Counter[str] = Counter()
        self.rejected: Counter[str] = Counter()
        self._names = names.NameMap()
        self._lock = threading.Lock()

    def handle(self, raw: RawSample) -> None:
        try:
            key, message = decode_sample(raw.key, raw.payload)
        except ProtocolError as err:
            with self._lock:
                self.rejected[err.reason] += 1
            return
        for name in (key.fleet, key.vehicle):
            other = self._names.collision(name)
            if other is not None:
                log.warning("%r and %r are both %r in ROS names; their topics mix", other, name,
                            names.ros_name(name))
        for out in translate(key, message, raw.received_ns):
            known = {p.topic for p in self.node.publishers()}
            publisher = self.node.publisher(out.topic, out.msgtype, ros_msgs.type_hash(out.msgtype), out.qos)
            if out.topic not in known and self._emit is not None:
                self._emit({"event": "publisher", "topic": out.topic, "type": out.msgtype, "key": publisher.key,
                            "token": publisher.token_key})
            publisher.publish(out.cdr())
            with self._lock:
                self.published[out.topic] += 1


def run_mirror(options: SessionOptions, stop: threading.Event, fleet: str, *, domain: int = 0,
               node_name: str = NODE_NAME, legacy_attachment: bool = False, duration: float | None = None,
               hints_from: str | None = None, hint_vehicle: str = HINT_VEHICLE,
               emit: Callable[[dict], None] | None = None) -> dict:
    """Mirror ``fleet`` until ``stop`` (or ``duration`` s); emits ``ready``, then ``publisher`` per new topic.

    ``hints_from``: also take ``geometry_msgs/msg/PoseStamped`` from that ROS topic and send each as a hint of the
    fleet vehicle ``hint_vehicle`` (:mod:`agents.bridges.ros_hints`; the name must be free in the fleet).
    Returns the summary: messages published per ROS topic, fleet samples rejected per reason, dropped, and with
    ``hints_from`` the hints forwarded and refused.
    """
    from protocol.keys import check_name

    from agents.bridges.listener import Ros2Listener
    from agents.bridges.ros_hints import HintForwarder
    from agents.transport.bus import FleetBus
    from agents.transport.presence import ensure_name_free

    check_name(fleet, "fleet")
    emit = emit or (lambda record: None)
    started = time.monotonic()
    hints = None
    with open_session(observer_options(options)) as session, ExitStack() as stack:
        node = Ros2Node(session, Node(node_name, f"/{names.ros_name(fleet)}"), domain=domain,
                        legacy_attachment=legacy_attachment)
        stack.callback(node.close)
        mirror = Mirror(node, emit)
        tap = stack.enter_context(FleetTap(session, fleet, mirror.handle))
        if hints_from is not None:
            check_name(hint_vehicle, "hint vehicle")
            ensure_name_free(session, fleet, hint_vehicle)
            hints = HintForwarder(stack.enter_context(FleetBus(session, fleet, hint_vehicle, max_age_s=None)))
            listener = stack.enter_context(Ros2Listener(session, domain=domain, topics=[hints_from],
                                                        on_message=hints, keep_samples=0))
        emit({"event": "ready", "fleet": fleet, "domain": domain, "zid": node.zid, "node": node.token_key,
              **({"hints_from": hints_from, "hint_vehicle": hint_vehicle} if hints is not None else {})})
        while not stop.wait(0.1):
            if duration is not None and time.monotonic() - started >= duration:
                break
    return {"event": "stopped", "published": dict(mirror.published), "rejected": dict(mirror.rejected),
            "dropped": tap.dropped, "seconds": time.monotonic() - started,
            **({"hints": {**hints.counts(), "undecodable": listener.error_count,
                            "dropped": listener.dropped}} if hints is not None else {})}
