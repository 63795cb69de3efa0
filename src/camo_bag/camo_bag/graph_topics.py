"""Topics as they appear on the ROS graph, and the QoS to take them with: what the recorder and
the live view share."""

from __future__ import annotations

from collections.abc import Callable, Iterator

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from camo_bag import msgdefs

SKIPPED = {"/rosout", "/parameter_events"}


def hidden(name: str) -> bool:
    """A hidden topic (a name part begins with `_`: an action's goal, feedback and status
    topics), which ros2cli lists and rosbag2 records only when asked to."""
    return any(part.startswith("_") for part in name.split("/"))


def new_topics(
    node: Node, known: dict[str, object], wants: Callable[[str], bool]
) -> Iterator[tuple[str, str, list[QoSProfile]]]:
    """(name, pkg/msg/Type, QoS its publishers offer) of each wanted topic not in `known` that
    has a publisher. A topic carrying several types is reported once and marked in `known`."""
    for name, types in node.get_topic_names_and_types():
        if name in known or name in SKIPPED or hidden(name) or not wants(name):
            continue
        if len(types) != 1:
            node.get_logger().warning(f"{name} carries several types {types}; left out")
            known[name] = None
            continue
        publishers = node.get_publishers_info_by_topic(name)
        if publishers:  # else only subscribers so far: wait for a publisher's QoS
            yield name, msgdefs.full_name(types[0]), [p.qos_profile for p in publishers]


def taking_qos(offered: list[QoSProfile]) -> QoSProfile:
    """As rosbag2 adapts: reliable and transient-local only when every publisher offers it (so a
    latched topic hands over its history), keeping every sample."""
    reliable = all(q.reliability == ReliabilityPolicy.RELIABLE for q in offered)
    latched = all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offered)
    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL,
        depth=1,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )
