"""A stranger in a run's domain (for tests/camo_nodes/test_trust.py): it finds the run's topics on
the graph and publishes on every one of them copies of the robots' messages (arrays of them on
tile topics) with plausible ids, rounds and steps, some with NaN and out-of-range values, some
well-formed but wrong, plus a fake host announcement, a fake background and fake parameters.

    python tests/attacker.py RUN_ID SECONDS [FIRST-LAST ...]

With tiles given it also publishes at once on the topics they would have (the names are no
secret), as soon as the run's launcher has started (it may be started first, and waits). It
prints "ready" (stderr) once its publishers exist, stops after SECONDS or on SIGTERM, and
prints how many topics it attacked and messages it sent.

    python tests/attacker.py RUN_ID SECONDS --replay IMAGE

One that listens to every topic of the run for SECONDS, then plays every message it took
again, bytes for bytes (a keyed run's tags with them), and tells the projector to load IMAGE
(a path) and a built-in background.

    python tests/attacker.py RUN_ID SECONDS --hijack FIRST-LAST ...

A quieter stranger (for tests/camo_bringup/test_launcher.py): it only announces those tiles as
its own (latched, before the run's workers can) and beats a heartbeat, as a process hosting
them would.
"""

from __future__ import annotations

import json
import math
import random
import signal
import sys
import time

import numpy as np
import rclpy
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image
from std_msgs.msg import String

from camo_core.swarm.status_rows import StatusRows
from camo_msgs.msg import (
    Color,
    Colors,
    Heartbeat,
    Hello,
    Hellos,
    Host,
    RobotStatus,
    State,
    States,
    StatusArray,
    Vote,
    Votes,
)
from camo_nodes.topics import keyed
from camo_nodes.topics.robot_messages import VALUE_COLUMNS

COLUMNS = {Hellos: ("hello", Hello), Colors: ("color", Color), Votes: ("vote", Vote)}
COLUMNS[States] = ("state", State)
TYPES = {
    "camo_msgs/msg/Hellos": Hellos,
    "camo_msgs/msg/Colors": Colors,
    "camo_msgs/msg/Votes": Votes,
    "camo_msgs/msg/States": States,
    "camo_msgs/msg/StatusArray": StatusArray,
    "camo_msgs/msg/Heartbeat": Heartbeat,
    "camo_msgs/msg/Host": Host,
    "sensor_msgs/msg/Image": Image,
    "std_msgs/msg/String": String,
}
NAN = math.nan
KINDS = ("hello", "color", "vote", "state")


def forged(cls, k: int, count: int, cols: int):  # noqa: PLR0911 - one forgery a case
    """The k-th forgery of a message type: NaN, out of range, or plausible and wrong."""
    if cls in COLUMNS:  # what a tile topic carries: several forged robot messages at once
        kind, single = COLUMNS[cls]
        rows = [forged(single, k * 3 + j, count, cols) for j in range(3)]
        msg = cls(phase=rows[0].phase, sender_id=[r.sender_id for r in rows])
        msg.round = [r.round for r in rows]
        # Every fourth one ragged: a column short of an entry.
        msg.step = [r.step for r in rows][: 2 if k % 4 == 3 else 3]
        for name, _ in VALUE_COLUMNS[kind]:
            values = [getattr(r, name) for r in rows]
            setattr(msg, name, [x for v in values for x in v] if name == "p" else values)
        return msg
    robot, step, bad = k % count, k % 30, k % 3
    if cls is Hello:
        return Hello(sender_id=robot, row=robot // cols, col=robot % cols, phase=0)
    if cls is Color:
        return Color(sender_id=robot, phase=1, value=(NAN, 300.0, 3.0)[bad])
    if cls is Vote:
        p = ([NAN, NAN, NAN], [2.0, -1.0, 0.0], [1.0, 0.0, 0.0])[bad]
        return Vote(sender_id=robot, phase=2, step=step, p=p, degree=(8, 99, 4)[bad])
    if cls is State:
        return State(sender_id=robot, phase=3, step=step % 10, state=(7, 1, 0)[bad])
    if cls is StatusArray:
        rows = [forged(RobotStatus, k * 3 + j, count, cols) for j in range(3)]
        return StatusArray(name="impostor", **StatusRows.from_reports(rows).message_fields())
    if cls is Heartbeat:
        return Heartbeat(name="impostor", sequence=k, offline=list(range(count)))
    if cls is RobotStatus:
        return RobotStatus(
            sender_id=robot, row=robot // cols, col=robot % cols, phase=(2, 4, 4)[bad],
            step=(0, 10, 10)[bad], sensed=(NAN, 100.0, 100.0)[bad],
            p=([NAN, NAN, NAN], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])[bad], state=1, pattern=0,
        )  # fmt: skip
    if cls is Host:
        return Host(name="impostor", first=[0], last=[count - 1])
    if cls is Image:
        image = Image(height=8, width=8, encoding="mono8", step=8)
        image.data = bytes(np.full(64, 255, np.uint8))
        return image
    return String(data=json.dumps({"params": {"rows": 2, "cols": 2}, "backgrounds": ["x"]}))


