"""A process that hosts many robot nodes in one executor (started by the launcher)."""

from __future__ import annotations

import argparse
import json
import os
import sys

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import Image

from camo_core.params import CamoParams
from camo_msgs.msg import RobotStatus
from camo_projector.qos import BACKGROUND_TOPIC, LATCHED

from .robot_node import MESSAGE_TYPES, RobotNode, inputs
from .shutdown import StopFlag
from .topics import STATUS_TOPIC, history_qos, robot_topic

# Hosted robots need no parameter, rosout or type-description services: fewer DDS entities.
LEAN_NODE = {
    "start_parameter_services": False,
    "enable_rosout": False,
    "parameter_overrides": [Parameter("start_type_description_service", value=False)],
}


class Hub(Node):
    """One subscription per neighbour topic for all the robots of this process.

    Each robot still publishes on its own topics; what its neighbours publish is
    received once here and handed to every local robot that listens to it, in
    that robot's slot. This keeps a process's DDS entities near 5 per robot
    instead of 40, and entity set-up time grows with their square.
    """

    def __init__(self, params: CamoParams, robots: int) -> None:
        super().__init__(f"swarm_worker_{os.getpid()}", namespace="/camo", **LEAN_NODE)
        self.qos = history_qos(max(params.consensus_steps, params.formation_steps) + 4)
        statuses = (params.consensus_steps + params.formation_steps + 8) * robots
        self.status_pub = self.create_publisher(RobotStatus, STATUS_TOPIC, history_qos(statuses))
        self.listeners: dict[tuple[int, str], list[tuple[RobotNode, int]]] = {}
        self.robots: list[RobotNode] = []
        self.create_subscription(Image, BACKGROUND_TOPIC, self._on_background, LATCHED)

    def register(self, robot: RobotNode) -> None:
        self.robots.append(robot)
        for slot, kind in inputs(robot.core.neighbors):
            key = (robot.core.neighbors[slot], kind)
            if key not in self.listeners:
                self.listeners[key] = []
                self.create_subscription(
                    MESSAGE_TYPES[kind],
                    robot_topic(key[0], kind),
                    lambda msg, k=key: self._dispatch(k, msg),
                    self.qos,
                )
            self.listeners[key].append((robot, slot))

    def _dispatch(self, key: tuple[int, str], msg) -> None:
        for robot, slot in self.listeners[key]:
            robot._on_message(key[1], slot, msg)

    def _on_background(self, msg: Image) -> None:
        for robot in self.robots:
            robot._on_background(msg)


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
    executor = None
    try:
        executor = events_executor()
        cells = [int(c) for c in args.cells.split(",") if c]
        hub = Hub(params, len(cells))
        nodes.append(hub)
        executor.add_node(hub)
        for robot in cells:
            row, col = divmod(robot, params.cols)
            node = RobotNode(
                params,
                row,
                col,
                step_timeout=args.step_timeout,
                discovery_timeout=args.discovery_timeout,
                autostart=False,
                hub=hub,
                **LEAN_NODE,
            )
            nodes.append(node)
            executor.add_node(node)
        for node in nodes[1:]:
            node.start()
        # spin_once in a loop: EventsExecutor.spin() busy-waits and starves its timers here.
        while not stop and rclpy.ok():
            executor.spin_once(timeout_sec=0.2)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if executor is not None:
            executor.shutdown()
            for node in nodes:
                executor.remove_node(node)
        for node in nodes:
            node.destroy_node()
        executor = None
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
