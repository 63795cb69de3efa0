"""`./camo topic list|echo|hz` and `./camo node list`: stand-ins for ros2cli, which PyPI lacks.

They follow ros2cli's arguments and output (`ros2 topic list -t`, `ros2 topic echo TOPIC
--once`, `ros2 topic hz TOPIC --window N`, `ros2 node list`), built on rclpy's graph API. With
Docker, the image's own `ros2` is the real thing.
"""

from __future__ import annotations

import itertools
import math
import os
import statistics
import sys
import time

import rclpy
import yaml
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from rclpy.signals import SignalHandlerOptions

from camo_bag import msgdefs
from camo_bag.graph_topics import taking_qos
from camo_core.cli.options import Parser, seconds
from camo_core.exceptions import CamoError, UsageError
from camo_core.shutdown import StopFlag, quiet_on_a_closed_pipe
from camo_nodes.topics.startup import add_network_options, network_env, start_ros

# Before listing: at least DISCOVERY s for the graph to fill (ros2cli's daemon keeps it filled),
# then until it has not changed for SETTLED s, MAX_DISCOVERY s at most (a loaded machine is slow).
DISCOVERY, SETTLED, MAX_DISCOVERY = 2.0, 1.0, 8.0


def as_plain(message, no_arr: bool = False):
    """A message as YAML-ready values, as ros2 topic echo prints it."""
    if hasattr(message, "get_fields_and_field_types"):
        return {
            name: as_plain(getattr(message, name), no_arr)
            for name in message.get_fields_and_field_types()
        }
    if isinstance(message, bytes | bytearray) or hasattr(message, "tolist"):
        values = list(message.tolist() if hasattr(message, "tolist") else message)
        return f"<array length: {len(values)}>" if no_arr else values
    if isinstance(message, list | tuple):
        if no_arr:
            return f"<sequence length: {len(message)}>"
        return [as_plain(item, no_arr) for item in message]
    if isinstance(message, float) and not math.isfinite(message):
        return str(message)
    return message


def wait_for_graph(node: Node) -> None:
    started = changed = time.monotonic()
    seen = None
    while True:
        rclpy.spin_once(node, timeout_sec=0.05)
        now = time.monotonic()
        nodes = node.get_node_names_and_namespaces()
        graph = (node.get_topic_names_and_types(), nodes)
        if graph != seen:
            seen, changed = graph, now
        others = any(name != node.get_name() for name, _ in nodes)
        waited = now - started
        # A graph of nobody but this tool has not settled: it has not been heard yet.
        if waited > MAX_DISCOVERY or (others and waited > DISCOVERY and now - changed > SETTLED):
            return


def topic_type(node: Node, topic: str, wait: float) -> str:
    deadline = time.monotonic() + wait
    while True:
        for name, types in node.get_topic_names_and_types():
            if name == topic:
                return types[0]
        if time.monotonic() > deadline:
            raise UsageError(f"topic {topic} does not appear to be published yet")
        rclpy.spin_once(node, timeout_sec=0.1)


def topic_list(node: Node, args) -> int:
    wait_for_graph(node)
    topics = sorted(node.get_topic_names_and_types())
    if args.count_topics:
        print(len(topics))
        return 0
    for name, types in topics:
        print(f"{name} [{', '.join(types)}]" if args.show_types else name)
    return 0


def subscribe(node: Node, topic: str, wait: float, callback):
    type_name = topic_type(node, topic, wait)
    cls = msgdefs.message_class(type_name)
    offered = [p.qos_profile for p in node.get_publishers_info_by_topic(topic)]
    qos = taking_qos(offered) if offered else 10
    return node.create_subscription(cls, topic, callback, qos, raw=True), cls


def topic_echo(node: Node, args, stop) -> int:
    seen = [0]
    cls_box = []

    def show(data: bytes) -> None:
        message = deserialize_message(data, cls_box[0])
        text = yaml.safe_dump(as_plain(message, args.no_arr), sort_keys=False)
        print(text + "---", flush=True)
        seen[0] += 1

    _, cls = subscribe(node, args.topic, args.wait, show)
    cls_box.append(cls)
    while not stop and rclpy.ok():
        rclpy.spin_once(node, timeout_sec=0.1)
        if seen[0] and args.once:
            break
    return 0


