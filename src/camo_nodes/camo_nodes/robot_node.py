"""One robot of the swarm as an rclpy node.

It talks only to the robots in its 12 neighbour slots, over per-robot topics,
and goes through SPEC's phases by itself: hello, sense, colour, vote,
consensus, pattern formation. There is no clock master: a robot moves on when,
for every neighbour it knows, the message for this step has arrived or will be
dropped by the simulated link (a deterministic draw, so known in advance), or
when the step's deadline passes. A neighbour that misses a deadline is not
waited for again until it speaks again. The rules themselves are
camo_core's RobotCore; this class only moves messages.
"""

from __future__ import annotations

import math
import sys
import time

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from sensor_msgs.msg import Image

from camo_core import rng
from camo_core.grid import NUM_SLOTS
from camo_core.params import CamoParams, ParameterError
from camo_core.robot import RobotCore
from camo_core.sensing import sense_image
from camo_msgs.msg import Color, Hello, RobotStatus, State, Vote
from camo_projector.image_msg import from_msg
from camo_projector.qos import BACKGROUND_TOPIC, LATCHED

from .topics import STATUS_TOPIC, history_qos, robot_topic

DISCOVERY, SENSING, CONSENSUS, FORMATION, DONE = (
    RobotStatus.PHASE_DISCOVERY,
    RobotStatus.PHASE_SENSING,
    RobotStatus.PHASE_CONSENSUS,
    RobotStatus.PHASE_FORMATION,
    RobotStatus.PHASE_DONE,
)
MESSAGE_TYPES = {"hello": Hello, "color": Color, "vote": Vote, "state": State}
TICK = 0.05  # s between checks of the step deadline
STALL = 0.5  # s: a tick this late means the process itself stalled


def inputs(neighbors: list[int | None]) -> list[tuple[int, str]]:
    """(slot, kind) a robot listens to: hellos and states from slots 0-11, colours 0-3, votes 0-7."""
    limit = {"hello": 12, "color": 4, "vote": 8, "state": 12}
    return [
        (slot, kind)
        for slot, n in enumerate(neighbors)
        if n is not None
        for kind in MESSAGE_TYPES
        if slot < limit[kind]
    ]


