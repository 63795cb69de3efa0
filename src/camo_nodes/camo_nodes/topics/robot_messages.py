"""Robot messages on the wire: the camo_msgs type of each kind, alone and in arrays, and the
conversion between them and the protocol's messages (`camo_core.algorithm.robot_io.Message`).
"""

from __future__ import annotations

import time

from camo_core.algorithm.robot_io import Message
from camo_msgs.msg import (
    Color,
    ColorArray,
    Energy,
    EnergyArray,
    Hello,
    HelloArray,
    Relay,
    RelayArray,
    State,
    StateArray,
    Vote,
    VoteArray,
)

MESSAGE_TYPES = {
    "hello": Hello,
    "color": Color,
    "energy": Energy,
    "vote": Vote,
    "state": State,
    "relay": Relay,
}
# On the wire: a tile topic of a kind carries arrays of its messages.
ARRAY_TYPES = {
    "hello": HelloArray,
    "color": ColorArray,
    "energy": EnergyArray,
    "vote": VoteArray,
    "state": StateArray,
    "relay": RelayArray,
}
NOT_RECEIVED = Relay.NOT_RECEIVED


def stamp(msg) -> None:
    """A message's header: now by the wall clock (ROS time), frame "camo"."""
    now = time.time_ns()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now, 1_000_000_000)
    msg.header.frame_id = "camo"


def fill(msg, message: Message) -> None:
    """Write a protocol message into a (reused) camo_msgs message of its kind."""
    msg.sender_id, msg.round, msg.step = message.sender, message.round, message.step
    kind = message.kind  # the kinds a robot sends every step first
    if kind == "vote":
        p, msg.degree = message.value
        array = msg.p
        array[0], array[1], array[2] = p[0], p[1], p[2]
        if len(p) > 3:  # --levels: the grey histogram averaged with p
            msg.histogram = p[3:]
    elif kind == "state":
        msg.state = message.value
    elif kind == "hello":
        msg.row, msg.col = message.value
    elif kind == "color":
        msg.value = message.value
    elif kind == "energy":
        msg.energy, msg.degree = message.value
    else:
        msg.states = [NOT_RECEIVED if v is None else v for v in message.value]


def from_ros(kind: str, msg) -> Message:
    if kind == "hello":
        value = (msg.row, msg.col)
    elif kind == "color":
        value = msg.value
    elif kind == "energy":
        value = (msg.energy, msg.degree)
    elif kind == "vote":
        # Python floats, not numpy scalars: a robot computes with what it hears, and numpy
        # scalars would spread through the swarm's arithmetic at several times the cost.
        value = ((*msg.p.tolist(), *msg.histogram), msg.degree)
    elif kind == "relay":
        value = tuple(None if v == NOT_RECEIVED else int(v) for v in msg.states)
    else:
        value = msg.state
    return Message(kind, msg.sender_id, msg.round, msg.step, value)
