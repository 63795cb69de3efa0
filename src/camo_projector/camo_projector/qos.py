"""Quality of service shared by the projector and everything that listens to it."""

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

# Latched: a robot that starts late still gets the background that is up.
LATCHED = QoSProfile(
    depth=1,
    history=HistoryPolicy.KEEP_LAST,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
BACKGROUND_TOPIC = "/camo/background"
LOAD_TOPIC = "/camo/projector/load"
