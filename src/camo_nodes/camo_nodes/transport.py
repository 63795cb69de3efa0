"""How a process's robots exchange messages: DDS for the world, memory between themselves.

Every robot publishes on its own topics (`/camo/robot_<id>/<kind>`), which a
neighbour in another process, a recorder or a viewer subscribes to. A robot
hosted in the same process as its neighbour gets the message handed over in
memory instead, as rclcpp's intra-process communication does, so a process
subscribes only to the topics of neighbours that live elsewhere: DDS endpoint
matching grows with readers x writers, and in-memory hand-over keeps a large
swarm's set-up short.
"""

from __future__ import annotations

from collections import defaultdict, deque
from collections.abc import Callable

from rclpy.node import Node

from camo_core.params import CamoParams
from camo_core.protocol import CONSENSUS, DISCOVERY, FORMATION, SENSING, Message, Report
from camo_msgs.msg import Color, Hello, RobotStatus, State, Vote

from .topics import STATUS_TOPIC, history_qos, robot_topic

MESSAGE_TYPES = {"hello": Hello, "color": Color, "vote": Vote, "state": State}
Receiver = Callable[[Message], None]


def to_ros(message: Message):
    """The camo_msgs message of a protocol message (header stamp and frame left to the sender)."""
    kind, common = message.kind, {"sender_id": message.sender, "round": message.round}
    if kind == "hello":
        row, col = message.value
        return Hello(phase=DISCOVERY, step=0, row=row, col=col, **common)
    if kind == "color":
        return Color(phase=SENSING, step=0, value=message.value, **common)
    if kind == "vote":
        p, degree = message.value
        return Vote(phase=CONSENSUS, step=message.step, p=list(p), degree=degree, **common)
    return State(phase=FORMATION, step=message.step, state=message.value, **common)


def from_ros(kind: str, msg) -> Message:
    if kind == "hello":
        value = (msg.row, msg.col)
    elif kind == "color":
        value = msg.value
    elif kind == "vote":
        value = (tuple(msg.p), msg.degree)
    else:
        value = msg.state
    return Message(kind, msg.sender_id, msg.round, msg.step, value)


def status_msg(report: Report) -> RobotStatus:
    return RobotStatus(
        sender_id=report.sender_id,
        row=report.row,
        col=report.col,
        phase=report.phase,
        step=report.step,
        round=report.round,
        sensed=report.sensed,
        p=list(report.p),
        pattern=report.pattern,
        state=report.state,
        alive=report.alive,
        known_slots=report.known_slots,
        deadlines=report.deadlines,
        silent=list(report.silent),
    )


def message_depth(params: CamoParams) -> int:
    """History per robot topic: a whole phase, so a neighbour that starts late misses nothing."""
    return max(params.consensus_steps, params.formation_steps) + 4


def status_depth(params: CamoParams) -> int:
    """Statuses one robot sends in a round (one per step and phase change)."""
    return params.consensus_steps + params.formation_steps + 8


class Transport:
    """The DDS endpoints of one process's robots, owned by one node (the process's own)."""

    def __init__(self, node: Node, params: CamoParams, hosted: list[int]) -> None:
        self.node = node
        self.params = params
        self.hosted = set(hosted)
        self.qos = history_qos(message_depth(params))
        self.status_pub = node.create_publisher(
            RobotStatus, STATUS_TOPIC, history_qos(status_depth(params) * len(hosted))
        )
        self.publishers: dict[tuple[int, str], object] = {}
        self.receivers: dict[tuple[int, str], list[Receiver]] = defaultdict(list)
        self._queue: deque[tuple[Receiver, Message]] = deque()
        self._pumping = False

    def hosts(self, robot: int) -> bool:
        """A robot of this process: alive as long as the process is."""
        return robot in self.hosted

    def add(self, robot: int, listens_to, receive: Receiver) -> None:
        """A hosted robot: its topics, and what it hears from whom (`listens_to`: (sender,
        kind))."""
        for kind, msg_type in MESSAGE_TYPES.items():
            self.publishers[(robot, kind)] = self.node.create_publisher(
                msg_type, robot_topic(robot, kind), self.qos
            )
        for sender, kind in listens_to:
            key = (sender, kind)
            if key not in self.receivers and sender not in self.hosted:
                self.node.create_subscription(
                    MESSAGE_TYPES[kind],
                    robot_topic(sender, kind),
                    lambda msg, k=kind: self._received(from_ros(k, msg)),
                    self.qos,
                )
            self.receivers[key].append(receive)

    def send(self, message: Message) -> None:
        msg = to_ros(message)
        msg.header.stamp = self.node.get_clock().now().to_msg()
        msg.header.frame_id = "camo"
        self.publishers[(message.sender, message.kind)].publish(msg)
        self._received(message)

    def report(self, report: Report) -> None:
        msg = status_msg(report)
        msg.header.stamp = self.node.get_clock().now().to_msg()
        msg.header.frame_id = "camo"
        self.status_pub.publish(msg)

    def _received(self, message: Message) -> None:
        """Hand a message to every hosted robot that listens to its sender. Queued, not called
        at once: a robot that steps on it sends again, and that must not recurse."""
        for receive in self.receivers.get((message.sender, message.kind), ()):
            self._queue.append((receive, message))
        if self._pumping:
            return
        self._pumping = True
        try:
            while self._queue:
                receive, queued = self._queue.popleft()
                receive(queued)
        finally:
            self._pumping = False
