"""One robot of the swarm as an rclpy node: an adapter around its step protocol.

The protocol (camo_core.algorithm.protocol) decides when the robot steps and what it
sends; this node only carries events in and output out: messages its
process's transport delivers, clock ticks, new backgrounds; messages to send,
statuses to report, warnings to log. Its sensor and display are objects handed
to it (the projected image and nothing, or a real Droplet's sensor and LED).
Robots hosted by one process share that process's DDS readers and writers
(`transport.py`); each is still a node of its own in the ROS graph.

`robot_node` (console script) runs one robot alone in its own process.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable

import rclpy
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from camo_core.algorithm.layout import layout_for, sense_at
from camo_core.algorithm.params import CamoParams, ParameterError
from camo_core.algorithm.protocol import StepProtocol
from camo_core.algorithm.robot_io import NOTHING, Display, Message, Output, Sensor
from camo_core.algorithm.sensing import ProjectedSensor, Projection
from camo_core.cli.options import layout_options, node_help, wants_help
from camo_core.exceptions import CamoError
from camo_core.shutdown import StopFlag
from camo_nodes.host import Host, host_node
from camo_nodes.topics import (
    LEAN_NODE,
    RunTopics,
    node_parameters,
    run_ended,
    run_from_parameter,
    start_ros,
)
from camo_nodes.transport import Transport


class NoParameterEvents:
    """Stands in for the /parameter_events writer rclpy gives every node: a hosted robot has no
    parameters to change, and thousands of writers nobody reads cost discovery and teardown."""

    def publish(self, msg) -> None:
        pass


class RobotNode(Node):
    def __init__(
        self,
        protocol: StepProtocol,
        transport: Transport,
        clock: Callable[[], float] = time.monotonic,
        **node_kwargs,
    ) -> None:
        core = protocol.core
        name = f"robot_{core.row}_{core.col}"
        self._lean = node_kwargs.get("start_parameter_services") is False
        super().__init__(name, namespace=transport.topics.robot_namespace, **node_kwargs)
        self.protocol = protocol
        self.transport = transport
        self.clock = clock
        transport.add(core.id, list(protocol.listens_to()), self.deliver)

    def create_publisher(self, msg_type, topic, *args, **kwargs):
        if topic == "/parameter_events" and self._lean:
            return NoParameterEvents()
        return super().create_publisher(msg_type, topic, *args, **kwargs)

    @property
    def done(self) -> bool:
        return self.protocol.done

    def start(self) -> None:
        """Say hello and begin. A process hosting many robots creates them all first, then starts
        them, so that no robot's deadline runs while its process is still creating nodes."""
        self._emit(self.protocol.start(self.clock()))

    def deliver(self, message: Message) -> None:
        self._emit(self.protocol.deliver(message, self.clock()))

    def tick(self, now: float) -> None:
        self._emit(self.protocol.tick(now))

    def background(self, now: float) -> None:
        self._emit(self.protocol.background(now))

    def _emit(self, out: Output) -> None:
        if out is NOTHING:
            return
        for warning in out.warnings:
            self.get_logger().warning(warning)
        for report in out.reports:
            self.transport.report(report)
        for message in out.send:
            self.transport.send(message)


# Between phase changes a robot reports every 0.25 s at most, and a process's robots together
# about 2000 times a second at most: the monitor and the recorder take every status.
REPORT_PERIOD = 0.25
REPORTS_PER_PROCESS = 2000.0

ROBOT_PARAMETERS = {
    "rows": 8,
    "cols": 8,
    "row": 0,
    "col": 0,
    "profile": "paper",
    "seed": 0,
    "rho_meas": 0.0,
    "rho_comm": 0.0,
    "threshold": 50.0,
    "threshold_auto": False,
    "orientation": "axes",
    "levels": 0,
    "layout": "",
    "consensus_steps": -1,
    "formation_steps": -1,
    "step_timeout": 10.0,
    "discovery_timeout": 300.0,
    "run_id": "",
}


def projected_on(params: CamoParams):
    """How a projected image becomes the robots' greys: None (block means), or on a layout the
    means round their positions."""
    if not params.layout:
        return None
    layout = layout_for(params)
    shape = (params.rows, params.cols)
    return lambda image: sense_at(image, layout, params.profile).reshape(shape)


