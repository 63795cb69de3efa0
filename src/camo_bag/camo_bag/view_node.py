"""`./camo view`: runs live in Foxglove, through a Foxglove WebSocket server (foxglove-sdk).

The server opens its port at once and follows runs as they appear and end, as
foxglove_bridge follows the graph: every topic of every run in the domain (or,
with --run-id, of that run) is advertised as a channel while it has a publisher,
its messages in CDR with the `ros2msg` schema that bags embed (`msgdefs.py`):
the Foxglove app decodes them as it decodes a bag, and can be connected before a
run starts. A topic is subscribed on the ROS side only while a Foxglove client
is subscribed to its channel, so with no client connected the view takes no
robot message and costs the swarm nothing but one more participant on the graph.
It serves no parameters (Foxglove would fetch every node's, thousands of them).
"""

from __future__ import annotations

import os
import queue
import sys
import time

import foxglove
import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from camo_bag import msgdefs
from camo_bag.graph_topics import new_topics, taking_qos
from camo_core.cli.options import Combination, Parser
from camo_core.exceptions import CamoError, UsageError
from camo_core.shutdown import StopFlag
from camo_nodes.topics import keyed
from camo_nodes.topics.names import RunTopics, check_run_id, runs_on_graph
from camo_nodes.topics.runs import run_ended
from camo_nodes.topics.startup import add_network_options, network_env, start_ros

DEFAULT_PORT = 8765
# Clients' subscription changes taken per turn of the 50 ms timer at most: clients that come and
# go faster than that do not keep the node's thread from its other work.
CHANGES_PER_TURN = 256


class Subscribers:
    """What Foxglove clients subscribe to, handed from the server's thread to the node's."""

    def __init__(self) -> None:
        self.changes: queue.SimpleQueue[tuple[str, int]] = queue.SimpleQueue()

    def on_subscribe(self, client, channel) -> None:
        self.changes.put((channel.topic, 1))

    def on_unsubscribe(self, client, channel) -> None:
        self.changes.put((channel.topic, -1))


class ViewNode(Node):
    def __init__(
        self,
        run_id: str | None = None,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        **kwargs,
    ) -> None:
        """`run_id`: follow that run only (None: every run that appears)."""
        super().__init__("camo_view", **kwargs)
        self.run_id = run_id
        self.listener = Subscribers()
        try:
            self.server = foxglove.start_server(
                name=f"camo {run_id}" if run_id else "camo",
                host=host,
                port=port,
                server_listener=self.listener,
                capabilities=[],
                supported_encodings=["cdr"],
            )
        except Exception as exc:  # noqa: BLE001 - the SDK raises its own error types
            raise UsageError(f"cannot serve Foxglove on {host}:{port}: {exc}") from None
        self.channels: dict[str, foxglove.Channel | None] = {}
        self.offered: dict[str, tuple[type, list]] = {}
        self.watchers: dict[str, int] = {}
        self.taken: dict[str, object] = {}
        self.forwarded = 0
        self.refused = 0  # messages not shown: refused for their key tag, or sealed
        self.reader = keyed.Reader()
        self.create_timer(0.5, self.discover)
        self.create_timer(0.05, self.follow_clients)
        self.discover()

    @property
    def port(self) -> int:
        return self.server.port

    def runs(self) -> set[str]:
        """The runs followed now: those whose parameters have a publisher (their launcher)."""
        names = [name for name, _ in self.get_topic_names_and_types()]
        found = [r for r in runs_on_graph(names) if self.run_id in (None, r)]
        return {r for r in found if self.count_publishers(RunTopics(r).params)}

    def discover(self) -> None:
        """Channels for the followed runs' new topics; none any more for topics gone."""
        runs = self.runs()
        wanted = lambda name: name.split("/")[1] in runs  # noqa: E731
        for name in [n for n, c in self.channels.items() if c is not None]:
            if name.split("/")[1] not in runs and not self.count_publishers(name):
                self._drop(name)
        for name, type_name, offered in new_topics(self, self.channels, wanted):
            try:
                cls = msgdefs.message_class(type_name)
                schema = msgdefs.message_definition(type_name).encode()
            except msgdefs.DefinitionError as exc:
                self.get_logger().warning(f"{name} not viewable: {exc}")
                self.channels[name] = None
                continue
            self.offered[name] = (cls, offered)
            self.channels[name] = foxglove.Channel(
                name,
                message_encoding="cdr",
                schema=foxglove.Schema(name=type_name, encoding="ros2msg", data=schema),
            )

    def _drop(self, name: str) -> None:
        """A topic of a run that ended: its channel is unadvertised."""
        channel = self.channels.pop(name)
        if channel is not None:
            channel.close()
        self.offered.pop(name, None)
        self.watchers.pop(name, None)
        if name in self.taken:
            self.destroy_subscription(self.taken.pop(name))

    def follow_clients(self) -> None:
        """Take a topic from ROS while a client is subscribed to it, and only then (what clients
        changed: CHANGES_PER_TURN changes a turn at most, the rest the next turns)."""
        for _ in range(CHANGES_PER_TURN):
            try:
                topic, change = self.listener.changes.get_nowait()
            except queue.Empty:
                break
            self.watchers[topic] = max(0, self.watchers.get(topic, 0) + change)
        for topic, count in self.watchers.items():
            if count and topic not in self.taken and topic in self.offered:
                cls, offered = self.offered[topic]
                channel = self.channels[topic]
                self.taken[topic] = self.create_subscription(
                    cls,
                    topic,
                    lambda data, channel=channel, topic=topic: self._forward(channel, topic, data),
                    taking_qos(offered),
                    raw=True,
                )
            elif not count and topic in self.taken:
                self.destroy_subscription(self.taken.pop(topic))

    def _forward(self, channel: foxglove.Channel, topic: str, data: bytes) -> None:
        # Foxglove's decoders take plain CDR: a keyed run's trailer off, a sealed message opened
        # (with the run's key; else not shown), a stranger's refused where the key can tell.
        payload, _ = self.reader.payload(topic, data)
        if payload is None:
            self.refused += 1
            return
        channel.log(payload, log_time=time.time_ns())
        self.forwarded += 1

    def close(self) -> None:
        self.server.stop()
        for channel in self.channels.values():
            if channel is not None:
                channel.close()
        self.destroy_node()


def main(argv: list[str] | None = None) -> int:
    parser = Parser(prog="camo view", description="runs live in Foxglove (WebSocket)")
    parser.add_argument(
        "--run-id", default=None, help="follow this run only (default: every run that appears)"
    )
    parser.add_argument(
        "--port", type=int, default=DEFAULT_PORT, help=f"port (default {DEFAULT_PORT}; 0: any)"
    )
    parser.add_argument(
        "--host", default="127.0.0.1", help="address to serve on (default 127.0.0.1; 0.0.0.0: all)"
    )
    parser.add_argument(
        "--exit-with-run",
        action="store_true",
        help="end when the --run-id run ends (as ./camo run --foxglove's view does)",
    )
    add_network_options(parser)
    parser.combine(Combination("--exit-with-run", needs=("--run-id",), why="the run to end with"))
    try:
        args, ros_args = parser.parse_with_ros_args(argv)
        if not 0 <= args.port <= 65535:
            raise UsageError(f"--port must be in 0..65535 (got {args.port})")
        os.environ.update(network_env(args, os.environ))
        run_id = check_run_id(args.run_id) if args.run_id is not None else None
    except CamoError as exc:
        print(f"camo view: error: {exc}", file=sys.stderr)
        return 2
    stop = StopFlag()
    start_ros("camo view", ros_args, signal_handler_options=SignalHandlerOptions.NO)
    foxglove.set_log_level("WARN")
    node = None
    executor = EventsExecutor()
    try:
        node = ViewNode(run_id, args.host, args.port)
        executor.add_node(node)
        following = f"run {run_id}" if run_id else "every run in the domain as it appears"
        print(
            f"camo view: serving on ws://{args.host}:{node.port} (Foxglove: Open connection, "
            f"Foxglove WebSocket), following {following}; Ctrl-C to stop",
            file=sys.stderr,
        )
        ended = run_ended(node, RunTopics(run_id)) if args.exit_with_run else lambda: False
        while not stop and rclpy.ok() and not ended():
            executor.spin_once(timeout_sec=0.2)
    except CamoError as exc:
        print(f"camo view: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        pass
    finally:
        executor.shutdown()
        if node is not None:
            refused = f" ({node.refused} refused: no key tag of the run)" if node.refused else ""
            print(f"camo view: forwarded {node.forwarded} messages{refused}", file=sys.stderr)
            node.close()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
