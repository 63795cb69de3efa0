"""Robot messages on the wire: the camo_msgs type of each kind, and the conversion between them
and the protocol's messages (`camo_core.swarm.robot_io.Message`).

A tile topic carries a tile's messages of one kind as columns (`camo_msgs/Votes`, ...): per
message its sender, step and round, and its value spread over the kind's value columns. Packing
a robot message is a few list appends, and rclpy converts a column as one block, where an array
of `camo_msgs/Vote`s cost a Python attribute per field and message both ways (`Columns`, the
packing; `unpack`, the reading). One robot's message alone (`camo_msgs/Vote`, ...) and the
arrays of them (`camo_msgs/VoteArray`, ...) are what bags of older camo hold.
"""

from __future__ import annotations

import time
from array import array
from itertools import accumulate

from camo_core.swarm.robot_io import PHASE_OF, Message
from camo_msgs.msg import (
    Color,
    ColorArray,
    Colors,
    Energies,
    Energy,
    EnergyArray,
    Hello,
    HelloArray,
    Hellos,
    Relay,
    RelayArray,
    Relays,
    State,
    StateArray,
    States,
    Vote,
    VoteArray,
    Votes,
)

# One robot's message of each kind (what bags of the oldest camo hold, one a bag message).
MESSAGE_TYPES = {
    "hello": Hello,
    "color": Color,
    "energy": Energy,
    "vote": Vote,
    "state": State,
    "relay": Relay,
}
# Bags of older camo: a tile topic of a kind carried arrays of its messages.
ARRAY_TYPES = {
    "hello": HelloArray,
    "color": ColorArray,
    "energy": EnergyArray,
    "vote": VoteArray,
    "state": StateArray,
    "relay": RelayArray,
}
# On the wire: a tile topic of a kind carries its messages as columns.
COLUMN_TYPES = {
    "hello": Hellos,
    "color": Colors,
    "energy": Energies,
    "vote": Votes,
    "state": States,
    "relay": Relays,
}
NOT_RECEIVED = Relay.NOT_RECEIVED
RELAY_SLOTS = 8  # a relay's states: one per slot 0-7
# Per kind, its value columns: (name, array typecode).
VALUE_COLUMNS = {
    "hello": (("row", "I"), ("col", "I")),
    "color": (("value", "d"),),
    "energy": (("energy", "d"), ("degree", "I")),
    "vote": (("degree", "I"), ("p", "d")),
    "state": (("state", "B"),),
    "relay": (("states", "B"),),
}


class Columns:
    """A tile topic's messages until the next write, as the columns of one message of its kind.
    `add` is a robot's every step: a few list appends."""

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self.sender: list[int] = []
        self.step: list[int] = []
        self.round: list[int] = []
        self.values: tuple[list, ...] = tuple([] for _ in VALUE_COLUMNS[kind])
        self.widths: list[int] = []  # votes: each message's values of p
        self.add = getattr(self, f"_add_{kind}")

    def __len__(self) -> int:
        return len(self.sender)

    def _head(self, message: Message) -> None:
        self.sender.append(message.sender)
        self.step.append(message.step)
        self.round.append(message.round)

    def _add_vote(self, message: Message) -> None:
        self.sender.append(message.sender)  # _head, written out: a robot's every step
        self.step.append(message.step)
        self.round.append(message.round)
        p, degree = message.value
        self.values[0].append(degree)
        self.values[1].extend(p)
        self.widths.append(len(p))

    def _add_state(self, message: Message) -> None:
        self._head(message)
        self.values[0].append(message.value)

    def _add_hello(self, message: Message) -> None:
        self._head(message)
        row, col = message.value
        self.values[0].append(row)
        self.values[1].append(col)

    def _add_color(self, message: Message) -> None:
        self._head(message)
        self.values[0].append(message.value)

    def _add_energy(self, message: Message) -> None:
        self._head(message)
        energy, degree = message.value
        self.values[0].append(energy)
        self.values[1].append(degree)

    def _add_relay(self, message: Message) -> None:
        self._head(message)
        self.values[0].extend(NOT_RECEIVED if v is None else v for v in message.value)

    def take(self):
        """The message of what was added (stamped now), and empty again."""
        msg = COLUMN_TYPES[self.kind](phase=PHASE_OF[self.kind])
        msg.sender_id = array("I", self.sender)
        msg.step = array("I", self.step)
        msg.round = array("I", self.round)
        for (name, code), values in zip(VALUE_COLUMNS[self.kind], self.values, strict=True):
            setattr(msg, name, array(code, values))
            values.clear()
        if self.widths and min(self.widths) != max(self.widths):  # else: one width, implied
            msg.width = array("I", self.widths)
        self.widths = []
        self.sender, self.step, self.round = [], [], []
        stamp(msg)
        return msg


