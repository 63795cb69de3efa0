"""The recorder: every topic of a run (or the ones named) into an MCAP bag, as rosbag2 records.

It discovers topics as they appear, subscribes to each with a QoS compatible
with what its publishers offer (transient-local topics hand over their
history, so nothing published before discovery is lost), and stores the CDR
bytes as received. Log time is the receive time; publish time is the
message's header stamp (the receive time for types without a header). It
flushes a chunk every second, so a recorder killed with SIGKILL loses at
most the last second; Ctrl-C closes the bag with its index and summary.

It also keeps a ledger of what the bag holds of the run (`ledger.py`) and
publishes it on /<run>/swarm/recorded: the run's launcher waits for each round
to be complete in every recorder's bag before it switches backgrounds or stops
the robots, and for its result (/<run>/swarm/result) to be recorded before it
exits. A recorder of a run stops by itself once the result and all it names
are in the bag (or the run's launcher is gone).
"""

from __future__ import annotations

import json
import os
import signal
import socket
import struct
import sys
import time
from pathlib import Path

import rclpy
from rclpy.duration import Duration
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import String

from camo_bag import msgdefs, qos_yaml
from camo_bag.completeness import done_reports, header_frame_id
from camo_bag.container import BagWriter, TopicInfo
from camo_bag.graph_topics import new_topics, taking_qos
from camo_bag.ledger import ROBOT_KINDS, Ledger
from camo_core.cli.options import Parser, seconds
from camo_core.exceptions import CamoError, UsageError
from camo_core.results.folders import new_folder_problem
from camo_core.shutdown import StopFlag
from camo_core.swarm.keys import sealed
from camo_nodes.topics import keyed
from camo_nodes.topics.images import frame_number
from camo_nodes.topics.names import RunTopics, check_run_id, check_topic_name
from camo_nodes.topics.qos import LATCHED
from camo_nodes.topics.robot_messages import RaggedColumns, senders_rounds_steps
from camo_nodes.topics.runs import result_from, run_ended, setup_from, wait_for_run
from camo_nodes.topics.startup import LEAN_NODE, add_network_options, network_env, start_ros

RESULT_GRACE = 10.0  # s a recorder waits, after the run's result, for what the result names
# A recorder that could not write its bag (a full disk) exits with this code: the bag ends
# where writing failed, and the run it recorded goes on without it.
EXIT_WRITE_FAILED = 3


def header_stamp_ns(data: bytes) -> int | None:
    """The header stamp of a CDR message whose first field is std_msgs/Header (sec int32,
    nanosec uint32)."""
    if len(data) < 12:
        return None
    sec, nanosec = struct.unpack("<iI" if data[1] == 1 else ">iI", data[4:12])
    return sec * 10**9 + nanosec


class RecorderNode(Node):
    def __init__(
        self,
        path: str,
        run: RunTopics | None,
        topics: list[str] | None = None,
        discovery_period: float = 0.5,
        flush_period: float = 1.0,
        **kwargs,
    ) -> None:
        """Records the run's topics (those under /<run>/), or with `topics` only those."""
        namespace = run.swarm_namespace if run else "/"
        super().__init__("recorder", namespace=namespace, **kwargs)
        self.bag = BagWriter(path, library="camo recorder_node")
        self.run = run
        self.wanted = set(topics) if topics else None
        self.ledger = Ledger()
        self.identity = f"{socket.gethostname()}:{os.getpid()}"
        self._stamped: dict[str, bool] = {}
        self._decoders: dict[str, object] = {}
        self._recorded: dict[str, object] = {}
        self.create_timer(discovery_period, self.discover)
        self.flush_period = flush_period
        self._flushed = time.monotonic()
        self._params_written = False
        self.reader = keyed.Reader()
        self.refused = 0  # messages without the run's key tag: not recorded
        self.create_timer(flush_period, self._flush)
        self.report_pub = None
        if run is not None:
            self.report_pub = keyed.publisher(self, String, run.recorded, LATCHED, run.run)
            self.create_timer(0.25, self.report)
        self._reported = None
        if run is not None and self._wants(run.params):
            # Its type and QoS are known: taken at once, the bag names its run from the start,
            # however late discovery shows the run's topics (a recorder killed then still
            # leaves a bag `bag info` calls the run's and incomplete).
            self._subscribe(run.params, "std_msgs/msg/String", [LATCHED])
        self.discover()
        self.report()

    def recorded(self, topic: str) -> int:
        """Messages recorded on a topic so far."""
        info = self.bag.topics.get(topic)
        return 0 if info is None else info.count

    def discover(self) -> None:
        for name, type_name, offered in new_topics(self, self._recorded, self._wants):
            self._subscribe(name, type_name, offered)

    def _wants(self, name: str) -> bool:
        if self.wanted is not None:
            return name in self.wanted
        run = self.run
        return run is not None and name.startswith(f"/{run.run}/") and name != run.recorded

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
        run = self.run
        if run is not None and (
            type_name in ROBOT_KINDS or name in (run.status, run.params, run.result)
        ):
            self._decoders[name] = cls
        qos = taking_qos(offered)
        self._recorded[name] = self.create_subscription(
            cls, name, lambda data, topic=name: self._on_message(topic, data), qos, raw=True
        )

    def _on_message(self, topic: str, data: bytes) -> None:
        if self.bag.closed:
            return
        received = time.time_ns()
        # A keyed run's messages are recorded as plain CDR (any reader of bags reads them), an
        # encrypted run's as their ciphertext; with the run's key, what it did not tag is not
        # the run's and is left out (counted).
        payload, _ = self.reader.payload(topic, data)
        if payload is None and self.reader.key is not None:
            self.refused += 1
            return
        recorded = data if payload is None or sealed(data) else payload
        stamped = payload is not None and self._stamped[topic]
        published = header_stamp_ns(payload) if stamped else None
        self.bag.write(topic, recorded, received, published if published is not None else received)
        cls = self._decoders.get(topic)
        if cls is not None and payload is not None:
            self._account(topic, deserialize_message(payload, cls))
        elif self.run is not None and topic == self.run.background:
            self.ledger.background(frame_number(header_frame_id(data)))
        if time.monotonic() - self._flushed > self.flush_period:  # timers starve under floods
            self._flush()
        elif self.run is not None and topic == self.run.params and not self._params_written:
            # Written out at once: a bag cut short (a recorder killed) still says which run it
            # holds, whatever chunk the parameters would have shared with later messages.
            self._params_written = True
            self._flush()

    def _account(self, topic: str, msg) -> None:
        """What the ledger must know of a run message: who sent it, in which round."""
        ledger = self.ledger
        if topic == self.run.params:
            setup = setup_from(msg.data, self.run.run)
            if setup is None:
                self.get_logger().warning(f"{topic}: a message that is not the run's parameters")
            elif ledger.params is None:
                ledger.set_run(setup.params, len(setup.backgrounds), setup.protocol.continuous)
        elif topic == self.run.result:
            result = result_from(msg.data, self.run.run)
            if result is None:
                self.get_logger().warning(f"{topic}: a message that is not the run's result")
            else:
                ledger.set_result(result)
        elif topic == self.run.status:
            for robot, index in done_reports(msg):
                ledger.reported_done(robot, index)
        else:
            type_name = msgdefs.full_name(self.bag.topics[topic].type)
            kind = ROBOT_KINDS[type_name]
            try:
                messages = senders_rounds_steps(msg)
            except RaggedColumns:  # recorded as it came; a stranger's, or damaged: not counted
                self.get_logger().warning(
                    f"{topic}: columns of different lengths", throttle_duration_sec=10.0
                )
                return
            for sender, round_index, step in messages:
                ledger.message(kind, sender, round_index, step)

    def finished(self) -> bool:
        """The run's result is recorded, and all it says the bag must hold."""
        return self.ledger.result is not None and not self.ledger.gaps()

    def report(self, final: bool = False) -> None:
        """/<run>/swarm/recorded: per round, how many robots' rounds the bag holds completely.
        `final`: sent now, and waited for (a second at most) until its readers have it. (With
        --topics there is no run to report to.)"""
        if self.report_pub is None:
            return
        ledger = self.ledger
        rounds = ledger.rounds or 0
        report = {
            "recorder": self.identity,
            "result": ledger.result is not None,
            "messages": self.bag.message_count,
            "complete": [len(ledger.complete(k)) for k in range(rounds)],
            "lacking": [ledger.lacking(k) for k in range(rounds)],
            # By round (its frame number), the latest rounds robots finished in (a continuous
            # run's: the launcher waits for its last one; all of them made the report grow).
            "rounds": {str(k): ledger.complete_count(k) for k in ledger.latest_rounds()},
        }
        changed = {k: v for k, v in report.items() if k != "messages"}
        if changed != self._reported or final:
            self._reported = changed
            self.report_pub.publish(String(data=json.dumps(report)))
        if final:
            self.report_pub.wait_for_all_acked(Duration(seconds=1))

    def _flush(self) -> None:
        self.bag.flush()
        self._flushed = time.monotonic()

    def close(self) -> None:
        self.bag.close()

    def failure(self) -> str:
        """One line: which bag stopped, why, and how far it got."""
        bag = self.bag
        start = bag.start_ns or bag.saved_ns
        got = f"{bag.saved} messages, {max(0, bag.saved_ns - start) / 1e9:.1f} s"
        if self.run is not None:
            got += f" of run {self.run.run}"
        return (
            f"cannot write the bag {bag.folder} ({bag.failed}); it holds its first {got} and "
            f"is incomplete (./camo bag repair {bag.folder} makes a readable copy)"
        )


def join(executor, run_id: str | None, wait: float, stop) -> RunTopics:
    """The run to record: as soon as its topics appear, to miss nothing."""
    finder = Node("recorder_join", **LEAN_NODE)
    executor.add_node(finder)
    try:
        found = wait_for_run(
            finder, lambda: executor.spin_once(timeout_sec=0.05), run_id, wait, stop
        )
    finally:
        executor.remove_node(finder)
        finder.destroy_node()
    return RunTopics(found)


def main(argv: list[str] | None = None) -> int:
    parser = Parser(prog="recorder_node", description="record topics into an MCAP bag folder")
    parser.add_argument(
        "path", help="bag folder to create (NAME/ with NAME_0.mcap and metadata.yaml)"
    )
    parser.add_argument(
        "--topics", nargs="+", default=None, help="only these topics (default: the run's)"
    )
    parser.add_argument(
        "--run-id", default=None, help="the run to record (default: the only one in the domain)"
    )
    parser.add_argument(
        "--wait", type=seconds, default=120.0, help="seconds to wait for the run (default 120)"
    )
    add_network_options(parser)
    try:
        args, ros_args = parser.parse_with_ros_args(argv)
        os.environ.update(network_env(args, os.environ))
        run_id = check_run_id(args.run_id) if args.run_id is not None else None
        problem = new_folder_problem(Path(args.path), "the bag")
        if problem:
            raise UsageError(problem)
        for topic in args.topics or []:
            check_topic_name(topic, "--topics")
    except CamoError as exc:
        print(f"recorder_node: error: {exc}", file=sys.stderr)
        return 2
    stop = StopFlag()
    start_ros("recorder_node", ros_args, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    executor = EventsExecutor()
    try:
        run = None
        if args.topics is None:
            run = join(executor, run_id, args.wait, stop)
        node = RecorderNode(args.path, run, args.topics)
        executor.add_node(node)
        what = f"run {run.run}" if run else "topics"
        print(
            f"recorder_node: recording {what} to {node.bag.file} (Ctrl-C to stop)", file=sys.stderr
        )
        ended = run_ended(node, run) if run else (lambda: False)
        result_at = None
        while not stop and rclpy.ok() and not ended() and node.bag.failed is None:
            executor.spin_once(timeout_sec=0.2)
            if run is not None and node.ledger.result is not None:
                # The result came: what it names should follow at once; RESULT_GRACE at most.
                result_at = result_at or time.monotonic()
                if node.finished() or time.monotonic() - result_at > RESULT_GRACE:
                    node.report(final=True)  # the launcher waits for it before it exits
                    break
    except CamoError as exc:
        print(f"recorder_node: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        pass
    finally:
        executor.shutdown()
        code = 0 if node is None else finish(executor, node)
        rclpy.try_shutdown()
        # The bag is closed and its exit status says how it went: a stop signal from now on
        # (a launcher stopping the recorder that has just ended by itself) would otherwise
        # meet Python's own handling again once the interpreter tears down, and end it as
        # killed by the signal, a recording failed to its launcher.
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_IGN)
    return code


def finish(executor, node: RecorderNode) -> int:
    """Close the bag and say what it holds (one line if writing failed); the exit code."""
    executor.remove_node(node)
    node.close()
    bag = node.bag
    try:
        if bag.failed is not None:
            print(f"recorder_node: error: {node.failure()}", file=sys.stderr)
            return EXIT_WRITE_FAILED
        print(
            f"recorder_node: wrote {bag.message_count} messages on {len(bag.topics)} topics "
            f"to {bag.folder}",
            file=sys.stderr,
        )
        if node.run is not None:
            gaps = node.ledger.gaps()
            verdict = "incomplete: " + "; ".join(gaps) if gaps else "complete"
            print(f"recorder_node: the bag of run {node.run.run} is {verdict}", file=sys.stderr)
        return 0
    finally:
        node.destroy_node()


if __name__ == "__main__":
    sys.exit(main())
