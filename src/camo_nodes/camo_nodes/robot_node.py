"""One robot of the swarm as an rclpy node: an adapter around its step protocol.

The protocol (camo_core.swarm.protocol) decides when the robot steps and what it
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
from dataclasses import dataclass

import rclpy
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from camo_core.algorithm.modes import modes_of
from camo_core.algorithm.params import MAX_SIDE, CamoParams, ParameterError
from camo_core.algorithm.sensing import ProjectedSensor, Projection
from camo_core.exceptions import CamoError
from camo_core.schema import param
from camo_core.shutdown import StopFlag
from camo_core.swarm.protocol import DUE_ONLY_LATER, StepProtocol
from camo_core.swarm.robot_io import NOTHING, Display, Output, Sensor
from camo_core.swarm.run_setup import ProtocolParams, RunSetup
from camo_nodes.host import Host, host_node
from camo_nodes.topics.names import RunTopics
from camo_nodes.topics.parameters import (
    JoinParams,
    declarations,
    node_parameters,
    parameters_help,
)
from camo_nodes.topics.runs import run_ended, run_from_parameter
from camo_nodes.topics.startup import (
    GROUPED_NODE,
    LEAN_NODE,
    Participants,
    node_help,
    start_ros,
    wants_help,
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
        # Looked up once: used every step.
        self._send_message, self._report_status = transport.send, transport.report
        self.clock = clock
        # Its host's tick schedule, told when the robot stepped: a step can bring its deadline
        # nearer (out of discovery, whose timeout is longer).
        self.stepped: Callable[[float], None] = lambda now: None
        self._phase_told: int | None = None  # the phase it was in when it last told it
        # Its host's watch, told when the robot joined a round (continuous camouflage).
        self.joined: Callable[[int], None] = lambda round_: None
        self._round_told = protocol.round
        # The transport keeps the robot's messages in the mailbox its robots share, wakes the
        # protocol when one came for it, and hands what the protocol answers to this node.
        transport.add(core.id, protocol.listens_to(), protocol.wake, self._emit)

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
        now = self.clock()
        self._emit(self.protocol.start(now), now)

    def report_now(self, now: float) -> None:
        self._emit(self.protocol.report_now(now), now)

    def tick(self, now: float) -> None:
        self._emit(self.protocol.tick(now), now)

    def background(self, now: float, frame: int = 0) -> None:
        self._emit(self.protocol.background(now, frame), now)

    def notice(self, frame: int, now: float) -> None:
        self._emit(self.protocol.notice(frame, now), now)

    def _emit(self, out: Output, now: float) -> None:
        if out is NOTHING:
            return
        protocol = self.protocol
        if protocol.round != self._round_told:
            self._round_told = protocol.round
            self.joined(protocol.round)
        phase = protocol.phase
        if phase != self._phase_told or phase not in DUE_ONLY_LATER:
            # Within consensus and formation its due only moves later: the schedule, told on
            # entering the phase, ticks it at the earlier due and queues it again (ticks.py).
            self._phase_told = phase
            self.stepped(now)
        for warning in out.warnings:
            self.get_logger().warning(warning)
        for report in out.reports:
            self._report_status(report)
        send = self._send_message
        for message in out.send:
            send(message)


# Between phase changes a robot reports every 0.25 s at most, and a process's robots together
# about 2000 times a second at most: the monitor and the recorder take every status.
REPORT_PERIOD = 0.25
REPORTS_PER_PROCESS = 2000.0


@dataclass(frozen=True)
class RobotCell:
    """Where a robot alone stands."""

    row: int = param(0, "the robot's row", low=0, high=MAX_SIDE - 1)
    col: int = param(0, "the robot's column", low=0, high=MAX_SIDE - 1)


# A robot node's ROS parameters: the run's, the protocol's, its cell and the run it joins.
ROBOT_PARAMETERS = (CamoParams, ProtocolParams, RobotCell, JoinParams)


def projected_on(params: CamoParams):
    """How a projected image becomes the robots' greys and colours: (None, None) for block
    means, or on a layout the means round their positions."""
    layout = modes_of(params).layout
    if layout.grid:
        return None, None
    return (
        lambda image: layout.sense_greys(image, params.profile),
        lambda image: layout.sense_colours(image),
    )


@dataclass(frozen=True)
class RobotSetup:
    """A robot alone, as its ROS parameters describe it."""

    params: CamoParams
    protocol: ProtocolParams
    cell: RobotCell


def robot_setup(values: dict) -> RobotSetup:
    """A standalone robot's ROS parameters, checked (ParameterError in one line)."""
    declared = declarations(CamoParams)
    params = CamoParams.from_options(**{k: v for k, v in values.items() if k in declared})
    protocol = ProtocolParams(**{k: values[k] for k in declarations(ProtocolParams)})
    cell = RobotCell(values["row"], values["col"])
    if not (cell.row < params.rows and cell.col < params.cols):
        raise ParameterError(
            f"cell ({cell.row}, {cell.col}) is outside the {params.rows}x{params.cols} grid"
        )
    return RobotSetup(params, protocol.for_swarm(params.count), cell)


def robot_parameters(stop, check=None, classes: tuple = ()) -> tuple[RobotSetup, RunTopics, dict]:
    """A standalone robot's parameters: (its setup, run topics, every value). They are read
    twice: first as `robot_parameters` (`/**` keys), which says the cell and the run, then as
    the robot's own node /<run>/camo/robot_<row>_<col>, so that keys naming it in a parameters
    file apply too. `classes` declare more parameters (a bridge's); `check(values)` raises
    ParameterError for what the caller cannot use."""
    classes = (*ROBOT_PARAMETERS, *classes)
    reader = Node("robot_parameters", **LEAN_NODE)
    try:
        values = node_parameters(reader, *classes)
        cell = robot_setup(values).cell
        if check is not None:
            check(values)  # before waiting for a run: a bad value is said at once
        topics = run_from_parameter(reader, stop)
    finally:
        reader.destroy_node()
    named = Node(f"robot_{cell.row}_{cell.col}", namespace=topics.robot_namespace, **LEAN_NODE)
    try:
        values = node_parameters(named, *classes)
    finally:
        named.destroy_node()
    setup = robot_setup(values)
    if setup.cell != cell:
        raise ParameterError(f"robot_{cell.row}_{cell.col}'s parameters give it another cell")
    return setup, topics, values


def host_robots(
    params: CamoParams,
    protocol: ProtocolParams,
    topics: RunTopics,
    tiles: list[tuple[int, int]],
    lean: bool = True,
    sensors: dict[int, Sensor] | None = None,
    displays: dict[int, Display] | None = None,
    setup: RunSetup | None = None,
    created: Callable[[int], None] | None = None,
) -> Host:
    """This process's robots (tiles of robot ids), ready to run: a projected-image sensor
    unless `sensors` names another (a Droplet's); `lean` robots have no services of their own.
    `setup`: the run's, as its launcher published it (which tiles and backgrounds it has);
    `created(count)`: told every 1024 robot nodes created (thousands take a while). Lean robot
    nodes are spread over DDS participants (`Participants`): one participant's node creation
    grows with the square of its nodes."""
    node = host_node(topics)
    protocol = protocol.for_swarm(params.count)
    transport = Transport(node, params, topics, tiles, setup, protocol.step_timeout)
    projection = Projection(params.rows, params.cols, params.profile, *projected_on(params))
    robots, hardware = [], []
    participants = Participants(node.context)
    for cell in sorted(transport.hosted):
        row, col = divmod(cell, params.cols)
        sensor = (sensors or {}).get(cell) or ProjectedSensor(projection, row, col)
        display = (displays or {}).get(cell)
        if cell in (sensors or {}) or display is not None:
            hardware.append(len(robots))
        steps = StepProtocol(
            params,
            row,
            col,
            sensor,
            display,
            protocol.step_timeout,
            protocol.discovery_timeout,
            transport.alive,
            max(REPORT_PERIOD, len(transport.hosted) / REPORTS_PER_PROCESS),
            transport.mailbox,
        )
        if protocol.continuous:
            steps.watching()
        node_kwargs = {**LEAN_NODE, **GROUPED_NODE, "context": participants.next()} if lean else {}
        robots.append(RobotNode(steps, transport, **node_kwargs))
        if created is not None and len(robots) % 1024 == 0:
            created(len(robots))
    return Host(
        node, transport, projection, robots, not lean, tuple(hardware), participants, protocol
    )


def main(args=None) -> int:
    """A single robot in its own process (its ROS parameters: `./camo robot --help`)."""
    if wants_help(args):
        about = "One robot of the camouflage swarm."
        print(node_help("robot_node", about, parameters_help(*ROBOT_PARAMETERS)))
        return 0
    stop = StopFlag()
    start_ros(
        "robot_node", args, node_options=True, signal_handler_options=SignalHandlerOptions.NO
    )
    try:
        robot, topics, _ = robot_parameters(stop)
        params, cell = robot.params, robot.cell
        robot_id = cell.row * params.cols + cell.col
        host = host_robots(params, robot.protocol, topics, [(robot_id, robot_id)], lean=False)
        return host.run(stop, until=run_ended(host.node, topics))
    except CamoError as exc:
        print(f"robot_node: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # Ctrl-C or SIGTERM while it waited for its run
        return 0
    finally:
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