def topic_hz(node: Node, args, stop) -> int:
    arrivals: list[float] = []

    def tick(_data: bytes) -> None:
        arrivals.append(time.monotonic())
        del arrivals[: -args.window - 1]

    subscribe(node, args.topic, args.wait, tick)
    printed = time.monotonic()
    while not stop and rclpy.ok():
        rclpy.spin_once(node, timeout_sec=0.1)
        if time.monotonic() - printed >= 1.0:
            printed = time.monotonic()
            if len(arrivals) < 2:
                print("no new messages", flush=True)
                continue
            gaps = [b - a for a, b in itertools.pairwise(arrivals)]
            mean = statistics.fmean(gaps)
            print(
                f"average rate: {1.0 / mean:.3f}\n\tmin: {min(gaps):.3f}s max: "
                f"{max(gaps):.3f}s std dev: {statistics.pstdev(gaps):.5f}s window: "
                f"{len(gaps)}",
                flush=True,
            )
    return 0


def node_list(node: Node, args) -> int:
    wait_for_graph(node)
    names = sorted(
        f"{ns.rstrip('/')}/{name}"
        for name, ns in node.get_node_names_and_namespaces()
        if name != node.get_name() and (args.all or not name.startswith("_"))
    )
    if args.count_nodes:
        print(len(names))
        return 0
    print("\n".join(names))
    return 0


def build_parser() -> Parser:
    parser = Parser(prog="camo", description="ros2cli stand-ins: topics and nodes of the graph")
    verbs = parser.add_subparsers(dest="what", required=True, parser_class=Parser)
    topic = verbs.add_parser("topic", help="topics: list, echo, hz")
    topic_verbs = topic.add_subparsers(dest="verb", required=True, parser_class=Parser)
    listing = topic_verbs.add_parser("list", help="the topics of the graph")
    listing.add_argument("-t", "--show-types", action="store_true", help="with their types")
    listing.add_argument("-c", "--count-topics", action="store_true", help="only count them")
    echo = topic_verbs.add_parser("echo", help="print a topic's messages as YAML")
    echo.add_argument("topic")
    echo.add_argument("--once", action="store_true", help="one message, then exit")
    echo.add_argument("--no-arr", action="store_true", help="arrays as their length")
    hz = topic_verbs.add_parser("hz", help="a topic's rate, every second")
    hz.add_argument("topic")
    hz.add_argument("-w", "--window", type=int, default=10000, help="messages to average over")
    for sub in (echo, hz):
        sub.add_argument(
            "--wait", type=seconds, default=5.0, help="seconds to wait for the topic (default 5)"
        )
    node = verbs.add_parser("node", help="nodes: list")
    node_verbs = node.add_subparsers(dest="verb", required=True, parser_class=Parser)
    nodes = node_verbs.add_parser("list", help="the nodes of the graph")
    nodes.add_argument("-a", "--all", action="store_true", help="hidden nodes too")
    nodes.add_argument("-c", "--count-nodes", action="store_true", help="only count them")
    for sub in (listing, echo, hz, nodes):
        add_network_options(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    quiet_on_a_closed_pipe()  # `./camo topic echo T | head`
    try:
        args = build_parser().parse_args(argv)
        if getattr(args, "window", 1) < 1:
            raise UsageError(f"--window must be at least 1 (got {args.window})")
        os.environ.update(network_env(args, os.environ))
    except CamoError as exc:
        print(f"camo: error: {exc}", file=sys.stderr)
        return 2
    stop = StopFlag()
    start_ros(f"camo {args.what}", [], signal_handler_options=SignalHandlerOptions.NO)
    # A hidden node (leading _), as ros2cli's own: `node list` leaves it out.
    node = Node(f"_camo_{args.what}_{os.getpid()}", start_parameter_services=False)
    try:
        if args.what == "node":
            return node_list(node, args)
        verb = {"list": topic_list, "echo": topic_echo, "hz": topic_hz}[args.verb]
        return verb(node, args) if args.verb == "list" else verb(node, args, stop)
    except CamoError as exc:
        print(f"camo {args.what} {args.verb}: error: {exc}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, BrokenPipeError):
        return 0
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
