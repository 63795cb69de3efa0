"""The swarm's topics in one place: names, QoS profiles and the wire form of images.

Robots, workers, the monitor, the projector, recorders and viewers all take
their topic names and QoS from here, so that they always match.
"""

from __future__ import annotations

import numpy as np
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image

from camo_core.exceptions import CamoError

STATUS_TOPIC = "/swarm/status"
PATTERN_TOPIC = "/swarm/pattern"
# std_msgs/String, latched: the run's parameters and backgrounds as JSON, for recorders and render.
PARAMS_TOPIC = "/swarm/params"
# std_msgs/String, latched: what a recorder holds of the run, per round (JSON).
RECORDED_TOPIC = "/swarm/recorded"
BACKGROUND_TOPIC = "/camo/background"
# std_msgs/String: a built-in background name or an image path for the projector to show next.
LOAD_TOPIC = "/camo/projector/load"

# Latched: a robot that starts late still gets the background that is up.
LATCHED = QoSProfile(
    depth=1,
    history=HistoryPolicy.KEEP_LAST,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)


def robot_topic(robot_id: int, kind: str) -> str:
    return f"/camo/robot_{robot_id}/{kind}"


def history_qos(depth: int) -> QoSProfile:
    """Reliable and transient-local: a neighbour that starts late still gets every step's
    message."""
    return QoSProfile(
        depth=depth,
        history=HistoryPolicy.KEEP_LAST,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )


def status_listener_qos() -> QoSProfile:
    """Every robot writes to one status topic: a listener keeps all, or bursts would push samples
    out."""
    return QoSProfile(
        depth=1,
        history=HistoryPolicy.KEEP_ALL,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )


# ---- images on the wire: numpy <-> sensor_msgs/Image (8-bit grey or BGR) ---------------------


class ImageEncodingError(CamoError):
    """An Image message in an encoding the swarm does not read."""


def image_to_msg(image: np.ndarray, frame_id: str = "arena") -> Image:
    msg = Image()
    msg.header.frame_id = frame_id
    msg.height, msg.width = int(image.shape[0]), int(image.shape[1])
    msg.encoding = "mono8" if image.ndim == 2 else "bgr8"
    msg.is_bigendian = 0
    msg.step = msg.width * (1 if image.ndim == 2 else 3)
    msg.data = np.ascontiguousarray(image, dtype=np.uint8).tobytes()
    return msg


def image_from_msg(msg: Image) -> np.ndarray:
    channels = {"mono8": 1, "bgr8": 3, "rgb8": 3}.get(msg.encoding)
    if channels is None:
        raise ImageEncodingError(
            f"unsupported image encoding {msg.encoding!r} (mono8, bgr8, rgb8)"
        )
    if msg.height * msg.step != len(msg.data) or msg.step < msg.width * channels:
        raise ImageEncodingError(
            f"an image of {msg.width}x{msg.height} with step {msg.step} cannot hold "
            f"{len(msg.data)} bytes"
        )
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(msg.height, msg.step)
    data = data[:, : msg.width * channels]
    if channels == 1:
        return data.copy()
    image = data.reshape(msg.height, msg.width, 3)
    return (image[:, :, ::-1] if msg.encoding == "rgb8" else image).copy()
