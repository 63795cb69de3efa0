"""The recorder: every topic of a run (or the ones named) into an MCAP bag, as rosbag2 records.

It discovers topics as they appear, subscribes to each with a QoS compatible
with what its publishers offer (transient-local topics hand over their
history, so nothing published before discovery is lost), and stores the CDR
bytes as received. Log time is the receive time; publish time is the
message's header stamp (the receive time for types without a header). It
flushes a chunk every second, so a recorder killed with SIGKILL loses at
most the last second; Ctrl-C closes the bag with its index and summary.
"""

from __future__ import annotations

import struct
import sys
import time

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from camo_core import cli

from . import msgdefs, qos_yaml
from .bag import BagError, BagWriter, TopicInfo
from .shutdown import StopFlag
from .swarm_worker import events_executor

SKIPPED = {"/rosout", "/parameter_events"}


def header_stamp_ns(data: bytes) -> int | None:
    """The header stamp of a CDR message whose first field is std_msgs/Header (sec int32, nanosec uint32)."""
    if len(data) < 12:
        return None
    sec, nanosec = struct.unpack("<iI" if data[1] == 1 else ">iI", data[4:12])
    return sec * 10**9 + nanosec


class RecorderNode(Node):
    def __init__(
        self,
        path: str,
        topics: list[str] | None = None,
        discovery_period: float = 0.5,
        flush_period: float = 1.0,
        **kwargs,
    ) -> None:
        super().__init__("recorder", namespace="/camo", **kwargs)
        self.bag = BagWriter(path, library="camo recorder_node")
        self.wanted = set(topics) if topics else None
        self.last_message: dict[str, float] = {}
        self._stamped: dict[str, bool] = {}
        self._since: dict[str, float] = {}
        self._recorded = {}
        self.create_timer(discovery_period, self.discover)
        self.flush_period = flush_period
        self._flushed = time.monotonic()
        self.create_timer(flush_period, self._flush)
        self.discover()

    def recording_now(self) -> set[str]:
        return {name for name, sub in self._recorded.items() if sub is not None}

    def recorded(self, topic: str) -> int:
        """Messages recorded on a topic so far."""
        info = self.bag.topics.get(topic)
        return 0 if info is None else info.count

    def settled(
        self, topics: set[str], quiet: float, ignoring: frozenset[str] = frozenset()
    ) -> bool:
        """Subscribed to every one of these topics, matched with their publishers for `quiet` seconds
        (a latched topic's history has come in), and no message for `quiet` seconds."""
        if not topics <= self.recording_now():
            return False
        now = time.monotonic()
        return (
            all(
                self._recorded[name].get_publisher_count() > 0 and now - self._since[name] > quiet
                for name in topics
            )
            and self.idle_for(ignoring) > quiet
        )

    def idle_for(self, ignoring: frozenset[str] = frozenset()) -> float:
        """Seconds since the last message arrived on a topic not ignored (e.g. a periodic one)."""
        times = [t for name, t in self.last_message.items() if name not in ignoring]
        return time.monotonic() - max(times, default=0.0)

    def discover(self) -> None:
        for name, types in self.get_topic_names_and_types():
            if (
                name in self._recorded
                or name in SKIPPED
                or (self.wanted and name not in self.wanted)
            ):
                continue
            if len(types) != 1:
                self.get_logger().warning(f"{name} carries several types {types}; not recorded")
                self._recorded[name] = None
                continue
            publishers = self.get_publishers_info_by_topic(name)
            if not publishers:
                continue  # only subscribers so far: wait for a publisher's QoS
            self._subscribe(name, msgdefs.full_name(types[0]), [p.qos_profile for p in publishers])

    def _subscribe(self, name: str, type_name: str, offered: list[QoSProfile]) -> None:
        try:
            cls = msgdefs.message_class(type_name)
            definition = msgdefs.message_definition(type_name)
        except msgdefs.DefinitionError as exc:
            self.get_logger().warning(f"{name} not recorded: {exc}")
            self._recorded[name] = None
            return
        self.bag.add_topic(
            TopicInfo(name, type_name, qos_yaml.dump(offered), msgdefs.type_hash(type_name)),
            definition,
        )
        fields = list(cls.get_fields_and_field_types().items())
        self._stamped[name] = bool(fields) and fields[0] == ("header", "std_msgs/Header")
        # As rosbag2 adapts: reliable and transient-local only when every publisher offers it.
        reliable = all(q.reliability == ReliabilityPolicy.RELIABLE for q in offered)
        latched = all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offered)
        qos = QoSProfile(
            history=HistoryPolicy.KEEP_ALL,
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
        )
        self._since[name] = time.monotonic()
        self._recorded[name] = self.create_subscription(
            cls, name, lambda data, topic=name: self._on_message(topic, data), qos, raw=True
        )

    def _on_message(self, topic: str, data: bytes) -> None:
        if self.bag.closed:
            return
        received = time.time_ns()
        published = header_stamp_ns(data) if self._stamped[topic] else None
        self.bag.write(topic, data, received, published if published is not None else received)
        now = self.last_message[topic] = time.monotonic()
        if now - self._flushed > self.flush_period:  # timers can starve under a flood of messages
            self._flush()

    def _flush(self) -> None:
        self.bag.flush()
        self._flushed = time.monotonic()

    def close(self) -> None:
        self.bag.close()


def main(argv: list[str] | None = None) -> int:
    parser = cli.Parser(prog="recorder_node", description="record topics into an MCAP bag folder")
    parser.add_argument(
        "path", help="bag folder to create (NAME/ with NAME_0.mcap and metadata.yaml)"
    )
    parser.add_argument(
        "--topics", nargs="+", default=None, help="only these topics (default: every topic)"
    )
    try:
        args, ros_args = parser.parse_known_args(argv)
    except cli.UsageError as exc:
        print(f"recorder_node: error: {exc}", file=sys.stderr)
        return 2
    stop = StopFlag()
    rclpy.init(args=ros_args, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    executor = events_executor()
    try:
        node = RecorderNode(args.path, args.topics)
        executor.add_node(node)
        print(f"recorder_node: recording to {node.bag.file} (Ctrl-C to stop)", file=sys.stderr)
        while not stop and rclpy.ok():
            executor.spin_once(timeout_sec=0.2)
    except BagError as exc:
        print(f"recorder_node: error: {exc}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        executor.shutdown()
        if node is not None:
            executor.remove_node(node)
            node.close()
            print(
                f"recorder_node: wrote {node.bag.message_count} messages on {len(node.bag.topics)} topics "
                f"to {node.bag.folder}",
                file=sys.stderr,
            )
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
