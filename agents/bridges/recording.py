"""``evopose record`` and ``evopose replay``: a fleet in one MCAP file, and back (docs/ros2.md, "Record and replay").

The file has the ROS 2 profile (header profile ``ros2``): each ROS 2 message the mirror would publish
(:mod:`agents.bridges.translate`) is a CDR message on a channel named after its ROS topic, with a ``ros2msg`` schema
and the type hash in the channel metadata (``topic_type_hash``), so Foxglove, Lichtblick and rosbag2 tools read it.
Beside them, the raw channels keep every fleet sample as it was on the wire, nothing lost: the channel's topic is the
fleet key (``evopose/<fleet>/<vehicle>/<topic>``), its message encoding ``msgpack`` (hints: ``evopose-hint``, 24
bytes), no schema; log time = receive time, publish time = the message's acquisition stamp.

Replay publishes the raw channels on their keys (or another fleet's, ``fleet``) with the recorded spacing (divided by
``rate``). The fleet's receivers drop data older than their ``max_age``, so by default each message's ``stamp_ns``
is moved to the replay's clock (:func:`restamp`: at rate 1 one shift for all, replay start - first recorded stamp):
the messages are the same but for that, and their stamps keep their spacing. The vehicles' presence tokens are
declared for the replay's duration, so fresh agents see their team-mates.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path

import msgpack
import zenoh

from protocol.codec import decode_sample
from protocol.errors import ProtocolError
from protocol.keys import Topic, alive_key, check_name, parse_key, topic_key
from protocol.messages import Message
from protocol.qos import QOS

from agents.bridges import ros_msgs
from agents.bridges.mirror import observer_options
from agents.bridges.tap import FleetTap, RawSample
from agents.bridges.translate import translate
from agents.errors import FleetError
from agents.transport.session import SessionOptions, open_session

#: Message encoding of the raw channels (MCAP registry: ``msgpack``); hints are 24 raw bytes.
RAW_ENCODING = "msgpack"
HINT_ENCODING = "evopose-hint"
#: Metadata record naming the recording's fleet.
METADATA_NAME = "evopose"


class RecordingError(FleetError):
    """A recording that cannot be read or replayed."""


class Recorder:
    """Writes fleet samples to an open MCAP writer: the ROS 2 channels and the raw ones (one thread only)."""

    def __init__(self, writer, *, ros: bool = True, raw: bool = True) -> None:
        self.writer, self.ros, self.raw = writer, ros, raw
        self.written: Counter[str] = Counter()
        self.rejected = 0
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._sequence: Counter[int] = Counter()

    def _channel(self, topic: str, encoding: str, msgtype: str | None) -> int:
        channel = self._channels.get(topic)
        if channel is None:
            schema = 0
            metadata = {}
            if msgtype is not None:
                schema = self._schemas.get(msgtype)
                if schema is None:
                    schema = self._schemas[msgtype] = self.writer.register_schema(
                        name=msgtype, encoding="ros2msg", data=ros_msgs.msgdef(msgtype).encode())
                metadata = {"topic_type_hash": ros_msgs.type_hash(msgtype)}
            channel = self._channels[topic] = self.writer.register_channel(topic=topic, message_encoding=encoding,
                                                                           schema_id=schema, metadata=metadata)
        return channel

    def _add(self, channel: int, log_ns: int, data: bytes, publish_ns: int, topic: str) -> None:
        self._sequence[channel] += 1
        self.writer.add_message(channel_id=channel, log_time=log_ns, data=data, publish_time=publish_ns,
                                sequence=self._sequence[channel])
        self.written[topic] += 1

    def handle(self, raw: RawSample) -> None:
        try:
            key, message = decode_sample(raw.key, raw.payload)
        except ProtocolError:
            self.rejected += 1  # not a valid message: kept raw only if its key is a fleet key
            key, message = parse_key(raw.key), None
        if self.raw:
            encoding = HINT_ENCODING if key.topic is Topic.HINT else RAW_ENCODING
            stamp = message.stamp_ns if isinstance(message, Message) else raw.received_ns
            self._add(self._channel(raw.key, encoding, None), raw.received_ns, raw.payload, stamp, raw.key)
        if self.ros and message is not None:
            for out in translate(key, message, raw.received_ns):
                self._add(self._channel(out.topic, "cdr", out.msgtype), raw.received_ns, out.cdr(), out.stamp_ns,
                          out.topic)


def run_record(options: SessionOptions, stop: threading.Event, fleet: str, out: Path, *,
               duration: float | None = None, ros: bool = True, raw: bool = True,
               emit: Callable[[dict], None] | None = None) -> dict:
    """Record ``fleet`` into the MCAP file ``out`` until ``stop`` (or ``duration`` s); emits ``ready`` once subscribed.

    Returns the summary: messages written per channel, samples that did not decode, samples dropped (queue full).
    """
    from mcap.writer import Writer

    check_name(fleet, "fleet")
    emit = emit or (lambda record: None)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    started = time.monotonic()
    with open(out, "wb") as stream, open_session(observer_options(options)) as session:
        writer = Writer(stream)
        writer.start(profile="ros2", library="evopose record")
        writer.add_metadata(METADATA_NAME, {"fleet": fleet, "started_ns": str(time.time_ns())})
        recorder = Recorder(writer, ros=ros, raw=raw)
        try:
            with FleetTap(session, fleet, recorder.handle) as tap:
                emit({"event": "ready", "fleet": fleet, "out": str(out)})
                while not stop.wait(0.1):
                    if duration is not None and time.monotonic() - started >= duration:
                        break
        finally:
            writer.finish()
    return {"event": "stopped", "out": str(out), "written": dict(recorder.written), "rejected": recorder.rejected,
            "dropped": tap.dropped, "seconds": time.monotonic() - started}


# -- replay ------------------------------------------------------------------------------------------

def raw_messages(path: Path) -> Iterator[tuple[str, int, bytes]]:
    """``(fleet key, log time ns, payload)`` of every raw channel of the recording, in log-time order."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as stream:
            for _, channel, message in make_reader(stream).iter_messages(log_time_order=True):
                if channel.message_encoding in (RAW_ENCODING, HINT_ENCODING) and channel.topic.startswith("evopose/"):
                    yield channel.topic, message.log_time, message.data
    except (McapError, OSError, ValueError) as err:
        raise RecordingError(f"{path}: not a readable MCAP recording ({err})") from None


