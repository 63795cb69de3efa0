"""QoS profiles to and from rosbag2's `offered_qos_profiles` YAML (metadata version 9).

`check_profiles` validates the YAML (a string holding YAML, in metadata.yaml and in an MCAP
channel's metadata) before anything uses it: every field of a profile known, enums named
(or, as older rosbag2 versions wrote them, numbered) within their value sets, the depth an
int in range, and durations of non-negative int sec and nsec.
"""

from __future__ import annotations

from typing import Any

from rclpy.duration import Duration
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
)

from camo_bag.checks import bad, boolean, integer, listed, load_yaml, mapping
from camo_core.inputs.strict_yaml import dump_yaml

INFINITE_NS = 9223372036854775807  # RMW_DURATION_INFINITE, as rosbag2 writes it
DEPTH_MAX = 2**31 - 1  # DDS history depths are int32
# nsec up to 2**32 - 1: rosbag2 before version 9 wrote an infinite duration as
# {sec: 2147483647, nsec: 4294967295}.
DURATION = mapping(
    {"sec": integer(0, INFINITE_NS // 10**9), "nsec": integer(0, 2**32 - 1)},
    required=("sec", "nsec"),
)


def _enum(enum):
    names = [m.name.lower() for m in enum]
    values = [m.value for m in enum]

    def check(value: Any, where: str) -> str:
        """The policy's name (lower case), from its name or its number."""
        if type(value) is int and value in values:
            return enum(value).name.lower()
        if isinstance(value, str) and value.lower() in names:
            return value.lower()
        raise bad(where, f"one of {', '.join(names)} (or {values})", value)

    return check


PROFILE = mapping(
    {
        "history": _enum(HistoryPolicy),
        "depth": integer(0, DEPTH_MAX),
        "reliability": _enum(ReliabilityPolicy),
        "durability": _enum(DurabilityPolicy),
        "deadline": DURATION,
        "lifespan": DURATION,
        "liveliness": _enum(LivelinessPolicy),
        "liveliness_lease_duration": DURATION,
        "avoid_ros_namespace_conventions": boolean,
    }
)
PROFILES = listed(PROFILE)


def check_profiles(value: Any, where: str) -> list[dict]:
    """The offered profiles of one topic, checked: `value` is their YAML text (as rosbag2
    writes it), or the list itself (as camo's metadata.yaml holds it); empty means none."""
    if isinstance(value, str):
        value = load_yaml(value, where) if value.strip() else []
    if value is None:
        return []
    return PROFILES(value, where)


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
    return dump_yaml([to_dict(q) for q in profiles]) if profiles else ""


def _policy(enum, value, default):
    """A checked policy name as the enum; `default` for none or "unknown" (a publisher cannot
    offer an unknown policy)."""
    return default if value in (None, "unknown") else enum[value.upper()]


def load_first(text: str, where: str = "offered_qos_profiles") -> QoSProfile:
    """The first recorded profile, for a replay publisher (default: reliable, volatile, keep
    all); BagError if the text is not a list of valid profiles."""
    profiles = check_profiles(text, where)
    if not profiles:
        return QoSProfile(depth=10)
    first = profiles[0]
    # Offered profiles from graph discovery carry no history (rosbag2 writes "unknown", depth 0):
    # keep
    # all then, or a reliable burst would overwrite samples a subscriber has not acknowledged yet.
    history = _policy(HistoryPolicy, first.get("history"), HistoryPolicy.KEEP_ALL)
    depth = first.get("depth", 0)
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
