"""``evopose record`` and ``evopose replay``: a fleet in two MCAP files, and back (docs/ros2.md, "Record and replay").

``--out DIR`` (no ``.mcap`` suffix) writes a rosbag2 bag directory, as ``ros2 bag record`` does: ``DIR/DIR.mcap``,
``DIR/metadata.yaml`` (rosbag2 metadata version 8, storage ``mcap``: :func:`bag_metadata`) and the raw channels in
``DIR/DIR.raw.mcap``, which the metadata does not list; ``ros2 bag info DIR`` and ``rosbags.rosbag2.Reader(DIR)``
open it. ``--out X.mcap`` writes the two files alone.

``run.mcap`` has the ROS 2 profile (header profile ``ros2``) and nothing else: each ROS 2 message the mirror would
publish (:mod:`agents.bridges.translate`) is a CDR message on a channel named after its ROS topic, with a ``ros2msg``
schema and the metadata rosbag2's MCAP storage plugin writes and reads (``offered_qos_profiles``, the QoS the mirror
offers, and ``topic_type_hash``), so ``ros2 bag``, Foxglove and Lichtblick read every channel of it.
Beside it, ``run.raw.mcap`` (:func:`raw_path`, no profile) keeps every fleet sample as it was on the wire, nothing
lost: the channel's topic is the fleet key (``evopose/<fleet>/<vehicle>/<topic>``), its message encoding ``msgpack``
(hints: ``evopose-hint``, 24 bytes), no schema; log time = receive time, publish time = the message's acquisition
stamp. Schemaless channels are valid MCAP but not ROS 2 profile, which is why they have a file of their own.

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
from agents.bridges.rmw_zenoh import QoS
from agents.bridges.translate import RosMessage, translate
from agents.errors import FleetError
from agents.transport.session import SessionOptions, open_session

#: Message encoding of the raw channels (MCAP registry: ``msgpack``); hints are 24 raw bytes.
RAW_ENCODING = "msgpack"
HINT_ENCODING = "evopose-hint"
#: Metadata record naming the recording's fleet.
METADATA_NAME = "evopose"
#: rmw_qos_liveliness_policy_e AUTOMATIC (rmw/types.h): what every rmw_zenoh publisher offers.
LIVELINESS_AUTOMATIC = 1


class RecordingError(FleetError):
    """A recording that cannot be read or replayed."""


def raw_path(out: Path) -> Path:
    """Where the raw channels of a recording ``out`` go: ``run.mcap`` -> ``run.raw.mcap``."""
    out = Path(out)
    if out.name.endswith(".raw.mcap"):
        return out
    return out.with_name((out.stem if out.suffix == ".mcap" else out.name) + ".raw.mcap")


#: rosbag2 metadata version written in metadata.yaml: 8 (Jazzy's) keeps offered_qos_profiles as a YAML string with
#: integer policies (:func:`offered_qos_profiles`), which Jazzy and later read; 9 is the same with policy names.
BAG_VERSION = 8
BAG_METADATA = "metadata.yaml"


def bag_file(out: Path) -> Path:
    """The ROS 2 MCAP file of the recording ``out``: ``out`` itself when it ends in ``.mcap``, else the file of the
    bag directory ``out`` (``out/<name>.mcap``)."""
    out = Path(out)
    return out if out.suffix == ".mcap" else out / f"{out.name}.mcap"


def offered_qos_profiles(qos: QoS) -> str:
    """The channel metadata ``offered_qos_profiles`` of a topic offered with ``qos``, as rosbag2 serialises it
    (rosbag2_storage ``serialize_rclcpp_qos_vector``: a YAML list of profiles). The integer form of the policies
    (rosbag2 metadata version 8): Humble's reader reads only that one and later readers detect it; deadline,
    lifespan and lease duration 0 s are "unspecified" (the RMW default), which is what the mirror offers."""
    unset = "\n    sec: 0\n    nsec: 0"
    return (f"- history: {int(qos.history)}\n  depth: {int(qos.depth)}\n  reliability: {int(qos.reliability)}\n"
            f"  durability: {int(qos.durability)}\n  deadline:{unset}\n  lifespan:{unset}\n"
            f"  liveliness: {LIVELINESS_AUTOMATIC}\n  liveliness_lease_duration:{unset}\n"
            "  avoid_ros_namespace_conventions: false\n")


class Recorder:
    """Writes fleet samples to open MCAP writers: the ROS 2 channels to ``ros``, the raw ones to ``raw`` (either
    None: not written); one thread only."""

    def __init__(self, ros=None, raw=None) -> None:
        self.ros, self.raw = ros, raw
        self.written: Counter[str] = Counter()
        self.rejected = 0
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._raw_channels: dict[str, int] = {}
        self._sequence: Counter[tuple[int, int]] = Counter()
        #: ROS topic -> (type, QoS) and message count, first and last log time: the bag's metadata.yaml.
        self.topics: dict[str, tuple[str, QoS]] = {}
        self.ros_counts: Counter[str] = Counter()
        self.first_ns: int | None = None
        self.last_ns: int | None = None

    def _ros_channel(self, out: RosMessage) -> int:
        channel = self._channels.get(out.topic)
        if channel is None:
            schema = self._schemas.get(out.msgtype)
            if schema is None:
                schema = self._schemas[out.msgtype] = self.ros.register_schema(
                    name=out.msgtype, encoding="ros2msg", data=ros_msgs.msgdef(out.msgtype).encode())
            metadata = {"offered_qos_profiles": offered_qos_profiles(out.qos),
                        "topic_type_hash": ros_msgs.type_hash(out.msgtype)}
            channel = self._channels[out.topic] = self.ros.register_channel(
                topic=out.topic, message_encoding="cdr", schema_id=schema, metadata=metadata)
            self.topics[out.topic] = (out.msgtype, out.qos)
        return channel

    def _raw_channel(self, key: str, encoding: str) -> int:
        channel = self._raw_channels.get(key)
        if channel is None:
            channel = self._raw_channels[key] = self.raw.register_channel(topic=key, message_encoding=encoding,
                                                                          schema_id=0)
        return channel

    def _add(self, writer, channel: int, log_ns: int, data: bytes, publish_ns: int, topic: str) -> None:
        self._sequence[(id(writer), channel)] += 1
        writer.add_message(channel_id=channel, log_time=log_ns, data=data, publish_time=publish_ns,
                           sequence=self._sequence[(id(writer), channel)])
        self.written[topic] += 1

    def handle(self, raw: RawSample) -> None:
        try:
            key, message = decode_sample(raw.key, raw.payload)
        except ProtocolError:
            self.rejected += 1  # not a valid message: kept raw only if its key is a fleet key
            key, message = parse_key(raw.key), None
        if self.raw is not None:
            encoding = HINT_ENCODING if key.topic is Topic.HINT else RAW_ENCODING
            stamp = message.stamp_ns if isinstance(message, Message) else raw.received_ns
            self._add(self.raw, self._raw_channel(raw.key, encoding), raw.received_ns, raw.payload, stamp, raw.key)
        if self.ros is not None and message is not None:
            for out in translate(key, message, raw.received_ns):
                self._add(self.ros, self._ros_channel(out), raw.received_ns, out.cdr(), out.stamp_ns, out.topic)
                self.ros_counts[out.topic] += 1
                self.first_ns = raw.received_ns if self.first_ns is None else min(self.first_ns, raw.received_ns)
                self.last_ns = raw.received_ns if self.last_ns is None else max(self.last_ns, raw.received_ns)


def bag_metadata(recorder: Recorder, mcap_name: str) -> dict:
    """rosbag2's metadata.yaml of a bag whose one file ``mcap_name`` holds ``recorder``'s ROS 2 channels (what
    rosbag2_storage's ``MetadataIo`` writes, version :data:`BAG_VERSION`)."""
    start = recorder.first_ns or 0
    duration = (recorder.last_ns - start) if recorder.last_ns is not None else 0
    count = sum(recorder.ros_counts.values())
    return {"rosbag2_bagfile_information": {
        "version": BAG_VERSION, "storage_identifier": "mcap", "relative_file_paths": [mcap_name],
        "duration": {"nanoseconds": duration}, "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": count,
        "topics_with_message_count": [
            {"topic_metadata": {"name": topic, "type": msgtype, "serialization_format": "cdr",
                                "offered_qos_profiles": offered_qos_profiles(qos),
                                "type_description_hash": ros_msgs.type_hash(msgtype)},
             "message_count": recorder.ros_counts[topic]}
            for topic, (msgtype, qos) in sorted(recorder.topics.items())],
        "compression_format": "", "compression_mode": "",
        "files": [{"path": mcap_name, "starting_time": {"nanoseconds_since_epoch": start},
                   "duration": {"nanoseconds": duration}, "message_count": count}],
        "custom_data": {"evopose_raw": raw_path(Path(mcap_name)).name},
        "ros_distro": "evopose"}}


def run_record(options: SessionOptions, stop: threading.Event, fleet: str, out: Path, *,
               duration: float | None = None, ros: bool = True, raw: bool = True,
               emit: Callable[[dict], None] | None = None) -> dict:
    """Record ``fleet`` until ``stop`` (or ``duration`` s): the ROS 2 channels into the MCAP file ``out``, the raw
    ones into :func:`raw_path` of it; emits ``ready`` once subscribed.

    Returns the summary: the files, messages written per channel, samples that did not decode, samples dropped
    (queue full).
    """
    from mcap.writer import Writer

    check_name(fleet, "fleet")
    if not (ros or raw):
        raise RecordingError("--no-ros and --no-raw: nothing to record")
    emit = emit or (lambda record: None)
    bag = Path(out) if Path(out).suffix != ".mcap" else None
    if bag is not None and bag.exists() and (not bag.is_dir() or any(bag.iterdir())):
        raise RecordingError(f"{bag}: exists and is not an empty directory; name a new bag directory "
                             "(or X.mcap for a file)")
    out = bag_file(Path(out))
    paths = {"out": out if ros else None, "raw": raw_path(out) if raw else None}
    if paths["out"] is not None and paths["out"] == paths["raw"]:
        raise RecordingError(f"{out}: name the ROS 2 file, not the raw one (*.raw.mcap)")
    out.parent.mkdir(parents=True, exist_ok=True)
    started = time.monotonic()
    streams, writers = [], {}
    try:
        for name, path in paths.items():
            if path is not None:
                streams.append(open(path, "wb"))
                writers[name] = Writer(streams[-1])
                writers[name].start(profile="ros2" if name == "out" else "", library="evopose record")
                writers[name].add_metadata(METADATA_NAME, {"fleet": fleet, "started_ns": str(time.time_ns())})
        recorder = Recorder(writers.get("out"), writers.get("raw"))
        with open_session(observer_options(options)) as session:
            try:
                with FleetTap(session, fleet, recorder.handle) as tap:
                    emit({"event": "ready", "fleet": fleet, **{k: str(v) for k, v in paths.items() if v}})
                    while not stop.wait(0.1):
                        if duration is not None and time.monotonic() - started >= duration:
                            break
            finally:
                for writer in writers.values():
                    writer.finish()
    finally:
        for stream in streams:
            stream.close()
    if bag is not None and ros:  # a rosbag2 bag directory: its metadata.yaml, once the file is finished
        import yaml

        (bag / BAG_METADATA).write_text(yaml.safe_dump(bag_metadata(recorder, out.name), sort_keys=False))
        paths["bag"] = bag
    return {"event": "stopped", **{k: str(v) for k, v in paths.items() if v}, "written": dict(recorder.written),
            "rejected": recorder.rejected, "dropped": tap.dropped, "seconds": time.monotonic() - started}


# -- replay ------------------------------------------------------------------------------------------

def raw_recording(path: Path) -> Path:
    """The file with the raw channels of the recording ``path`` (a file or a bag directory): ``path`` itself when it
    has them (a ``*.raw.mcap`` or a one-file recording of older versions), else its :func:`raw_path`."""
    path = Path(path)
    if path.is_dir():  # a bag directory of evopose record: its raw file
        path = bag_file(path)
    if not raw_path(path).exists():
        return path
    if path.exists():
        messages = raw_messages(path)
        try:
            if next(messages, None) is not None:
                return path
        finally:
            messages.close()
    return raw_path(path)


def raw_messages(path: Path) -> Iterator[tuple[str, int, bytes]]:
    """``(fleet key, log time ns, payload)`` of every raw channel of the MCAP file ``path``, in log-time order."""
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
    """Publish the raw channels of ``path`` (:func:`raw_recording`) back on the fleet keys with their recorded
    spacing / ``rate``.

    ``fleet`` replays under another fleet name. ``wait_s``: first wait up to that long until every key has a
    subscriber (``ready`` says whether they all did). Returns the summary: messages sent per key.
    """
    if rate <= 0:
        raise RecordingError(f"--rate must be positive, got {rate}")
    emit = emit or (lambda record: None)
    path = raw_recording(Path(path))
    first_stamp, keys = _first_stamp(path)
    if not keys:
        raise RecordingError(f"{path}: no raw fleet channels to replay, nor a {raw_path(path).name} beside "
                             "it (recorded with --no-raw?)")
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
            for key, log_ns, payload in raw_messages(path):
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
