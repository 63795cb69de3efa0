"""`./camo view`: a run live in Foxglove, through a Foxglove WebSocket server (foxglove-sdk).

Every topic of the run is advertised as a channel, its messages in CDR with
the `ros2msg` schema that bags embed (`msgdefs.py`), as foxglove_bridge does
for C++ ROS: the Foxglove app decodes them as it decodes a bag. A topic is
subscribed on the ROS side only while a Foxglove client is subscribed to its
channel, so with no client connected the view takes no robot message and
costs the swarm nothing but one more participant on the graph. It serves no
parameters (Foxglove would fetch every node's, thousands of them).
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
from camo_bag.recorder_node import join
from camo_core.cli.options import Parser, seconds
from camo_core.exceptions import CamoError, UsageError
from camo_core.shutdown import StopFlag
from camo_nodes.topics.names import RunTopics, check_run_id
from camo_nodes.topics.runs import run_ended
from camo_nodes.topics.startup import add_network_options, network_env, start_ros

DEFAULT_PORT = 8765


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
        self, run: RunTopics, host: str = "127.0.0.1", port: int = DEFAULT_PORT, **kwargs
    ) -> None:
        super().__init__("view", namespace=run.swarm_namespace, **kwargs)
        self.run = run
        self.listener = Subscribers()
        try:
            self.server = foxglove.start_server(
                name=f"camo {run.run}",
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
        self.create_timer(0.5, self.discover)
        self.create_timer(0.05, self.follow_clients)
        self.discover()

    @property
    def port(self) -> int:
        return self.server.port

    def discover(self) -> None:
        wanted = lambda name: name.startswith(f"/{self.run.run}/")  # noqa: E731
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

    def follow_clients(self) -> None:
        """Take a topic from ROS while a client is subscribed to it, and only then."""
        while True:
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
                    lambda data, channel=channel: self._forward(channel, data),
                    taking_qos(offered),
                    raw=True,
                )
            elif not count and topic in self.taken:
                self.destroy_subscription(self.taken.pop(topic))

    def _forward(self, channel: foxglove.Channel, data: bytes) -> None:
        channel.log(data, log_time=time.time_ns())
        self.forwarded += 1

    def close(self) -> None:
        self.server.stop()
        for channel in self.channels.values():
            if channel is not None:
                channel.close()
        self.destroy_node()


def main(argv: list[str] | None = None) -> int:
    parser = Parser(prog="camo view", description="a run live in Foxglove (WebSocket)")
    parser.add_argument(
        "--run-id", default=None, help="the run to view (default: the only one in the domain)"
    )
    parser.add_argument(
        "--port", type=int, default=DEFAULT_PORT, help=f"port (default {DEFAULT_PORT}; 0: any)"
    )
    parser.add_argument(
        "--host", default="127.0.0.1", help="address to serve on (default 127.0.0.1; 0.0.0.0: all)"
    )
    parser.add_argument(
        "--wait", type=seconds, default=120.0, help="seconds to wait for a run (default 120)"
    )
    add_network_options(parser)
    try:
        args, ros_args = parser.parse_with_ros_args(argv)
        if not 0 <= args.port <= 65535:
            raise UsageError(f"--port must be in 0..65535 (got {args.port})")
        os.environ.update(network_env(args, os.environ))
        run_id = check_run_id(args.run_id) if args.run_id else None
    except CamoError as exc:
        print(f"camo view: error: {exc}", file=sys.stderr)
        return 2
    stop = StopFlag()
    start_ros("camo view", ros_args, signal_handler_options=SignalHandlerOptions.NO)
    foxglove.set_log_level("WARN")
    node = None
    executor = EventsExecutor()
    try:
        wanted = f"run {run_id}" if run_id else "the only run in the domain"
        print(f"camo view: waiting for {wanted} (up to {args.wait:g} s)", file=sys.stderr)
        run = join(executor, run_id, args.wait, stop)
        node = ViewNode(run, args.host, args.port)
        executor.add_node(node)
        print(
            f"camo view: run {run.run} on ws://{args.host}:{node.port} (Foxglove: Open "
            f"connection, Foxglove WebSocket); Ctrl-C to stop",
            file=sys.stderr,
        )
        ended = run_ended(node, run)
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
            print(f"camo view: forwarded {node.forwarded} messages", file=sys.stderr)
            node.close()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
