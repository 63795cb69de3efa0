"""`./camo worker --cells FIRST-LAST`: a process hosting robots of a run, here or elsewhere.

It joins the run with `--run-id` (or the only run in its domain and network),
takes the run's parameters from the run itself (its latched /<run>/swarm/params,
published by the launcher), hosts the robots it is given and exits 0 when the
run's launcher is gone. The launcher starts its own workers the same way; a
second machine needs only a clone and this command line, for cells the run
left to remote workers (`./camo run --remote-cells FIRST-LAST`).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import rclpy
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from camo_core.algorithm.params import MAX_SIDE
from camo_core.cli.options import Parser, parse_ranges, seconds
from camo_core.exceptions import CamoError, UsageError
from camo_core.shutdown import StopFlag
from camo_core.swarm.run_setup import RunSetup
from camo_msgs.msg import Host as HostMsg
from camo_nodes.polled import PolledTopics
from camo_nodes.robot_node import host_robots
from camo_nodes.topics.names import RunTopics, check_run_id
from camo_nodes.topics.qos import LATCHED_READER
from camo_nodes.topics.runs import run_ended, wait_for_run, wait_for_setup
from camo_nodes.topics.startup import LEAN_NODE, add_network_options, network_env, start_ros
from camo_nodes.trust import Hosts, Rejections


def build_parser() -> Parser:
    parser = Parser(prog="camo worker", description="host robots of a running swarm")
    parser.add_params_file_option("camo_worker")
    parser.add_argument(
        "--cells",
        action="append",
        required=True,
        metavar="FIRST-LAST",
        help="robot ids to host, row-major, inclusive (repeatable)",
    )
    parser.add_argument("--run-id", default=None, help="the run to join (default: the only one)")
    parser.add_argument(
        "--wait", type=seconds, default=120.0, help="seconds to wait for the run (default 120)"
    )
    add_network_options(parser)
    # The launcher's own workers: the run's setup from it, not from the network, and cells it
    # keeps for itself.
    parser.add_argument("--setup", default=None, help=argparse.SUPPRESS)
    # ... and a file to create once its robot nodes exist (the launcher defers discovery).
    parser.add_argument("--ready", default=None, help=argparse.SUPPRESS)
    return parser


def tiles_for(setup: RunSetup, texts: list[str], launched: bool):
    """The tiles to host; a worker started by hand may host only cells left to remote workers."""
    tiles = parse_ranges(texts, setup.params.count)
    if launched:
        return tiles
    remote = setup.remote
    for first, last in tiles:
        if not any(a <= first and last <= b for a, b in remote):
            left = ", ".join(f"{a}-{b}" for a, b in remote) or "none"
            raise UsageError(
                f"run {setup.run}: cells {first}-{last} are not left to remote workers by this "
                f"run (its --remote-cells: {left})"
            )
    return tiles


class Hosted(CamoError):
    """Cells another process hosts already: every process of the run trusts their first host."""


class _Quiet:
    def warning(self, line: str) -> None:
        pass  # what the hosts topic holds besides announcements is not this worker's business


def refuse_hosted(node: Node, topics: RunTopics, setup: RunSetup, tiles, stop, settle=(1.0, 5.0)):
    """Hosted if another process's announcement of any of `tiles` is heard (they are latched:
    the run's processes and strangers alike have said theirs): listened to for `settle[0]`
    seconds, and on until every writer of announcements the graph shows was heard, for
    `settle[1]` at most."""
    hosts = Hosts(setup.params.count, Rejections(_Quiet()), setup)
    polled = PolledTopics("worker_join_hosts", topics.robot_namespace, run=topics.run)

    def learn(data: bytes, gid: bytes) -> None:
        msg = hosts.rejections.decoded(data, HostMsg, gid, "an announcement")
        if msg is not None:
            hosts.learn(msg, gid)

    polled.listen(HostMsg, topics.hosts, LATCHED_READER, learn)
    started = time.monotonic()
    try:
        while not stop:
            polled.poll()
            rclpy.spin_once(node, timeout_sec=0.05)
            waited = time.monotonic() - started
            heard_all = len(hosts.names) >= node.count_publishers(topics.hosts)
            if waited > settle[1] or (waited > settle[0] and heard_all):
                break
    finally:
        polled.close()
    conflict = hosts.held_by_others(tiles, lambda prefix: False)
    if conflict is not None:
        raise Hosted(
            f"run {topics.run}: cells {conflict.cells} are hosted already by another process "
            f"({conflict.process}); a cell has one host"
        )


def join(node: Node, args, stop) -> tuple[RunTopics, RunSetup]:
    def spin() -> None:
        rclpy.spin_once(node, timeout_sec=0.1)

    run_id = check_run_id(args.run_id) if args.run_id is not None else None
    print(
        f"camo worker: waiting for {'run ' + run_id if run_id else 'a run'} "
        f"(up to {args.wait:g} s; Ctrl-C to stop)",
        file=sys.stderr,
        flush=True,
    )
    topics = RunTopics(wait_for_run(node, spin, run_id, args.wait, stop))
    return topics, wait_for_setup(node, spin, topics, args.wait, stop)


def main(argv: list[str] | None = None) -> int:
    stop = StopFlag()
    try:
        args, ros_args = build_parser().parse_with_ros_args(argv)
        parse_ranges(args.cells, MAX_SIDE**2)  # FIRST <= LAST, inside the largest grid: up front
        os.environ.update(network_env(args, os.environ))
    except CamoError as exc:
        print(f"camo worker: error: {exc}", file=sys.stderr)
        return 2
    start_ros("camo worker", ros_args, signal_handler_options=SignalHandlerOptions.NO)
    try:
        launched = args.setup is not None
        if launched:
            setup = RunSetup.from_json(args.setup)
            topics = RunTopics(check_run_id(setup.run))
            tiles = tiles_for(setup, args.cells, launched)
        else:
            finder = Node("worker_join", **LEAN_NODE)
            try:
                topics, setup = join(finder, args, stop)
                tiles = tiles_for(setup, args.cells, launched)
                refuse_hosted(finder, topics, setup, tiles, stop)
            finally:
                finder.destroy_node()
        progress = Path(f"{args.ready}.count") if args.ready else None
        host = host_robots(
            setup.params,
            setup.protocol,
            topics,
            tiles,
            setup=setup,
            created=progress and (lambda count: progress.write_text(str(count))),
        )
        if args.ready:
            Path(args.ready).touch()
        if not launched:
            cells = ", ".join(f"{a}-{b}" for a, b in tiles)
            print(f"camo worker: hosting robots {cells} of {topics.run}", file=sys.stderr)
        ended = run_ended(host.node, topics)
        # A worker by hand whose cells another process announces too leaves (its launcher, for
        # a worker it started, ends the run: session.py).
        contested = lambda: not launched and host.transport.conflict is not None  # noqa: E731
        code = host.run(stop, until=lambda: ended() or contested(), destroy=False)
        if contested():
            conflict = host.transport.conflict
            print(
                f"camo worker: error: run {topics.run}: cells {conflict.cells} were announced by "
                f"another process too ({conflict.process}); a cell has one host: stopping",
                file=sys.stderr,
            )
            code = 2
        elif not launched and not stop:
            print(f"camo worker: {topics.run} has ended", file=sys.stderr)
        # At once: tearing thousands of robot nodes down one by one takes longer than the run's
        # end allows, and the process's exit frees them all (its shared-memory files, left
        # behind, are removed as stale by the next camo process: shm.py).
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    except CamoError as exc:
        print(f"camo worker: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    finally:
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
