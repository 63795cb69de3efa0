"""Whether a bag holds the whole of its run: `bag info` and `render` ask before they trust it.

One pass over the bag fills a ledger (`ledger.py`) with the run's parameters,
its result, the backgrounds, the robots' done reports and, for every robot
message, its sender, round and step. Arrays of robot messages (what runs
record now), statuses, parameters and the result are decoded with rclpy's
serialization; in bags of the older layout, one robot message per bag message,
those three fields are read straight from the CDR bytes (such a bag of a large
run holds millions of messages, and a full decode of each costs ten times more).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

from rclpy.serialization import deserialize_message
from std_msgs.msg import String

from camo_bag.container import BagError, BagMessage, BagSummary, damaged
from camo_bag.ledger import ARRAY_KINDS, COLUMN_KINDS, SINGLE_KINDS, Ledger
from camo_bag.loader import Bag, open_bag
from camo_bag.msgdefs import full_name, message_class
from camo_bag.upgrade import installed_decoder
from camo_core.exceptions import CamoError
from camo_core.swarm.protocol import DONE
from camo_core.swarm.run_setup import RunSetup, SetupError
from camo_core.swarm.status_rows import rows_of_message
from camo_msgs.msg import RobotStatus
from camo_nodes.topics.images import frame_number
from camo_nodes.topics.names import PARAMS_SUFFIX
from camo_nodes.topics.robot_messages import senders_rounds_steps
from camo_nodes.topics.runs import result_from

MANY_KINDS = {**COLUMN_KINDS, **ARRAY_KINDS}  # types of many robot messages a bag message


def message_fields(kind: str, data: bytes) -> tuple[int, int, int]:
    """(sender_id, round, step) of a robot message's CDR bytes (std_msgs/Header first, then
    sender_id; a hello has row and col before its phase)."""
    order = "<" if data[1] == 1 else ">"
    (length,) = struct.unpack_from(order + "I", data, 12)  # the frame_id, NUL included
    at = 16 + length
    at += -(at - 4) % 4  # CDR aligns from the end of the 4-byte encapsulation header
    if kind == "hello":
        sender, _row, _col, _phase, step, round_index = struct.unpack_from(
            order + "IIIB3xII", data, at
        )
    else:
        sender, _phase, step, round_index = struct.unpack_from(order + "IB3xII", data, at)
    return sender, round_index, step


def header_frame_id(data: bytes) -> str:
    """The header.frame_id of a CDR message whose first field is std_msgs/Header ("" if the bytes
    do not hold one)."""
    if len(data) < 16:
        return ""
    (length,) = struct.unpack_from("<I" if data[1] == 1 else ">I", data, 12)
    if not 0 < length <= 256 or len(data) < 16 + length:
        return ""
    return data[16 : 16 + length - 1].decode("utf-8", "replace")  # without its NUL


def ledger_message(ledger: Ledger, kind: str, sender: int, round_index: int, step: int) -> None:
    if ledger.params is None or sender < ledger.params.count:
        ledger.message(kind, sender, round_index, step)


def run_topics_of(summary: BagSummary) -> tuple[str, str, str, str]:
    """The bag's run: its parameters, status, background and result topics. A bag recorded
    before runs had identities holds them at the root (/swarm/params, ...)."""
    params = sorted(t.name for t in summary.topics if t.name.endswith(PARAMS_SUFFIX))
    if not params:
        raise BagError(
            f"{summary.path} has no {PARAMS_SUFFIX} topic: it was not recorded from `./camo run`"
        )
    if len(params) > 1:
        raise BagError(f"{summary.path} holds several runs ({', '.join(params)}): not rendered")
    root = params[0][: -len(PARAMS_SUFFIX)]  # "/<run>", or "" in the older layout
    return (
        params[0],
        f"{root}/swarm/status",
        f"{root}/camo/background",
        f"{root}/swarm/result",
    )


def status_decoder(summary: BagSummary, topic: str):
    """Statuses as the installed StatusArray or RobotStatus: directly when the bag's schema is
    the installed one, else (a bag of an older camo) through the schema the bag holds, fields it
    lacks read as empty (upgrade.py)."""
    info = next((t for t in summary.topics if t.name == topic), None)
    if info is None:
        return lambda data: deserialize_message(data, RobotStatus)
    try:
        return installed_decoder(info)
    except ValueError as exc:
        raise damaged(summary.path, exc, f"holds an unreadable schema for {topic}") from None


def done_reports(msg) -> list[tuple[int, int]]:
    """(robot, round) of each report in a status message (a StatusArray, or a RobotStatus of
    an older camo) that says its robot finished the round."""
    rows = rows_of_message(msg)
    done = rows.phase == DONE
    return list(zip(rows.sender_id[done].tolist(), rows.round[done].tolist(), strict=True))


def setup_in(data: bytes) -> RunSetup | None:
    """A parameters message of the bag's run (of any camo version), or None."""
    try:
        return RunSetup.from_json(deserialize_message(data, String).data)
    except SetupError:
        return None


