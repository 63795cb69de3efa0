"""Topic names and QoS of the swarm, in one place for robots, monitor and recorder."""

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

STATUS_TOPIC = "/swarm/status"
PATTERN_TOPIC = "/swarm/pattern"
# std_msgs/String, latched: the run's parameters and backgrounds as JSON, for recorders and `camo render`.
PARAMS_TOPIC = "/swarm/params"


def robot_topic(robot_id: int, kind: str) -> str:
    return f"/camo/robot_{robot_id}/{kind}"


def history_qos(depth: int) -> QoSProfile:
    """Reliable and transient-local: a neighbour that starts late still gets every step's message."""
    return QoSProfile(
        depth=depth,
        history=HistoryPolicy.KEEP_LAST,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )


def status_listener_qos() -> QoSProfile:
    """Every robot writes to one status topic: a listener keeps all, or bursts would push samples out."""
    return QoSProfile(
        depth=1,
        history=HistoryPolicy.KEEP_ALL,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )
