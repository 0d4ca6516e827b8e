"""rosbag2 recordings (sqlite3 or mcap) written and read with the ``rosbags`` library.

``ros2 bag`` is not on PyPI, so the project records with :class:`BagRecorder`: rclpy subscriptions
with ``raw=True`` hand over the serialized CDR bytes, which the rosbags ``Writer`` stores as they
are, under the Jazzy message definitions of ``rosbags.typesys.Stores.ROS2_JAZZY``. Reading needs no
ROS at all (:func:`read_bag`, :func:`bag_info`), so the offline replay and the tests can use it
where rclpy is absent; only :class:`BagRecorder` and :func:`message_class` import ROS packages, and
only when called.

Timestamps in a bag are receive (log) times in integer nanoseconds of the recorder's clock (sim
time when the recorder node has ``use_sim_time``).

Command line (``ros2 bag`` stand-in)::

    python -m mrslam_ros.bag record OUT [--topics /a /b] [--storage mcap|sqlite3] [--duration S] [--use-sim-time]
    python -m mrslam_ros.bag info BAG
"""

from __future__ import annotations

import importlib
from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any, Self

from rosbags.rosbag2 import Reader, ReaderError, StoragePlugin, Writer, WriterError

from mrslam_core.errors import InputError

STORAGES = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}
DEFAULT_EXCLUDE = ("/rosout", "/parameter_events")


class BagError(InputError, RuntimeError):
    """A bag that cannot be written or read, or a message type that cannot be handled."""


@dataclass(frozen=True)
class BagMessage:
    """One serialized message of a bag.

    Attributes:
        topic: fully qualified topic name.
        msgtype: ROS 2 type name, ``pkg/msg/Name``.
        stamp_ns: log (receive) time [ns].
        data: the CDR-serialized message, as published on the wire.
    """

    topic: str
    msgtype: str
    stamp_ns: int
    data: bytes


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a bag: type, message count and the offered QoS records (rosbags ``Qos``)."""

    msgtype: str
    count: int
    offered_qos: tuple = ()


@dataclass(frozen=True)
class BagInfo:
    """Summary of a bag: storage, first and last log time [ns] (inclusive) and its topics."""

    storage: str
    start_ns: int
    end_ns: int
    topics: dict[str, TopicInfo] = field(default_factory=dict)

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) * 1e-9 if self.topics else 0.0

    @property
    def count(self) -> int:
        return sum(t.count for t in self.topics.values())


@lru_cache(maxsize=1)
def typestore():
    """The rosbags typestore of ROS 2 Jazzy (message definitions written into the bags)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def message_class(msgtype: str) -> type:
    """The rclpy message class of ``pkg/msg/Name`` (``rosidl_runtime_py`` is not on PyPI).

    Raises:
        BagError: malformed name, or the package is not importable (e.g. tf2_msgs before
            ``scripts/build_interfaces.sh`` ran).
    """
    parts = msgtype.split("/")
    if len(parts) != 3 or not all(parts):
        raise BagError(f"malformed message type {msgtype!r} (expected pkg/msg/Name)")
    pkg, kind, name = parts
    try:
        return getattr(importlib.import_module(f"{pkg}.{kind}"), name)
    except (ImportError, AttributeError) as exc:
        raise BagError(f"message type {msgtype} is not available: {exc}") from exc


def msgtype_of(cls: type) -> str:
    """``pkg/msg/Name`` of an rclpy message class."""
    module = cls.__module__.split(".")  # e.g. sensor_msgs.msg._image
    return f"{module[0]}/{module[1]}/{cls.__name__}"


def _storage(storage: str) -> StoragePlugin:
    try:
        return STORAGES[storage]
    except KeyError:
        raise BagError(f"unknown bag storage {storage!r} (have {sorted(STORAGES)})") from None


class BagWriter:
    """A rosbag2 being written: add topics, then messages; close (or use as a context manager).

    Args:
        path: the bag folder to create (must not exist).
        storage: ``"sqlite3"`` or ``"mcap"``.

    Raises:
        BagError: the folder exists, or an unknown storage.
    """

    def __init__(self, path: str | Path, storage: str = "sqlite3"):
        self.path = Path(path)
        self.storage = storage
        try:
            self._writer = Writer(self.path, version=Writer.VERSION_LATEST, storage_plugin=_storage(storage))
            self._writer.open()
        except WriterError as exc:
            raise BagError(f"cannot write bag {self.path}: {exc}") from exc
        self._connections: dict[str, Any] = {}
        self.counts: Counter[str] = Counter()

    def add_topic(self, topic: str, msgtype: str, offered_qos: Iterable = ()) -> None:
        """Declare ``topic`` of type ``msgtype`` (idempotent for the same type).

        Raises:
            BagError: the type is not in the Jazzy typestore, or the topic was added with another type.
        """
        if topic in self._connections:
            if self._connections[topic].msgtype != msgtype:
                raise BagError(f"topic {topic} already recorded as {self._connections[topic].msgtype}, not {msgtype}")
            return
        if msgtype not in typestore().fielddefs:
            raise BagError(f"message type {msgtype} is not in the ROS 2 Jazzy typestore of rosbags")
        self._connections[topic] = self._writer.add_connection(topic, msgtype, typestore=typestore(),
                                                               offered_qos_profiles=list(offered_qos))

    def has_topic(self, topic: str) -> bool:
        return topic in self._connections

    def write(self, topic: str, stamp_ns: int, data: bytes) -> None:
        """Append one serialized message at log time ``stamp_ns`` [ns] to an added topic."""
        if topic not in self._connections:
            raise BagError(f"topic {topic} was not added to the bag")
        self._writer.write(self._connections[topic], int(stamp_ns), data)
        self.counts[topic] += 1

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None  # type: ignore[assignment]

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def write_bag(path: str | Path, messages: Iterable[BagMessage], storage: str = "sqlite3") -> Path:
    """Write serialized messages into a new bag (topics are added as they first appear)."""
    with BagWriter(path, storage) as writer:
        for m in messages:
            writer.add_topic(m.topic, m.msgtype)
            writer.write(m.topic, m.stamp_ns, m.data)
    return Path(path)


def serialize(msg: Any, msgtype: str) -> bytes:
    """A rosbags (typestore) message object -> CDR bytes, as rclpy publishes them."""
    return bytes(typestore().serialize_cdr(msg, msgtype))


def deserialize(data: bytes, msgtype: str) -> Any:
    """CDR bytes -> a rosbags (typestore) message object (no ROS needed)."""
    return typestore().deserialize_cdr(data, msgtype)


def _open(path: str | Path) -> Reader:
    path = Path(path)
    if not (path / "metadata.yaml").is_file():
        raise BagError(f"{path} is not a rosbag2 folder (no metadata.yaml)")
    try:
        reader = Reader(path)
        reader.open()
    except ReaderError as exc:
        raise BagError(f"cannot read bag {path}: {exc}") from exc
    return reader


def bag_info(path: str | Path) -> BagInfo:
    """Storage, time span and topics of the bag folder ``path``.

    Raises:
        BagError: not a bag, or unreadable.
    """
    reader = _open(path)
    try:
        topics: dict[str, TopicInfo] = {}
        for c in reader.connections:
            old = topics.get(c.topic)
            qos = tuple(getattr(c.ext, "offered_qos_profiles", ()) or ())
            topics[c.topic] = TopicInfo(c.msgtype, c.msgcount + (old.count if old else 0), qos)
        storage = "mcap" if any(Path(path).glob("*.mcap")) else "sqlite3"
        # rosbags reports the end exclusive (last stamp + 1)
        end = reader.end_time - 1 if reader.message_count else reader.start_time
        return BagInfo(storage, reader.start_time, end, topics)
    finally:
        reader.close()


def read_bag(path: str | Path, topics: Iterable[str] | None = None) -> Iterator[BagMessage]:
    """The messages of a bag in log-time order, optionally only those of ``topics``.

    Raises:
        BagError: not a bag, or unreadable.
    """
    reader = _open(path)
    try:
        wanted = set(topics) if topics is not None else None
        conns = [c for c in reader.connections if wanted is None or c.topic in wanted]
        if not conns:
            return
        for conn, stamp, data in reader.messages(connections=conns):
            yield BagMessage(conn.topic, conn.msgtype, int(stamp), bytes(data))
    finally:
        reader.close()


