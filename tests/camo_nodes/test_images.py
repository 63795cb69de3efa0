"""Frames that come on an image topic: decoded as the swarm reads them, or refused in one line
(the projector counts and skips them; the swarm keeps its scene)."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from sensor_msgs.msg import Image

from camo_nodes.topics.images import ImageEncodingError, image_from_msg, image_to_msg

ENCODINGS = st.sampled_from(["mono8", "bgr8", "rgb8", "mono16", "", "bayer_rggb8", "32FC1"])


@settings(max_examples=200, deadline=None)
@given(
    encoding=ENCODINGS,
    width=st.integers(0, 70),
    height=st.integers(0, 70),
    extra=st.integers(-3, 5),
    spare=st.integers(-4, 4),
)
def test_any_frame_decodes_to_its_pixels_or_is_one_line(encoding, width, height, extra, spare):
    channels = {"mono8": 1, "bgr8": 3, "rgb8": 3}.get(encoding, 1)
    step = max(0, width * channels + extra)
    msg = Image(encoding=encoding, width=width, height=height, step=step)
    msg.data = bytes(range(256)) * ((max(0, height * step + spare) // 256) + 1)
    msg.data = msg.data[: max(0, height * step + spare)]
    try:
        image = image_from_msg(msg)
    except ImageEncodingError as exc:
        assert "\n" not in str(exc)
        return
    # Taken: a known encoding, pixels at least one, every row's bytes there.
    assert encoding in ("mono8", "bgr8", "rgb8") and width * height > 0
    assert image.shape[:2] == (height, width) and image.dtype == np.uint8
    assert len(msg.data) == height * step and step >= width * channels


def test_empty_and_oversized_frames_are_refused_and_a_sent_frame_comes_back():
    frame = np.arange(12, dtype=np.uint8).reshape(3, 4)
    assert np.array_equal(image_from_msg(image_to_msg(frame)), frame)
    for msg in (Image(encoding="mono8"), Image(encoding="mono8", width=10**5, height=10**5)):
        msg.step = msg.width
        try:
            image_from_msg(msg)
        except ImageEncodingError as exc:
            assert "empty image" in str(exc) or "more than the" in str(exc)
        else:
            raise AssertionError("taken")
