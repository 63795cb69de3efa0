"""QoS profiles to and from rosbag2's `offered_qos_profiles` YAML (metadata version 9)."""

from __future__ import annotations

import yaml
from rclpy.duration import Duration
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
)

INFINITE_NS = 9223372036854775807  # RMW_DURATION_INFINITE, as rosbag2 writes it


def _time(duration: Duration) -> dict:
    ns = duration.nanoseconds if duration.nanoseconds > 0 else INFINITE_NS
    return {"sec": ns // 10**9, "nsec": ns % 10**9}


def to_dict(qos: QoSProfile) -> dict:
    return {
        "history": qos.history.name.lower(),
        "depth": qos.depth,
        "reliability": qos.reliability.name.lower(),
        "durability": qos.durability.name.lower(),
        "deadline": _time(qos.deadline),
        "lifespan": _time(qos.lifespan),
        "liveliness": qos.liveliness.name.lower(),
        "liveliness_lease_duration": _time(qos.liveliness_lease_duration),
        "avoid_ros_namespace_conventions": qos.avoid_ros_namespace_conventions,
    }


def dump(profiles: list[QoSProfile]) -> str:
    return yaml.safe_dump([to_dict(q) for q in profiles], sort_keys=False) if profiles else ""


def _policy(enum, value, default):
    if isinstance(value, int):
        return enum(value)
    try:
        return enum[str(value).upper()]
    except KeyError:
        return default


def load_first(text: str) -> QoSProfile:
    """The first recorded profile, for a replay publisher (default: reliable, volatile, keep
    all)."""
    try:
        profiles = yaml.safe_load(text) if text else []
    except yaml.YAMLError:
        profiles = []
    if not profiles or not isinstance(profiles, list) or not isinstance(profiles[0], dict):
        return QoSProfile(depth=10)
    first = profiles[0]
    # Offered profiles from graph discovery carry no history (rosbag2 writes "unknown", depth 0):
    # keep
    # all then, or a reliable burst would overwrite samples a subscriber has not acknowledged yet.
    history = _policy(HistoryPolicy, first.get("history"), HistoryPolicy.KEEP_ALL)
    depth = int(first.get("depth", 0) or 0)
    if history != HistoryPolicy.KEEP_LAST or depth < 1:
        history, depth = HistoryPolicy.KEEP_ALL, 1
    return QoSProfile(
        history=history,
        depth=depth,
        reliability=_policy(
            ReliabilityPolicy, first.get("reliability"), ReliabilityPolicy.RELIABLE
        ),
        durability=_policy(DurabilityPolicy, first.get("durability"), DurabilityPolicy.VOLATILE),
        liveliness=_policy(LivelinessPolicy, first.get("liveliness"), LivelinessPolicy.AUTOMATIC),
    )