class RaggedColumns(ValueError):
    """A columns message whose columns do not hold an entry per message."""


def unpack(kind: str, msg) -> list[Message]:
    """The protocol's messages in a columns message of `kind` (RaggedColumns: its columns do not
    line up, and none of it can be trusted). Values are Python numbers, not numpy's: a robot
    computes with what it hears, and numpy scalars would spread through the swarm's arithmetic
    at several times the cost."""
    senders, steps, rounds = msg.sender_id.tolist(), msg.step.tolist(), msg.round.tolist()
    n = len(senders)
    columns = [getattr(msg, name).tolist() for name, _ in VALUE_COLUMNS[kind]]
    if len(steps) != n or len(rounds) != n:
        raise RaggedColumns("columns of different lengths")
    if kind == "vote":
        degrees, p = columns
        widths = msg.width.tolist() if len(getattr(msg, "width", ())) else None
        if widths is None:  # every message the same width
            width = len(p) // n if n else 0
            if len(degrees) != n or len(p) != width * n:
                raise RaggedColumns("columns of different lengths")
            values = [(tuple(p[k * width : (k + 1) * width]), degrees[k]) for k in range(n)]
        else:
            if len(degrees) != n or len(widths) != n or sum(widths) != len(p):
                raise RaggedColumns("columns of different lengths")
            ends = list(accumulate(widths))
            values = [
                (tuple(p[e - w : e]), degrees[k])
                for k, (e, w) in enumerate(zip(ends, widths, strict=True))
            ]
    elif kind == "relay":
        (states,) = columns
        if len(states) != RELAY_SLOTS * n:
            raise RaggedColumns("columns of different lengths")
        received = [None if v == NOT_RECEIVED else v for v in states]
        values = [tuple(received[k * RELAY_SLOTS : (k + 1) * RELAY_SLOTS]) for k in range(n)]
    else:
        if any(len(column) != n for column in columns):
            raise RaggedColumns("columns of different lengths")
        values = list(zip(*columns, strict=True)) if len(columns) > 1 else columns[0]
    return [Message(kind, senders[k], rounds[k], steps[k], values[k]) for k in range(n)]


def senders_rounds_steps(msg) -> list[tuple[int, int, int]]:
    """(sender, round, step) of each robot message in a decoded message of any robot type: one
    robot's, an array of them or columns (the bag ledger's view of a tile topic)."""
    if hasattr(msg, "messages"):
        return [(m.sender_id, m.round, m.step) for m in msg.messages]
    if isinstance(msg.sender_id, int):
        return [(msg.sender_id, msg.round, msg.step)]
    senders, rounds, steps = msg.sender_id.tolist(), msg.round.tolist(), msg.step.tolist()
    if not len(senders) == len(rounds) == len(steps):
        raise RaggedColumns("columns of different lengths")
    return list(zip(senders, rounds, steps, strict=True))


def stamp(msg) -> None:
    """A message's header: now by the wall clock (ROS time), frame "camo"."""
    now = time.time_ns()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now, 1_000_000_000)
    msg.header.frame_id = "camo"
