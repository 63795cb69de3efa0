"""A process hosting robots: the background, the clock and the spin loop they share.

Every process with robots runs one Host: a worker started by the launcher, a
robot alone (`robot_node`), a Droplet bridge. It owns one node of its own,
which holds the transport's DDS endpoints (`transport.py`), the background
subscription and the one timer that ticks every robot's protocol.
"""

from __future__ import annotations

import os
import socket
import time

import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import Image

from camo_core.protocol import TICK
from camo_core.sensing import ImageError, Projection
from camo_core.shutdown import StopFlag

from .topics import BACKGROUND_TOPIC, LATCHED, ImageEncodingError, image_from_msg

# Hosted robots need no parameter, rosout or type-description services: fewer DDS entities.
LEAN_NODE = {
    "start_parameter_services": False,
    "enable_rosout": False,
    "parameter_overrides": [Parameter("start_type_description_service", value=False)],
}


def host_node() -> Node:
    """The process's own node: /camo/worker_<host>_<pid>."""
    name = f"worker_{socket.gethostname().split('.')[0]}_{os.getpid()}"
    return Node("".join(c if c.isalnum() else "_" for c in name), namespace="/camo", **LEAN_NODE)


class Host:
    """Robots are duck-typed: start(), tick(now), background(now), and a Node to spin when
    `spin_robots` (robots with services of their own)."""

    def __init__(
        self, node: Node, projection: Projection, robots: list, spin_robots: bool
    ) -> None:
        self.node = node
        self.projection = projection
        self.robots = robots
        self._stamps: set[tuple[int, int]] = set()
        self.spun = [node, *robots] if spin_robots else [node]
        node.create_subscription(Image, BACKGROUND_TOPIC, self._on_background, LATCHED)
        node.create_timer(TICK, self._tick)

    def _on_background(self, msg: Image) -> None:
        stamp = (msg.header.stamp.sec, msg.header.stamp.nanosec)
        if stamp in self._stamps:
            return
        self._stamps.add(stamp)
        try:
            self.projection.add(image_from_msg(msg))
        except (ImageEncodingError, ImageError) as exc:
            self.node.get_logger().error(f"background not used: {exc}")
            return
        now = time.monotonic()
        for robot in self.robots:
            robot.background(now)

    def _tick(self) -> None:
        now = time.monotonic()
        for robot in self.robots:
            robot.tick(now)

    def run(self, stop: StopFlag | None = None, extra_nodes: tuple[Node, ...] = ()) -> int:
        """Start every robot and spin until Ctrl-C, SIGTERM or shutdown."""
        executor = EventsExecutor()
        nodes = [*self.spun, *extra_nodes]
        try:
            for node in nodes:
                executor.add_node(node)
            for robot in self.robots:
                robot.start()
            # spin_once in a loop: EventsExecutor.spin() busy-waits and starves its timers here.
            while not stop and rclpy.ok():
                executor.spin_once(timeout_sec=0.2)
        except KeyboardInterrupt:
            pass
        finally:
            # Executor first, then nodes: the EventsExecutor must let go of the nodes' handles
            # before they are destroyed, or interpreter exit can crash.
            executor.shutdown()
            for node in nodes:
                executor.remove_node(node)
            for node in [*nodes, *(r for r in self.robots if r not in nodes)]:
                node.destroy_node()
        return 0
