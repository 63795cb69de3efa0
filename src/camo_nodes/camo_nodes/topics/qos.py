"""The QoS profiles of a run's topics: latched for what a late joiner must still get, a deep
history where a neighbour that starts late needs every step's message."""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

# Latched: a robot that starts late still gets the background that is up.
LATCHED = QoSProfile(
    depth=1,
    history=HistoryPolicy.KEEP_LAST,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)

# A reader of a latched topic that anyone in the domain can write to: it keeps every sample
# until taken, so that a stranger's flood cannot push the rightful writer's sample out.
LATCHED_READER = QoSProfile(
    depth=1,
    history=HistoryPolicy.KEEP_ALL,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)

# Heartbeats (`heartbeat.py`): the latest few; nobody needs old ones.
HEARTBEAT_WRITER = QoSProfile(
    depth=4,
    history=HistoryPolicy.KEEP_LAST,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
# Every sample until taken (a reader polls them each turn of its loop, a bounded batch): a
# stranger's flood cannot push a process's heartbeats out.
HEARTBEAT_READER = QoSProfile(
    depth=1,
    history=HistoryPolicy.KEEP_ALL,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)


def history_qos(depth: int) -> QoSProfile:
    """Reliable and transient-local: a neighbour that starts late still gets every step's
    message."""
    return QoSProfile(
        depth=depth,
        history=HistoryPolicy.KEEP_LAST,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )
