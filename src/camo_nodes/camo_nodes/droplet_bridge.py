"""The hardware bridge: a real Droplet takes the place of one robot node (console script droplet_bridge).

Robot mode (default): a RobotNode whose sensor is the Droplet's `get_rgb`
(grey by the profile's weights, then the calibration) and whose display is its
LED; its neighbours cannot tell it from a simulated robot. Its reading is
real, so simulated measurement noise never applies to it. A port that
disappears is reconnected with backoff; meanwhile the robot reports itself
not alive, keeps computing, and sets the LED it missed once the port is back.

Monitor mode (`monitor:=true`): for a Droplet running the camouflage firmware
itself; its printouts become this cell's RobotStatus messages, so a hardware
run can be watched and recorded like a simulated one. `transcript:=FILE`
reads a recorded printout instead of a port.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

from camo_core.params import CamoParams, ParameterError
from camo_core.sensing import rgb_to_gray
from camo_msgs.msg import RobotStatus

from .droplet_link import Calibration, DropletDisconnected, DropletError, DropletLink
from .firmware import FirmwareState
from .robot_node import RobotNode, params_from_node
from .topics import STATUS_TOPIC, history_qos

MAX_BACKOFF = 8.0


def parse_rgb(text: str) -> tuple[int, int, int]:
    try:
        rgb = tuple(int(x) for x in text.replace(",", " ").split())
    except ValueError:
        rgb = ()
    if len(rgb) != 3 or not all(0 <= c <= 255 for c in rgb):
        raise ParameterError(
            f"an LED colour is three integers 0..255, e.g. '255 0 0' (got {text!r})"
        )
    return rgb


class Reconnector:
    """Opens the link again after it went away, waiting longer after each failure."""

    def __init__(self, link: DropletLink, logger) -> None:
        self.link = link
        self.logger = logger
        self.backoff = 0.5
        self.next_try = 0.0

    def ensure(self) -> bool:
        if self.link.connected:
            return True
        now = time.monotonic()
        if now < self.next_try:
            return False
        try:
            self.link.open()
        except DropletDisconnected as exc:
            self.next_try = now + self.backoff
            self.logger.warning(f"{exc}; next try in {self.backoff:g} s")
            self.backoff = min(MAX_BACKOFF, self.backoff * 2)
            return False
        self.backoff = 0.5
        if self.next_try:  # an earlier open failed or the port went away
            self.logger.info(f"reconnected to {self.link.path}")
        return True

    def failed(self, exc: DropletError) -> None:
        if isinstance(exc, DropletDisconnected):
            self.logger.warning(f"{exc}: the robot is offline until the port is back")
            self.next_try = time.monotonic() + self.backoff


class DropletBridgeNode(RobotNode):
    def __init__(
        self,
        params: CamoParams,
        row: int,
        col: int,
        port: str,
        calibration: Calibration = Calibration(),
        led_on: tuple[int, int, int] = (255, 0, 0),
        led_off: tuple[int, int, int] = (255, 255, 255),
        link: DropletLink | None = None,
        **kwargs,
    ) -> None:
        self.link = link or DropletLink(port)
        self.calibration = calibration
        self.led = {1: led_on, 0: led_off}
        self.shown: tuple[int, int, int] | None = None
        self.wanted: tuple[int, int, int] | None = None
        self.droplet_id: int | None = None
        super().__init__(params, row, col, **kwargs)
        self.reconnector = Reconnector(self.link, self.get_logger())
        self.create_timer(0.25, self._keep_connected)
        self._keep_connected()

    def _keep_connected(self) -> None:
        if not self.reconnector.ensure():
            return
        try:
            if self.droplet_id is None:
                self.droplet_id = self.link.get_id()
                self.get_logger().info(
                    f"Droplet {self.droplet_id:04X} on {self.link.path} is robot "
                    f"({self.core.row}, {self.core.col})"
                )
            if self.wanted is not None and self.wanted != self.shown:
                self.link.set_led(*self.wanted)
                self.shown = self.wanted
        except DropletDisconnected as exc:
            self.reconnector.failed(exc)
        except DropletError as exc:
            self.get_logger().warning(str(exc))

    def _hardware_ok(self) -> bool:
        return self.link.connected

    def _display_ready(self) -> bool:
        if self.wanted != self.shown:
            self._keep_connected()
        return self.wanted == self.shown

    def _read_sensor(self) -> tuple[float, bool] | None:
        if not self.reconnector.ensure():
            return None
        try:
            r, g, b = self.link.get_rgb()
        except DropletDisconnected as exc:
            self.reconnector.failed(exc)
            return None
        except DropletError as exc:
            self.get_logger().warning(f"{exc}; reading again")
            return None
        grey = self.calibration.apply(rgb_to_gray(r, g, b, self.params.profile))
        self.get_logger().info(f"read r {r} g {g} b {b}: grey {grey:g}")
        return grey, True

    def _show(self, state: int) -> None:
        self.wanted = self.led[int(state)]
        if self.wanted != self.shown:
            self._keep_connected()


class DropletMonitorNode(Node):
    """A Droplet running the camouflage firmware, watched: its printouts as this cell's statuses."""

    def __init__(
        self,
        params: CamoParams,
        row: int,
        col: int,
        link: DropletLink | None = None,
        transcript: Path | None = None,
        **kwargs,
    ) -> None:
        super().__init__(f"droplet_monitor_{row}_{col}", namespace="/camo", **kwargs)
        self.params, self.row, self.col = params, row, col
        self.link = link
        self.lines = (
            list(Path(transcript).read_text(errors="replace").splitlines()) if transcript else None
        )
        self.state: FirmwareState | None = None
        self.status_pub = self.create_publisher(RobotStatus, STATUS_TOPIC, history_qos(10_000))
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
        phase = RobotStatus.PHASE_CONSENSUS if state.p is not None else RobotStatus.PHASE_SENSING
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
            pattern=RobotStatus.PATTERN_NONE if pattern is None else pattern,
            state=0,
            alive=self.link.connected if self.link else True,
            known_slots=0,
        )
        status.header.stamp = self.get_clock().now().to_msg()
        status.header.frame_id = "camo"
        self.status_pub.publish(status)