@dataclass
class Topics:
    """The topics of a bag's run, and how to read each."""

    params: str
    status: str
    background: str
    result: str
    run: str
    kinds: dict[str, str]  # topics of one robot message a bag message (oldest camo): their kind
    arrays: dict[
        str, tuple[str, type]
    ]  # topics of many robot messages (columns, arrays): kind, class
    decode_status: object


def ledger_one(ledger: Ledger, topics: Topics, message: BagMessage) -> None:
    """One bag message into the ledger (any exception: it does not decode as its type)."""
    topic, data = message.topic, message.data
    kind = topics.kinds.get(topic)
    if kind is not None:
        ledger_message(ledger, kind, *message_fields(kind, data))
    elif topic in topics.arrays:
        kind, cls = topics.arrays[topic]
        for sender, round_index, step in senders_rounds_steps(deserialize_message(data, cls)):
            ledger_message(ledger, kind, sender, round_index, step)
    elif topic == topics.status:
        for robot, index in done_reports(topics.decode_status(data)):
            ledger.reported_done(robot, index)
    elif topic == topics.background:
        ledger.background(frame_number(header_frame_id(data)))
    elif topic == topics.params and ledger.params is None:
        setup = setup_in(data)
        if setup is not None:
            ledger.set_run(setup.params, len(setup.backgrounds) or 1, setup.protocol.continuous)
    elif topic == topics.result:
        found = result_from(deserialize_message(data, String).data, topics.run)
        if found is not None:
            ledger.set_result(found)


def examine(path: str | Path | Bag) -> Ledger:
    """What the bag holds of its run (BagError if it holds no run, or cannot be read). A
    message that does not decode as its type is left out, and counted in the bag's
    `rejected`."""
    bag = path if isinstance(path, Bag) else open_bag(path)
    summary = bag.summary
    params, status, background, result = run_topics_of(summary)
    run = params[1 : -len(PARAMS_SUFFIX)]
    kinds = {
        t.name: SINGLE_KINDS[full_name(t.type)]
        for t in summary.topics
        if full_name(t.type) in SINGLE_KINDS
    }
    arrays = {
        t.name: (MANY_KINDS[full_name(t.type)], message_class(t.type))
        for t in summary.topics
        if full_name(t.type) in MANY_KINDS
    }
    decode_status = status_decoder(summary, status)
    ledger = Ledger()
    topics = Topics(params, status, background, result, run, kinds, arrays, decode_status)
    for message in bag.messages([params, status, background, result, *kinds, *arrays]):
        try:
            ledger_one(ledger, topics, message)
        except CamoError:
            raise
        except Exception:  # noqa: BLE001 - bytes that do not decode as their recorded type
            bag.reject(message)
    ledger.results_expected = bool(run)  # a bag of the older layout (no run id) never had one
    return ledger