def hijack(node, run: str, seconds: float, tiles: list[str]) -> int:
    """Announce `tiles` (FIRST-LAST) as this process's, then beat until SECONDS or SIGTERM."""
    latched = QoSProfile(
        depth=1,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )
    ranges = [tuple(int(x) for x in tile.split("-")) for tile in tiles]
    announcement = Host(name=node.get_name(), first=[a for a, _ in ranges])
    announcement.last = [b for _, b in ranges]
    keyed.publisher(node, Host, f"/{run}/camo/hosts", latched, run).publish(announcement)
    beat = keyed.publisher(node, Heartbeat, f"/{run}/swarm/heartbeat", 10, run)
    print("ready", file=sys.stderr, flush=True)
    stop: list[bool] = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(True))
    deadline, sequence = time.monotonic() + seconds, 0
    while time.monotonic() < deadline and not stop:
        beat.publish(Heartbeat(name=node.get_name(), sequence=sequence))
        sequence += 1
        rclpy.spin_once(node, timeout_sec=0.2)
    print(json.dumps({"announced": tiles, "beats": sequence}))
    return 0


def replay(node, run: str, seconds: float, image: str) -> int:
    """Listen to every topic of the run for SECONDS, taking each message's bytes as they came
    (a keyed run's tags and all), then write them all again, in order, on their topics; and
    tell the projector to load IMAGE (a path) and a built-in background."""
    from rclpy.qos import HistoryPolicy

    qos = QoSProfile(
        depth=1, history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE
    )
    taken: list[tuple[str, bytes]] = []
    readers, writers = {}, {}
    print("ready", file=sys.stderr, flush=True)
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        for name, types in node.get_topic_names_and_types():
            if name.startswith(f"/{run}/") and name not in readers and types[0] in TYPES:
                cls = TYPES[types[0]]
                readers[name] = node.create_subscription(
                    cls, name, lambda data, name=name: taken.append((name, data)), qos, raw=True
                )
                writers[name] = node.create_publisher(cls, name, qos)
        rclpy.spin_once(node, timeout_sec=0.05)
    for name, data in taken:  # played again, bytes for bytes
        writers[name].publish(data)
    load = node.create_publisher(String, f"/{run}/camo/projector/load", 10)
    end = time.monotonic() + 3
    while time.monotonic() < end:  # volatile: sent while the projector listens
        load.publish(String(data=image))
        load.publish(String(data="desert"))
        rclpy.spin_once(node, timeout_sec=0.2)
    print(json.dumps({"topics": len(readers), "replayed": len(taken)}))
    return 0


def main() -> int:
    run, seconds, tiles = sys.argv[1], float(sys.argv[2]), sys.argv[3:]
    rclpy.init()
    node = rclpy.create_node("stranger")
    if tiles[:1] == ["--replay"]:
        code = replay(node, run, seconds, tiles[1])
        node.destroy_node()
        rclpy.shutdown()
        return code
    if tiles[:1] == ["--hijack"]:
        code = hijack(node, run, seconds, tiles[1:])
        node.destroy_node()
        rclpy.shutdown()
        return code
    qos = QoSProfile(
        depth=1000,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )
    # As soon as the run's launcher has started (its parameters appear), not before: a writer
    # of them would make the launcher take its run for a live one of that id and refuse it.
    deadline = time.monotonic() + seconds
    while not node.count_publishers(f"/{run}/swarm/params") and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
    publishers: dict[str, tuple] = {}
    guessed = {f"/{run}/camo/hosts": Host, f"/{run}/camo/background": Image}
    guessed |= {f"/{run}/swarm/status": StatusArray, f"/{run}/swarm/params": String}
    guessed[f"/{run}/swarm/heartbeat"] = Heartbeat
    for tile in tiles:
        for part in ("edge", "core"):
            for kind, cls in zip(KINDS, COLUMNS, strict=True):
                guessed[f"/{run}/camo/tile_{tile.replace('-', '_')}/{part}/{kind}"] = cls
    for name, cls in guessed.items():
        publishers[name] = (keyed.publisher(node, cls, name, qos, run), cls)
    print("ready", file=sys.stderr, flush=True)
    count, cols = 36, 6
    random.seed(1)
    deadline = time.monotonic() + seconds
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(True))
    sent = 0
    while time.monotonic() < deadline and not stop:
        for name, types in node.get_topic_names_and_types():
            if name.startswith(f"/{run}/") and name not in publishers and types[0] in TYPES:
                cls = TYPES[types[0]]
                publishers[name] = (keyed.publisher(node, cls, name, qos, run), cls)
        for publisher, cls in publishers.values():
            for _ in range(5):
                publisher.publish(forged(cls, sent, count, cols))
                sent += 1
        rclpy.spin_once(node, timeout_sec=0.01)
    print(json.dumps({"topics": len(publishers), "sent": sent}))
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