def main(args=None) -> int:
    """droplet_bridge --ros-args -p rows:=8 -p cols:=8 -p row:=R -p col:=C -p port:=/dev/ttyUSB0 [...]"""
    rclpy.init(args=args)
    node = None
    try:
        reader = Node("droplet_parameters", start_parameter_services=False)
        try:
            params, row, col, timeout, discovery_timeout = params_from_node(reader)
            extra = {
                "port": "",
                "monitor": False,
                "transcript": "",
                "calibration": "",
                "gain": 1.0,
                "offset": 0.0,
                "led_on": "255 0 0",
                "led_off": "255 255 255",
                "serial_timeout": 0.5,
                "retries": 3,
            }
            values = {
                name: reader.declare_parameter(name, default).value
                for name, default in extra.items()
            }
        finally:
            reader.destroy_node()
        if not values["port"] and not values["transcript"]:
            raise ParameterError("give the Droplet's serial port: -p port:=/dev/ttyUSB0")
        if values["calibration"]:
            calibration = Calibration.from_yaml(values["calibration"])
        else:
            if not values["gain"] > 0:
                raise ParameterError(f"gain must be positive (got {values['gain']})")
            calibration = Calibration(values["gain"], values["offset"])
        if not (values["serial_timeout"] > 0 and values["retries"] >= 0):
            raise ParameterError("serial_timeout must be positive and retries not negative")
        link = (
            DropletLink(
                values["port"], timeout=values["serial_timeout"], retries=values["retries"]
            )
            if values["port"]
            else None
        )
        if values["monitor"] or values["transcript"]:
            transcript = Path(values["transcript"]) if values["transcript"] else None
            if transcript is not None and not transcript.is_file():
                raise ParameterError(f"transcript not found: {transcript}")
            node = DropletMonitorNode(params, row, col, link=link, transcript=transcript)
        else:
            node = DropletBridgeNode(
                params,
                row,
                col,
                values["port"],
                calibration,
                parse_rgb(values["led_on"]),
                parse_rgb(values["led_off"]),
                link=link,
                step_timeout=timeout,
                discovery_timeout=discovery_timeout,
            )
        while rclpy.ok():
            rclpy.spin_once(node, timeout_sec=0.1)
    except (ParameterError, ValueError) as exc:
        print(f"droplet_bridge: error: {exc}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            if getattr(node, "link", None) is not None:
                node.link.close()
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