class RobotNode(Node):
    def __init__(
        self,
        params: CamoParams,
        row: int,
        col: int,
        step_timeout: float = 10.0,
        discovery_timeout: float = 300.0,
        autostart: bool = True,
        hub=None,
        **node_kwargs,
    ) -> None:
        self.core = RobotCore(params, row, col)  # raises ValueError for a cell outside the grid
        super().__init__(f"robot_{row}_{col}", namespace="/camo", **node_kwargs)
        self.params = params
        self.step_timeout = step_timeout
        self.discovery_timeout = discovery_timeout
        depth = max(params.consensus_steps, params.formation_steps) + 4
        qos = history_qos(depth)
        me = self.core.id
        self.pub = {
            kind: self.create_publisher(t, robot_topic(me, kind), qos)
            for kind, t in MESSAGE_TYPES.items()
        }
        if hub is None:
            # Every status of a round stays available to a monitor or recorder that joins late.
            statuses = params.consensus_steps + params.formation_steps + 8
            self.status_pub = self.create_publisher(
                RobotStatus, STATUS_TOPIC, history_qos(statuses)
            )
            for slot, kind in inputs(self.core.neighbors):
                self.create_subscription(
                    MESSAGE_TYPES[kind],
                    robot_topic(self.core.neighbors[slot], kind),
                    lambda msg, s=slot, k=kind: self._on_message(k, s, msg),
                    qos,
                )
            self.create_subscription(Image, BACKGROUND_TOPIC, self._on_background, LATCHED)
        else:
            # Hosted by a worker: its hub subscribes once per topic for all the robots it hosts
            # and hands each robot what its neighbours sent (DDS entities cost quadratic set-up time).
            self.status_pub = hub.status_pub
            hub.register(self)
        # What has been delivered, by (round, kind, step, slot); early messages wait here for their step.
        self.inbox: dict[tuple[int, str, int, int], object] = {}
        self.silent: set[int] = set()
        self.deadlines = 0  # step deadlines passed in this round
        self.image = None
        self.image_stamp = None
        self.next_image = None  # a background that arrived mid-round: camouflaged next
        self.round = 0
        self.phase = DISCOVERY
        self.step = 0
        self.wait_started = time.monotonic()
        self.started = False
        self.ticking = False  # in the timer's call to _advance: deadlines may pass
        self.last_tick = time.monotonic()
        self.create_timer(TICK, self._on_timer)
        if autostart:
            self.start()

    def start(self) -> None:
        """Say hello and begin. A worker hosting many robots creates them all first, then starts
        them, so that no robot's deadline runs while its process is still busy creating nodes."""
        self.started = True
        self.wait_started = self.last_tick = time.monotonic()
        self._send("hello", Hello(phase=DISCOVERY, step=0, row=self.core.row, col=self.core.col))

    @property
    def done(self) -> bool:
        return self.phase == DONE

    # ---- receiving ------------------------------------------------------------

    def _on_timer(self) -> None:
        now = time.monotonic()
        stalled = now - self.last_tick - TICK
        self.last_tick = now
        if stalled > STALL:
            # This process could not listen (busy or descheduled): that time is not the neighbours'
            # fault, and their messages may still be queued behind this tick. Extend the deadline.
            self.wait_started += stalled
        if self.started and self.context.ok():  # not while the process is shutting down
            self.ticking = True
            try:
                self._advance()
            finally:
                self.ticking = False

    def _on_message(self, kind: str, slot: int, msg) -> None:
        self.silent.discard(slot)  # it speaks again: wait for it again
        if msg.round < self.round:
            return
        if kind == "hello":
            payload = True
        elif kind == "color":
            payload = msg.value
        elif kind == "vote":
            payload = (tuple(msg.p), msg.degree)
        else:
            payload = msg.state
        self.inbox[(msg.round, kind, msg.step, slot)] = payload
        if self.started:
            self._advance()

    def _on_background(self, msg: Image) -> None:
        stamp = (msg.header.stamp.sec, msg.header.stamp.nanosec)
        if stamp == self.image_stamp:
            return
        self.image_stamp = stamp
        if self.image is None:
            self.image = from_msg(msg)
        else:
            self.next_image = from_msg(msg)
        if self.started:
            self._advance()

    def _start_next_round(self) -> None:
        """Camouflage again on the new background: same rules, a fresh robot state."""
        self.round += 1
        self.image, self.next_image = self.next_image, None
        self.core = RobotCore(self.params, self.core.row, self.core.col)
        self.deadlines = 0
        self.inbox = {key: value for key, value in self.inbox.items() if key[0] >= self.round}
        self._next(DISCOVERY)
        self._send("hello", Hello(phase=DISCOVERY, step=0, row=self.core.row, col=self.core.col))

    # ---- sending --------------------------------------------------------------

    def _send(self, kind: str, msg) -> None:
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = "camo"
        msg.sender_id = self.core.id
        msg.round = self.round
        self.pub[kind].publish(msg)

    # ---- sensor and display: a simulated robot reads the projected image and shows nothing ----

    def _read_sensor(self) -> tuple[float, bool] | None:
        """(grey value, real reading) of this robot's cell; a real reading gets no simulated noise."""
        raw = sense_image(self.image, self.params.rows, self.params.cols, self.params.profile)
        return float(raw[self.core.row, self.core.col]), False

    def _show(self, state: int) -> None:
        """Display the formation state (a hardware robot sets its LED)."""

    def _hardware_ok(self) -> bool:
        return True

    def _display_ready(self) -> bool:
        """The display shows the latest state."""
        return True

    def _report(self) -> None:
        core = self.core
        if self.phase >= FORMATION:
            self._show(core.state)
        status = RobotStatus(
            sender_id=core.id,
            row=core.row,
            col=core.col,
            phase=self.phase,
            step=self.step,
            sensed=core.sensed,
            p=list(core.p),
            state=core.state,
            alive=self._hardware_ok(),
            known_slots=core.known_mask,
            round=self.round,
            deadlines=self.deadlines,
            pattern=RobotStatus.PATTERN_NONE if core.pattern is None else core.pattern,
        )
        status.header.stamp = self.get_clock().now().to_msg()
        status.header.frame_id = "camo"
        self.status_pub.publish(status)

    # ---- stepping -------------------------------------------------------------

    def _waiting_for(
        self, kind: str, stream: int, step: int, slots, known_only: bool = True
    ) -> list[int]:
        """Slots whose message for `step` is still to come: expected, not dropped, not silent."""
        return [
            s
            for s in slots
            if self.core.neighbors[s] is not None
            and (self.core.known[s] or not known_only)
            and s not in self.silent
            and (self.round, kind, step, s) not in self.inbox
            and self.core.arrives(stream, step, s)
        ]

    def _ready(self, pending: list[int], timeout: float) -> bool:
        if not pending:
            return True
        # Only the tick lets a deadline pass: it has first discounted a stall of this process, and a
        # message handled before the tick after a stall would otherwise find the deadline long gone.
        if not self.ticking or time.monotonic() - self.wait_started < timeout:
            return False
        self.silent.update(pending)
        self.deadlines += 1
        self.get_logger().warning(
            f"step deadline passed; neighbours in slots {pending} are silent"
        )
        return True

    def _next(self, phase: int, step: int = 0) -> None:
        self.phase, self.step = phase, step
        self.wait_started = time.monotonic()

    def _take(self, kind: str, step: int, slots) -> list:
        return [self.inbox.pop((self.round, kind, step, s), None) for s in slots]

    def _advance(self) -> None:
        while True:
            if self.phase == DISCOVERY:
                if not self._ready(
                    self._waiting_for("hello", rng.STREAM_HELLO, 0, range(NUM_SLOTS), False),
                    self.discovery_timeout,
                ):
                    return
                heard = self._take("hello", 0, range(NUM_SLOTS))
                self.core.discover([h is not None for h in heard])
                self._next(SENSING)
            elif self.phase == SENSING:
                if self.image is None:
                    return
                if math.isnan(self.core.sensed):
                    reading = self._read_sensor()
                    if reading is None:  # the sensor is not available yet: try again later
                        return
                    self.core.sense(*reading)
                    self._send("color", Color(phase=SENSING, step=0, value=self.core.sensed))
                    self.wait_started = time.monotonic()
                if not self._ready(
                    self._waiting_for("color", rng.STREAM_COLOR, 0, range(4)), self.step_timeout
                ):
                    return
                self.core.decide_vote(self._take("color", 0, range(4)))
                self._next(CONSENSUS)
                self._report()
                self._send_vote()
            elif self.phase == CONSENSUS:
                if self.step == self.params.consensus_steps:
                    self.core.finish_consensus()
                    self._next(FORMATION)
                    self._report()
                    self._send_state()
                    continue
                if not self._ready(
                    self._waiting_for("vote", rng.STREAM_CONSENSUS, self.step, range(8)),
                    self.step_timeout,
                ):
                    return
                self.core.consensus(self.step, self._take("vote", self.step, range(8)))
                self._next(CONSENSUS, self.step + 1)
                self._report()
                if self.step < self.params.consensus_steps:
                    self._send_vote()
            elif self.phase == FORMATION:
                if self.step == self.params.formation_steps:
                    if (
                        not self._display_ready()
                    ):  # a hardware robot is done once it shows its state
                        return
                    self._next(DONE, self.step)
                    self._report()
                    continue
                if not self._ready(
                    self._waiting_for("state", rng.STREAM_STATE, self.step, range(NUM_SLOTS)),
                    self.step_timeout,
                ):
                    return
                self.core.form(self.step, self._take("state", self.step, range(NUM_SLOTS)))
                self._next(FORMATION, self.step + 1)
                self._report()
                if self.step < self.params.formation_steps:
                    self._send_state()
            elif self.next_image is not None:  # done, and a new background is up
                self._start_next_round()
            else:
                return

    def _send_vote(self) -> None:
        self._send(
            "vote",
            Vote(phase=CONSENSUS, step=self.step, p=list(self.core.p), degree=self.core.degree),
        )

    def _send_state(self) -> None:
        self._send("state", State(phase=FORMATION, step=self.step, state=self.core.state))


