"""Images on the wire: numpy <-> sensor_msgs/Image (8-bit grey or BGR)."""

from __future__ import annotations

import numpy as np
from sensor_msgs.msg import Image

from camo_core.exceptions import CamoError


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