def params_from_values(values: dict) -> tuple[CamoParams, int, int, float, float]:
    """A standalone robot's ROS parameters as (params, row, col, step timeout, discovery timeout);
    raises ParameterError."""
    params = CamoParams(
        profile=values["profile"],
        **layout_options(values["layout"], values["rows"], values["cols"]),
        threshold=values["threshold"],
        threshold_auto=values["threshold_auto"],
        orientation=values["orientation"],
        levels=values["levels"],
        seed=values["seed"],
        rho_meas=values["rho_meas"],
        rho_comm=values["rho_comm"],
        consensus_steps=None if values["consensus_steps"] < 0 else values["consensus_steps"],
        formation_steps=None if values["formation_steps"] < 0 else values["formation_steps"],
    )
    if not (0 <= values["row"] < params.rows and 0 <= values["col"] < params.cols):
        raise ParameterError(
            f"cell ({values['row']}, {values['col']}) is outside the "
            f"{params.rows}x{params.cols} grid"
        )
    for name in ("step_timeout", "discovery_timeout"):
        if not values[name] > 0:
            raise ParameterError(f"{name} must be positive (got {values[name]})")
    return (
        params,
        values["row"],
        values["col"],
        values["step_timeout"],
        values["discovery_timeout"],
    )


def robot_parameters(defaults: dict, stop, check=None) -> tuple:
    """A standalone robot's parameters: (params, row, col, step timeout, discovery timeout, run
    topics, every value). They are read twice: first as `robot_parameters` (`/**` keys), which
    says the cell and the run, then as the robot's own node /<run>/camo/robot_<row>_<col>, so
    that keys naming it in a parameters file apply too. `check(values)` raises ParameterError
    for what the caller cannot use."""
    reader = Node("robot_parameters", **LEAN_NODE)
    try:
        values = node_parameters(reader, defaults)
        _, row, col, *_ = params_from_values(values)
        if check is not None:
            check(values)  # before waiting for a run: a bad value is said at once
        topics = run_from_parameter(reader, stop)
    finally:
        reader.destroy_node()
    named = Node(f"robot_{row}_{col}", namespace=topics.robot_namespace, **LEAN_NODE)
    try:
        values = node_parameters(named, defaults)
    finally:
        named.destroy_node()
    params, *cell_and_timeouts = params_from_values(values)
    if tuple(cell_and_timeouts[:2]) != (row, col):
        raise ParameterError(f"robot_{row}_{col}'s parameters give it another cell")
    return (params, *cell_and_timeouts, topics, values)


def host_robots(
    params: CamoParams,
    topics: RunTopics,
    tiles: list[tuple[int, int]],
    step_timeout: float,
    discovery_timeout: float,
    lean: bool = True,
    sensors: dict[int, Sensor] | None = None,
    displays: dict[int, Display] | None = None,
    setup: dict | None = None,
) -> Host:
    """This process's robots (tiles of robot ids), ready to run: a projected-image sensor
    unless `sensors` names another (a Droplet's); `lean` robots have no services of their own."""
    node = host_node(topics)
    transport = Transport(node, params, topics, tiles, setup)
    projection = Projection(params.rows, params.cols, params.profile, projected_on(params))
    robots = []
    for cell in sorted(transport.hosted):
        row, col = divmod(cell, params.cols)
        sensor = (sensors or {}).get(cell) or ProjectedSensor(projection, row, col)
        display = (displays or {}).get(cell)
        protocol = StepProtocol(
            params,
            row,
            col,
            sensor,
            display,
            step_timeout,
            discovery_timeout,
            transport.hosts,
            max(REPORT_PERIOD, len(transport.hosted) / REPORTS_PER_PROCESS),
        )
        robots.append(RobotNode(protocol, transport, **(LEAN_NODE if lean else {})))
    return Host(node, transport, projection, robots, spin_robots=not lean)


def main(args=None) -> int:
    """A single robot in its own process: parameters rows, cols, row, col, profile, seed,
    rho_*..."""
    if wants_help(args):
        print(node_help("robot_node", "One robot of the camouflage swarm.", ROBOT_PARAMETERS))
        return 0
    stop = StopFlag()
    start_ros(
        "robot_node", args, node_options=True, signal_handler_options=SignalHandlerOptions.NO
    )
    try:
        params, row, col, step_timeout, discovery_timeout, topics = robot_parameters(
            ROBOT_PARAMETERS, stop
        )[:6]
        cell = row * params.cols + col
        host = host_robots(params, topics, [(cell, cell)], step_timeout, discovery_timeout, False)
        return host.run(stop, until=run_ended(host.node, topics))
    except CamoError as exc:
        print(f"robot_node: error: {exc}", file=sys.stderr)
        return 2
    finally:
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
