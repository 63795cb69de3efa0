"""The hardware bridge: a real Droplet takes the place of one robot (console script
droplet_bridge).

Robot mode (default): a robot node whose sensor is the Droplet's `get_rgb`
(grey by the profile's weights, then the calibration) and whose display is its
LED (`rig.py`); its neighbours cannot tell it from a simulated robot. Its
reading is real, so simulated measurement noise never applies to it. A port
that disappears is reconnected with backoff; meanwhile the robot reports
itself not alive, keeps computing, and sets the LED it missed once the port is
back.

Monitor mode (`monitor:=true`): for a Droplet running the camouflage firmware
itself; its printouts become this cell's RobotStatus messages, so a hardware
run can be watched and recorded like a simulated one. `transcript:=FILE`
reads a recorded printout instead of a port.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path

import rclpy
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from camo_core.algorithm.modes import modes_of
from camo_core.algorithm.params import CamoParams, ParameterError
from camo_core.algorithm.sensing import Calibration
from camo_core.exceptions import CamoError
from camo_core.schema import check_fields, declared, param
from camo_core.shutdown import StopFlag
from camo_core.swarm.protocol import CONSENSUS, NO_PATTERN, SENSING
from camo_core.swarm.status_rows import StatusRows
from camo_droplet.firmware import FirmwareState
from camo_droplet.link import DropletDisconnected, DropletError, DropletLink
from camo_droplet.rig import DropletLed, DropletSensor, Reconnector, parse_rgb
from camo_msgs.msg import Host, RobotStatus, StatusArray
from camo_nodes.robot_node import (
    ROBOT_PARAMETERS,
    RobotSetup,
    host_robots,
    robot_parameters,
    robot_setup,
)
from camo_nodes.topics import keyed
from camo_nodes.topics.names import RunTopics
from camo_nodes.topics.parameters import parameters_help
from camo_nodes.topics.qos import LATCHED, history_qos
from camo_nodes.topics.runs import run_ended
from camo_nodes.topics.startup import node_help, start_ros, wants_help


@dataclass(frozen=True)
class BridgeParams:
    """A bridge's own ROS parameters (besides a robot node's)."""

    port: str = param("", "the Droplet's serial port, e.g. /dev/ttyUSB0")
    monitor: bool = param(False, "watch a Droplet that runs the camouflage firmware itself")
    transcript: str = param("", "read a recorded printout of the firmware instead of a port")
    calibration: str = param("", "a YAML file of the gain and offset of the grey reading")
    gain: float = param(1.0, "gain of the grey reading (without a calibration file)")
    offset: float = param(0.0, "offset of the grey reading (without a calibration file)")
    led_on: str = param("255 0 0", "the LED's colour for state on (R G B)")
    led_off: str = param("255 255 255", "the LED's colour for state off (R G B)")
    serial_timeout: float = param(0.5, "seconds to wait for an answer", low=0.0, above=True)
    retries: int = param(3, "times a command is retried", low=0, high=100)

    def __post_init__(self) -> None:
        check_fields(self)

    @classmethod
    def from_values(cls, values: dict) -> BridgeParams:
        return cls(**{name: values[name] for name in declared(cls)})


class DropletMonitorNode(Node):
    """A Droplet running the camouflage firmware, watched: its printouts as this cell's
    statuses."""

    def __init__(
        self,
        params: CamoParams,
        topics: RunTopics,
        row: int,
        col: int,
        link: DropletLink | None = None,
        transcript: Path | None = None,
        **kwargs,
    ) -> None:
        name = f"droplet_monitor_{row}_{col}"
        super().__init__(name, namespace=topics.robot_namespace, **kwargs)
        self.params, self.row, self.col = params, row, col
        self.link = link
        self.lines = (
            list(Path(transcript).read_text(errors="replace").splitlines()) if transcript else None
        )
        self.state: FirmwareState | None = None
        self.status_pub = keyed.publisher(
            self, StatusArray, topics.status, history_qos(10_000), topics.run
        )
        # The monitor takes a cell's statuses from the process that announced hosting it.
        cell = row * params.cols + col
        keyed.publisher(self, Host, topics.hosts, LATCHED, topics.run).publish(
            Host(name=self.get_name(), first=[cell], last=[cell])
        )
        self.reconnector = Reconnector(link, self.get_logger()) if link else None
        self.finished = False
        self.create_timer(0.05, self._poll)

    def _poll(self) -> None:
        if self.lines is not None:
            if self.state is None:
                self.state = FirmwareState(droplet_id=self._transcript_id())
            for line in self.lines:
                if self.state.feed(line):
                    self._report()
            self.lines, self.finished = [], True
            return
        if not self.reconnector.ensure():
            return
        try:
            if self.state is None:
                self.state = FirmwareState(droplet_id=self.link.get_id())
            for line in self.link.poll(0.0):
                if self.state.feed(line):
                    self._report()
        except DropletDisconnected as exc:
            self.reconnector.failed(exc)
        except DropletError as exc:
            self.get_logger().warning(str(exc))

    def _transcript_id(self) -> int:
        """The id the transcript's `get_id` answer shows (0 when it has none)."""
        for line in self.lines:
            if line.strip().startswith("My ID is: "):
                try:
                    return int(line.strip()[len("My ID is: ") :], 16)
                except ValueError:
                    break
        return 0

    def _report(self) -> None:
        state = self.state
        phase = CONSENSUS if state.p is not None else SENSING
        pattern = state.pattern
        status = RobotStatus(
            sender_id=self.row * self.params.cols + self.col,
            row=self.row,
            col=self.col,
            phase=phase,
            step=state.steps,
            round=0,
            sensed=state.sensed,
            p=list(state.p) if state.p else [0.0, 0.0, 0.0],
            pattern=NO_PATTERN if pattern is None else pattern,
            state=0,
            alive=self.link.connected if self.link else True,
            known_slots=0,
        )
        # A run's statuses go out as arrays, a process's reports in each: here, one report.
        msg = StatusArray(
            name=self.get_name(), **StatusRows.from_reports([status]).message_fields()
        )
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = "camo"
        self.status_pub.publish(msg)


def run_bridge(robot: RobotSetup, topics: RunTopics, bridge: BridgeParams, stop) -> int:
    """Robot mode: this cell's robot, with the Droplet's sensor and LED."""
    params, row, col = robot.params, robot.cell.row, robot.cell.col
    link = DropletLink(bridge.port, timeout=bridge.serial_timeout, retries=bridge.retries)
    if bridge.calibration:
        calibration = Calibration.from_yaml(bridge.calibration)
    else:
        calibration = Calibration(bridge.gain, bridge.offset)
    reconnector = Reconnector(link)
    cell = row * params.cols + col
    sensor = DropletSensor(link, reconnector, params.profile, calibration)
    led = DropletLed(
        link, reconnector, parse_rgb(bridge.led_on), parse_rgb(bridge.led_off), (row, col)
    )
    host = host_robots(
        params,
        robot.protocol,
        topics,
        [(cell, cell)],
        lean=False,
        sensors={cell: sensor},
        displays={cell: led},
    )
    reconnector.logger = host.node.get_logger()
    host.node.create_timer(0.25, led.keep)
    led.keep()
    try:
        return host.run(stop, until=run_ended(host.node, topics))
    finally:
        link.close()


def run_monitor(robot: RobotSetup, topics: RunTopics, bridge: BridgeParams, stop) -> int:
    """Monitor mode: a Droplet running the firmware, or a transcript of one."""
    params, row, col = robot.params, robot.cell.row, robot.cell.col
    link = None
    if bridge.port:
        link = DropletLink(bridge.port, timeout=bridge.serial_timeout, retries=bridge.retries)
    transcript = Path(bridge.transcript) if bridge.transcript else None
    if transcript is not None and not transcript.is_file():
        raise ParameterError(f"transcript not found: {transcript}")
    node = DropletMonitorNode(params, topics, row, col, link=link, transcript=transcript)
    try:
        while not stop and rclpy.ok():
            rclpy.spin_once(node, timeout_sec=0.1)
    except KeyboardInterrupt:
        pass
    finally:
        if link is not None:
            link.close()
        node.destroy_node()
    return 0


def firmware_lacks(params: CamoParams) -> list[str]:
    """The options of a run that a Droplet's own firmware has no rules for (it runs the
    paper's, with a fixed threshold and two stripe directions)."""
    return modes_of(params).beyond_paper()


def check_bridge(values: dict) -> None:
    """A bridge's parameters, said at once (not after waiting up to a minute for a run)."""
    bridge = BridgeParams.from_values(values)
    if not bridge.port and not bridge.transcript:
        raise ParameterError("give the Droplet's serial port: -p port:=/dev/ttyUSB0")
    if bridge.port and not os.path.exists(bridge.port):
        raise ParameterError(f"no serial port {bridge.port} (is the Droplet plugged in?)")
    setup = robot_setup(values)
    if setup.protocol.continuous:
        raise ParameterError(
            "a bridged Droplet does not watch for a changed scene (continuous): its process "
            "reads projected frames, not the Droplet's sensor"
        )
    beyond = firmware_lacks(setup.params)
    if (bridge.monitor or bridge.transcript) and beyond:
        raise ParameterError(
            f"a Droplet's firmware cannot run {' or '.join(beyond)}: monitor mode shows the "
            "firmware's own rules (bridged, without monitor, the bridge runs camo's rules and can)"
        )


def main(args=None) -> int:
    """droplet_bridge --ros-args -p rows:=8 -p cols:=8 -p row:=R -p col:=C -p port:=/dev/ttyUSB0"""
    if wants_help(args):
        about = "A real Droplet on a serial port as one robot of the swarm (see docs/hardware.md)."
        print(node_help("droplet_bridge", about, parameters_help(*ROBOT_PARAMETERS, BridgeParams)))
        return 0
    stop = StopFlag()
    start_ros(
        "droplet_bridge", args, node_options=True, signal_handler_options=SignalHandlerOptions.NO
    )
    try:
        robot, topics, values = robot_parameters(stop, check_bridge, (BridgeParams,))
        bridge = BridgeParams.from_values(values)
        if bridge.monitor or bridge.transcript:
            return run_monitor(robot, topics, bridge, stop)
        return run_bridge(robot, topics, bridge, stop)
    except CamoError as exc:
        print(f"droplet_bridge: error: {exc}", file=sys.stderr)
        return 2
    finally:
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
