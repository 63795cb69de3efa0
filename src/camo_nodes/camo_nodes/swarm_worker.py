"""A process that hosts many robot nodes in one executor (started by the launcher)."""
from __future__ import annotations

import argparse
import json
import sys

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from camo_core.params import CamoParams

from .robot_node import RobotNode
from .shutdown import StopFlag


def events_executor():
    """rclpy's EventsExecutor (about twice as fast with many nodes), else the default one."""
    try:
        from rclpy.experimental import EventsExecutor
    except ImportError:
        return SingleThreadedExecutor()
    return EventsExecutor()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="swarm_worker")
    parser.add_argument("--params", required=True, help="CamoParams as JSON")
    parser.add_argument("--cells", required=True, help="robot ids, comma-separated")
    parser.add_argument("--step-timeout", type=float, default=10.0)
    parser.add_argument("--discovery-timeout", type=float, default=300.0)
    args, ros_args = parser.parse_known_args(argv)
    params = CamoParams(**json.loads(args.params))
    stop = StopFlag()
    rclpy.init(args=ros_args, signal_handler_options=SignalHandlerOptions.NO)
    nodes = []
    try:
        executor = events_executor()
        for robot in (int(c) for c in args.cells.split(",") if c):
            row, col = divmod(robot, params.cols)
            node = RobotNode(params, row, col, step_timeout=args.step_timeout,
                             discovery_timeout=args.discovery_timeout, autostart=False,
                             start_parameter_services=False, enable_rosout=False)
            nodes.append(node)
            executor.add_node(node)
        for node in nodes:
            node.start()
        # spin_once in a loop: EventsExecutor.spin() busy-waits and starves its timers here.
        while not stop and rclpy.ok():
            executor.spin_once(timeout_sec=0.2)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