def restamp(payload: bytes, first_stamp_ns: int, start_ns: int, rate: float = 1.0) -> bytes:
    """The msgpack message with ``stamp_ns`` moved to the replay's clock: ``start_ns + (stamp - first) / rate``
    (at rate 1 a pure shift); everything else as it was. Anything that is not such a message is returned as is."""
    try:
        document = msgpack.unpackb(payload, raw=False)
    except (ValueError, msgpack.UnpackException):
        return payload
    if isinstance(document, dict) and type(document.get("stamp_ns")) is int:
        document["stamp_ns"] = max(0, start_ns + round((document["stamp_ns"] - first_stamp_ns) / rate))
        return msgpack.packb(document, use_bin_type=True)
    return payload


def _first_stamp(path: Path) -> tuple[int | None, set[tuple[str, str, str]]]:
    """The first recorded ``stamp_ns`` (None if no message has one) and every (fleet, vehicle, topic) recorded."""
    first, keys = None, set()
    for key, _, payload in raw_messages(path):
        parsed = parse_key(key)
        keys.add((parsed.fleet, parsed.vehicle, parsed.topic.value))
        if first is None and parsed.topic is not Topic.HINT:
            try:
                first = decode_sample(key, payload)[1].stamp_ns
            except (ProtocolError, AttributeError):
                pass
    return first, keys


def run_replay(options: SessionOptions, stop: threading.Event, path: Path, *, rate: float = 1.0,
               fleet: str | None = None, keep_stamps: bool = False, presence: bool = True, wait_s: float = 3.0,
               emit: Callable[[dict], None] | None = None) -> dict:
    """Publish the raw channels of ``path`` back on the fleet keys with their recorded spacing / ``rate``.

    ``fleet`` replays under another fleet name. ``wait_s``: first wait up to that long until every key has a
    subscriber (``ready`` says whether they all did). Returns the summary: messages sent per key.
    """
    if rate <= 0:
        raise RecordingError(f"--rate must be positive, got {rate}")
    emit = emit or (lambda record: None)
    first_stamp, keys = _first_stamp(Path(path))
    if not keys:
        raise RecordingError(f"{path}: no raw fleet channels to replay (recorded with --no-raw?)")
    fleet = check_name(fleet, "fleet") if fleet is not None else None
    sent: Counter[str] = Counter()
    with open_session(observer_options(options)) as session:
        publishers: dict[str, zenoh.Publisher] = {}
        for recorded_fleet, vehicle, topic in sorted(keys):
            qos = QOS[Topic(topic)]
            key = topic_key(fleet or recorded_fleet, vehicle, topic)
            publishers[f"evopose/{recorded_fleet}/{vehicle}/{topic}"] = session.declare_publisher(
                key, congestion_control=zenoh.CongestionControl.BLOCK if qos.block else zenoh.CongestionControl.DROP,
                express=qos.express)
        tokens = [session.liveliness().declare_token(alive_key(fleet or f, v))
                  for f, v in sorted({(f, v) for f, v, _ in keys})] if presence else []
        deadline = time.monotonic() + wait_s
        while not all(p.matching_status.matching for p in publishers.values()) and time.monotonic() < deadline:
            if stop.wait(0.01):
                break
        matched = all(p.matching_status.matching for p in publishers.values())
        start_wall, start_ns = time.monotonic(), time.time_ns()
        shift = 0 if keep_stamps or first_stamp is None else start_ns - first_stamp
        emit({"event": "ready", "keys": len(publishers), "matched": matched, "shift_ns": shift, "rate": rate})
        first_log = None
        try:
            for key, log_ns, payload in raw_messages(Path(path)):
                first_log = log_ns if first_log is None else first_log
                if stop.wait(max(0.0, start_wall + (log_ns - first_log) / 1e9 / rate - time.monotonic())):
                    break
                if shift and not key.endswith(f"/{Topic.HINT.value}"):
                    payload = restamp(payload, first_stamp, start_ns, rate)
                publishers[key].put(payload)
                sent[key] += 1
        finally:
            for token in tokens:
                token.undeclare()
            for publisher in publishers.values():
                publisher.undeclare()
    return {"event": "stopped", "sent": dict(sent), "matched": matched, "shift_ns": shift,
            "seconds": time.monotonic() - start_wall}
