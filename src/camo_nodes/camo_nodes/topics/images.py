"""Images on the wire: numpy <-> sensor_msgs/Image (8-bit grey or BGR)."""

from __future__ import annotations

import hashlib

import numpy as np
from sensor_msgs.msg import Image

from camo_core.exceptions import CamoError
from camo_core.inputs.images import MAX_IMAGE_PIXELS


class ImageEncodingError(CamoError):
    """An Image message in an encoding the swarm does not read."""


ARENA = "arena"  # the frame of the projected background
FRAME_PREFIX = "arena/frame_"


def frame_id(number: int) -> str:
    """A projected frame's header.frame_id: the arena, and the projector's frame number, which
    names the round that camouflages against it (ROS 2 headers have no sequence number)."""
    return f"{FRAME_PREFIX}{number}"


def frame_number(text: str) -> int | None:
    """The frame number a background's frame_id carries, or None (`arena`: a background
    from a camo before numbered frames, or another publisher)."""
    digits = text[len(FRAME_PREFIX) :] if text.startswith(FRAME_PREFIX) else ""
    if not (digits.isascii() and digits.isdigit()) or len(digits) > 10:
        return None
    number = int(digits)
    return number if number < 2**32 else None


def image_to_msg(image: np.ndarray, frame_id: str = ARENA) -> Image:
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
    if msg.width == 0 or msg.height == 0:
        raise ImageEncodingError(f"an empty image ({msg.width}x{msg.height} pixels)")
    if msg.width * msg.height > MAX_IMAGE_PIXELS:
        raise ImageEncodingError(
            f"an image of {msg.width}x{msg.height} pixels, more than the {MAX_IMAGE_PIXELS} "
            "camo decodes"
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


def pixels_sha256(msg: Image) -> str:
    """SHA-256 of an image's pixels as published: its rows one after another, without the
    padding a step may add, in its own encoding (mono8 one byte a pixel, rgb8 R G B, bgr8 B G R):
    what `hashlib.sha256(frame.tobytes())` gives of the array that was sent."""
    channels = {"mono8": 1, "bgr8": 3, "rgb8": 3}.get(msg.encoding, 1)
    row = msg.width * channels
    data = bytes(msg.data)
    if msg.step == row:
        return hashlib.sha256(data[: row * msg.height]).hexdigest()
    digest = hashlib.sha256()
    for k in range(msg.height):
        digest.update(data[k * msg.step : k * msg.step + row])
    return digest.hexdigest()
