"""Every camo_msgs type goes through real rclpy publishers and subscriptions in one process."""

import time
from pathlib import Path

import pytest
from support import domain

rclpy = pytest.importorskip("rclpy")
from camo_msgs.msg import Color, Hello, RobotStatus, State, Vote  # noqa: E402


def filled(msg_type):
    msg = msg_type()
    msg.header.frame_id = "camo"
    msg.sender_id = 41
    msg.phase = 2
    msg.step = 7
    if hasattr(msg, "round"):
        msg.round = 3
    if msg_type is Hello:
        msg.row, msg.col = 5, 1
    if msg_type is Color:
        msg.value = 123.456789012345
    if msg_type is Vote:
        msg.p = [0.125, 0.5, 0.375]
        msg.degree = 8
    if msg_type is State:
        msg.state = 1
    if msg_type is RobotStatus:
        msg.p = [0.1, 0.2, 0.7]
        msg.pattern = RobotStatus.PATTERN_MOTTLED
        msg.alive = True
        msg.known_slots = 0x0FFF
        msg.sensed = 99.5
    return msg


def test_each_message_type_round_trips(monkeypatch):
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain()))
    rclpy.init()
    try:
        node = rclpy.create_node("camo_msgs_round_trip")
        received = {}
        sent = {}
        pubs = []
        for msg_type in (Hello, Color, Vote, State, RobotStatus):
            topic = f"/camo_test/{msg_type.__name__.lower()}"
            node.create_subscription(
                msg_type, topic, lambda m, t=msg_type: received.setdefault(t, m), 10
            )
            pubs.append((node.create_publisher(msg_type, topic, 10), msg_type))
            sent[msg_type] = filled(msg_type)
        deadline = time.monotonic() + 20
        while len(received) < len(sent) and time.monotonic() < deadline:
            for pub, msg_type in pubs:
                if msg_type not in received:
                    pub.publish(sent[msg_type])
            rclpy.spin_once(node, timeout_sec=0.1)
        assert set(received) == set(sent)
        for msg_type, msg in sent.items():
            assert received[msg_type] == msg, msg_type.__name__
        assert received[Color].value == 123.456789012345  # float64, not rounded
        assert list(received[Vote].p) == [0.125, 0.5, 0.375]
        node.destroy_node()
    finally:
        rclpy.shutdown()


def test_robot_status_constants_are_the_protocols_phases_and_the_rules_patterns():
    from camo_core.swarm import protocol

    assert [
        RobotStatus.PHASE_DISCOVERY,
        RobotStatus.PHASE_SENSING,
        RobotStatus.PHASE_CONSENSUS,
        RobotStatus.PHASE_FORMATION,
        RobotStatus.PHASE_DONE,
    ] == [
        protocol.DISCOVERY,
        protocol.SENSING,
        protocol.CONSENSUS,
        protocol.FORMATION,
        protocol.DONE,
    ]
    from camo_core.algorithm.orientation import ORIENTED
    from camo_core.algorithm.patterns import PATTERNS

    # Every pattern of the table has its constant, at its code; stripes at an angle follow them.
    for pattern in PATTERNS:
        assert getattr(RobotStatus, f"PATTERN_{pattern.name.upper()}") == pattern.code
    assert RobotStatus.PATTERN_STRIPES == ORIENTED
    assert RobotStatus.PATTERN_NONE == protocol.NO_PATTERN


MSG = Path(__file__).parents[2] / "src" / "camo_msgs" / "msg"


def msg_fields(name: str) -> dict[str, str]:
    """A .msg file's fields: name -> type (constants and comments left out)."""
    fields = {}
    for line in (MSG / f"{name}.msg").read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line and "=" not in line:
            kind, field = line.split()
            fields[field] = kind
    return fields


def test_status_messages_hold_each_declared_status_column_with_its_type():
    # The status columns are declared once (robot_io.Report); the messages must carry each
    # with its declared type: a RobotStatus one robot's values, a StatusArray a column of them
    # (lists flattened, with a count a row), and nothing else beside the header and name.
    from camo_core.swarm.robot_io import STATUS_COLUMNS

    single, array = {}, {}
    for name, meta in STATUS_COLUMNS.items():
        element, shape = meta["element"], meta["shape"]
        if meta["single"]:
            single[name] = element if shape == "value" else f"{element}[]"
        if meta["array"]:
            array[name] = f"{'uint8' if element == 'bool' else element}[]"
            if shape == "list":
                array[f"{name}_count"] = "uint32[]"
    assert msg_fields("RobotStatus") == {"header": "std_msgs/Header", **single}
    assert msg_fields("StatusArray") == {"header": "std_msgs/Header", "name": "string", **array}


def test_a_vote_holds_p_of_any_width():
    # A fourth pattern widens p: every message that carries p takes any width.
    assert msg_fields("Vote")["p"] == "float64[]"
    assert msg_fields("Votes")["p"] == "float64[]"
    assert msg_fields("RobotStatus")["p"] == "float64[]"
    status = RobotStatus(p=[0.25, 0.25, 0.25, 0.25])
    assert list(status.p) == [0.25] * 4
