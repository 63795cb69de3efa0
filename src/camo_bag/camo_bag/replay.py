"""`./camo replay BAG [--rate R] [--topics ...] [--loop]`: publish a recorded run again.

Messages go out as the raw CDR bytes recorded, at their recorded log times
scaled by 1/R, each topic with the QoS its publishers offered (from the bag's
offered_qos_profiles), so Foxglove, a monitor or a fresh swarm see the run
again. Publishers stay up `--linger` seconds after the last message, so that
latched (transient-local) topics still reach subscribers that join late, and
then until reliable subscribers have acknowledged every message (ACK_WAIT
seconds at most).
"""

from __future__ import annotations

import os
import sys
import time

import rclpy
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from camo_bag import msgdefs, qos_yaml
from camo_bag.container import TopicInfo
from camo_bag.loader import Bag, open_bag
from camo_bag.upgrade import installed, installed_decoder
from camo_core.cli.options import Parser
from camo_core.cli.progress import ProgressBar
from camo_core.exceptions import CamoError, UsageError
from camo_core.shutdown import StopFlag
from camo_nodes.topics import keyed
from camo_nodes.topics.names import check_run_id
from camo_nodes.topics.startup import LEAN_NODE, add_network_options, network_env, start_ros


def build_parser() -> Parser:
    parser = Parser(
        prog="camo replay", description="republish a recorded bag with its timing and QoS"
    )
    parser.add_argument("bag", help="bag folder (or its .mcap file)")
    parser.add_argument(
        "--rate", type=float, default=1.0, help="playback speed factor (default 1)"
    )
    parser.add_argument(
        "--topics", nargs="+", default=None, help="only these topics (default: all)"
    )
    parser.add_argument("--loop", action="store_true", help="start again at the end, until Ctrl-C")
    parser.add_argument(
        "--delay",
        type=float,
        default=1.0,
        help="seconds between creating the publishers and the first message, so that "
        "subscribers are matched first (default 1)",
    )
    parser.add_argument(
        "--linger",
        type=float,
        default=2.0,
        help="seconds to keep publishers up after the last message (default 2)",
    )
    parser.add_argument(
        "--run-id",
        default=None,
        help="publish the bag's run under this run id instead (/<old>/... becomes /<new>/...), "
        "e.g. to drive a fresh swarm with the recorded background",
    )
    add_network_options(parser)
    return parser


def renamed(topic: str, run_id: str | None) -> str:
    """A recorded topic under another run id (topics of the older layout, at the root, keep
    their names)."""
    if run_id is None or topic.count("/") < 3:
        return topic
    return "/" + run_id + "/" + topic.split("/", 2)[2]


ACK_WAIT = 10.0  # s a finished replay waits at most for its messages to be acknowledged


def sleep_until(due: float, stop: StopFlag) -> None:
    while not stop and (left := due - time.monotonic()) > 0:
        time.sleep(min(left, 0.1))


def chosen_topics(args, bag: Bag) -> list[TopicInfo]:
    """The topics to replay: all the bag's usable ones, or those of --topics (UsageError for
    one the bag does not hold, or holds with a schema that cannot be used)."""
    topics = [t for t in bag.summary.topics if args.topics is None or t.name in args.topics]
    for name in sorted(set(args.topics or ()) - {t.name for t in topics}):
        if name in bag.left_out:
            raise UsageError(f"the bag's topic {name} cannot be replayed: {bag.left_out[name]}")
        raise UsageError(f"the bag has no topic {name} (see ./camo bag info {args.bag})")
    return topics


def replay(args, bag: Bag, stop: StopFlag) -> int:
    summary = bag.summary
    topics = chosen_topics(args, bag)
    node = Node("replay", **LEAN_NODE)
    try:
        # With a key (--key-file: the live run's), what the bag holds is published with this
        # run's tags (a bag holds plain CDR, or an encrypted run's ciphertext that this key
        # opens); without one, as recorded, and a keyed run takes none of it.
        publishers = {
            t.name: keyed.publisher(
                node,
                msgdefs.message_class(t.type),
                renamed(t.name, args.run_id),
                qos_yaml.load_first(t.qos, f"{bag.file}: {t.name} offered_qos_profiles"),
                keyed.run_of(renamed(t.name, args.run_id)),
            )
            for t in topics
        }
        # A topic of an older camo's type is decoded through the bag's schema and published as
        # the installed type (upgrade.py); the others as they were recorded.
        decoders = {t.name: installed_decoder(t) for t in topics}
        upgraded = {t.name for t in topics if not installed(t)}
        total = sum(t.count for t in topics)
        passes = 0
        sleep_until(time.monotonic() + args.delay, stop)
        while not stop:
            bar = ProgressBar(total, f"replay x{args.rate:g}")
            start = time.monotonic()
            for message in bag.messages(list(publishers)):
                sleep_until(start + (message.log_time - summary.start_ns) / 1e9 / args.rate, stop)
                if stop:
                    break
                data = message.data  # plain CDR (bag.messages opens an encrypted run's)
                try:  # subscribers would fail on it: left out, and counted
                    decoded = decoders[message.topic](data)
                except Exception:  # noqa: BLE001 - bytes that do not decode as their type
                    bag.reject(message)
                    continue
                if message.topic in upgraded:
                    publishers[message.topic].publish(decoded)
                else:
                    publishers[message.topic].publish(data)
                bar.update(note=message.topic)
            passes += 1
            if not args.loop:
                break
        sleep_until(time.monotonic() + args.linger, stop)
        # Reliable readers get everything before the publishers go (a loaded machine may still
        # be delivering when the linger ends): ACK_WAIT at most, all topics together.
        end = time.monotonic() + ACK_WAIT
        for publisher in publishers.values():
            publisher.wait_for_all_acked(Duration(seconds=max(0.0, end - time.monotonic())))
        if bag.note():
            print(f"camo replay: warning: {bag.note()}", file=sys.stderr)
        print(
            f"camo replay: published {total - bag.rejected_count} messages on "
            f"{len(publishers)} topics"
            f"{f' ({passes} passes)' if passes > 1 else ''}",
            file=sys.stderr,
        )
    finally:
        node.destroy_node()
    return 130 if stop else 0


def main(argv: list[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
        if not 0 < args.rate <= 1000:
            raise UsageError(f"--rate must be in (0, 1000] (got {args.rate})")
        for name in ("delay", "linger"):
            if not 0 <= getattr(args, name) <= 3600:
                raise UsageError(
                    f"--{name} must be in 0..3600 seconds (got {getattr(args, name)})"
                )
        if args.run_id is not None:
            check_run_id(args.run_id)
        env = network_env(args, os.environ)
        bag = open_bag(args.bag)  # a bad bag fails before ROS starts
        for topic in chosen_topics(args, bag):  # so do a topic it lacks and a bad QoS
            qos_yaml.load_first(topic.qos, f"{bag.file}: {topic.name} offered_qos_profiles")
    except CamoError as exc:
        print(f"camo replay: error: {exc}", file=sys.stderr)
        return 2
    os.environ.update(env)
    stop = StopFlag()
    start_ros("camo replay", None, signal_handler_options=SignalHandlerOptions.NO)
    try:
        return replay(args, bag, stop)
    except CamoError as exc:
        print(f"camo replay: error: {exc}", file=sys.stderr)
        return 2
    finally:
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