class BagRecorder:
    """Record topics of a live graph into a bag, from ``node``'s raw (serialized) subscriptions.

    Topics are discovered on a timer (``discover_period`` s): every topic in ``topics`` (or every
    topic at all when ``topics`` is None, except ``exclude``) gets a raw subscription whose QoS is
    adapted to its publishers (transient-local publishers, e.g. ``/tf_static``, are recorded from
    before the recorder joined). Messages are logged with the node's clock (sim time under
    ``use_sim_time``). Topics of types the Jazzy typestore lacks are skipped and counted in
    ``skipped``. The recorder needs ``node`` to be spun.

    Args:
        node: an rclpy node to subscribe with.
        path: the bag folder to create.
        topics: fully qualified topic names to record, or None for all.
        storage: ``"sqlite3"`` or ``"mcap"``.
        exclude: topics never recorded when ``topics`` is None.
        discover_period: seconds between graph look-ups.
    """

    def __init__(self, node, path: str | Path, topics: Iterable[str] | None = None, storage: str = "sqlite3",
                 exclude: Iterable[str] = DEFAULT_EXCLUDE, discover_period: float = 0.5):
        self.node = node
        self.writer = BagWriter(path, storage)
        self.topics = set(topics) if topics is not None else None
        self.exclude = set(exclude)
        self.skipped: Counter[str] = Counter()
        self._subs: dict[str, Any] = {}
        self.discover()
        from rclpy.clock import Clock, ClockType

        # graph look-ups on the steady clock: under use_sim_time a paused /clock must not stop discovery
        self._timer = node.create_timer(discover_period, self.discover, clock=Clock(clock_type=ClockType.STEADY_TIME))

    @property
    def counts(self) -> Counter[str]:
        """Messages written per topic."""
        return self.writer.counts

    def discover(self) -> None:
        """Subscribe every wanted topic that has appeared on the graph since the last look-up."""
        from mrslam_ros.qos import adapted_to_publishers, to_bag_qos

        for topic, types in self.node.get_topic_names_and_types():
            if topic in self._subs or topic in self.skipped:
                continue
            if (self.topics is not None and topic not in self.topics) or (self.topics is None and topic in self.exclude):
                continue
            msgtype = types[0]
            try:
                cls = message_class(msgtype)
                publishers = self.node.get_publishers_info_by_topic(topic)
                if not publishers:
                    # a topic only subscribed so far (a viewer's): its publishers' QoS is not
                    # known yet, and a latched guess would not match a volatile publisher
                    continue
                qos = adapted_to_publishers(publishers, topic)
                self.writer.add_topic(topic, msgtype, [to_bag_qos(p.qos_profile) for p in publishers])
            except BagError as exc:
                self.skipped[topic] += 1
                self.node.get_logger().warning(f"not recording {topic}: {exc}")
                continue
            self._subs[topic] = self.node.create_subscription(
                cls, topic, lambda data, t=topic: self._on_message(t, data), qos, raw=True)

    def _on_message(self, topic: str, data: bytes) -> None:
        if self.writer._writer is None:
            return
        self.writer.write(topic, self.node.get_clock().now().nanoseconds, data)

    def close(self) -> None:
        """Stop recording and finish the bag (metadata.yaml is written here)."""
        self.node.destroy_timer(self._timer)
        for sub in self._subs.values():
            self.node.destroy_subscription(sub)
        self._subs.clear()
        self.writer.close()


def main(argv: list[str]) -> int:
    """``python -m mrslam_ros.bag info BAG`` or ``record OUT [--topics T ...] [--storage S]
    [--duration S] [--use-sim-time]`` (Ctrl-C ends a recording cleanly)."""
    import argparse
    import sys
    import time

    ap = argparse.ArgumentParser(prog="python -m mrslam_ros.bag", description="rosbag2 info and recording")
    sub = ap.add_subparsers(dest="cmd", required=True)
    info_p = sub.add_parser("info", help="topics, counts and time span of a bag")
    info_p.add_argument("bag")
    rec_p = sub.add_parser("record", help="record topics of the live graph")
    rec_p.add_argument("out", help="bag folder to create")
    rec_p.add_argument("--topics", nargs="+", help="topics to record (default: all)")
    rec_p.add_argument("--storage", choices=sorted(STORAGES), default="mcap")
    rec_p.add_argument("--duration", type=float, help="stop after this many wall seconds")
    rec_p.add_argument("--use-sim-time", action="store_true", help="log times from /clock")
    args = ap.parse_args(argv)
    try:
        if args.cmd == "info":
            info = bag_info(args.bag)
            print(f"{args.bag}: {info.storage}, {info.count} messages, {info.duration_s:.3f} s "
                  f"[{info.start_ns} .. {info.end_ns}] ns")
            for topic, t in sorted(info.topics.items()):
                print(f"  {topic:<40} {t.msgtype:<40} {t.count}")
            return 0
        import rclpy
        from rclpy.parameter import Parameter

        rclpy.init()
        node = rclpy.create_node("mrslam_bag_recorder",
                                 parameter_overrides=[Parameter("use_sim_time", value=args.use_sim_time)])
        recorder = BagRecorder(node, args.out, args.topics, args.storage)
        end = None if args.duration is None else time.monotonic() + args.duration
        try:
            while rclpy.ok() and (end is None or time.monotonic() < end):
                rclpy.spin_once(node, timeout_sec=0.1)
        except KeyboardInterrupt:
            pass
        finally:
            recorder.close()
            node.destroy_node()
            rclpy.try_shutdown()
        print(f"recorded {sum(recorder.counts.values())} messages: {dict(recorder.counts)}")
        return 0
    except BagError as exc:
        print(f"mrslam_ros.bag: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    import sys

    sys.exit(main(sys.argv[1:]))