def params_from_node(node: Node) -> tuple[CamoParams, int, int, float]:
    """Read a standalone robot's ROS parameters into CamoParams (raises ParameterError)."""
    spec = {
        "rows": 8,
        "cols": 8,
        "row": 0,
        "col": 0,
        "profile": "paper",
        "seed": 0,
        "rho_meas": 0.0,
        "rho_comm": 0.0,
        "threshold": 50.0,
        "consensus_steps": -1,
        "formation_steps": -1,
        "step_timeout": 10.0,
        "discovery_timeout": 300.0,
    }
    values = {name: node.declare_parameter(name, default).value for name, default in spec.items()}
    params = CamoParams(
        profile=values["profile"],
        rows=values["rows"],
        cols=values["cols"],
        threshold=values["threshold"],
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


def main(args=None) -> int:
    """A single robot in its own process: parameters rows, cols, row, col, profile, seed, rho_*, ..."""
    rclpy.init(args=args)
    node = None
    try:
        reader = Node("robot_parameters", start_parameter_services=False)
        try:
            params, row, col, timeout, discovery_timeout = params_from_node(reader)
        finally:
            reader.destroy_node()
        node = RobotNode(
            params, row, col, step_timeout=timeout, discovery_timeout=discovery_timeout
        )
        while rclpy.ok():
            rclpy.spin_once(node, timeout_sec=0.5)
    except (ParameterError, ValueError) as exc:
        print(f"robot_node: error: {exc}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
