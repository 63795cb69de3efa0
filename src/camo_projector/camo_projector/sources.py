"""Where a projector's frames come from besides a still image: a video file, a sequence of image
files, a local camera (OpenCV), each asked for its frame at a given time. No ROS here."""

from __future__ import annotations

import glob
import math
import re
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import cv2
import numpy as np

from camo_core.algorithm.sensing import check_covers
from camo_core.inputs.files import checked_file, shown
from camo_core.inputs.images import (
    MAX_IMAGE_BYTES,
    MAX_QUOTED,
    ImageError,
    captured_stderr,
    decoder_messages,
    image_header,
    load_image,
)

MAX_SEQUENCE = 10_000  # image files of one --images pattern at most
MAX_VIDEO_BYTES = 1 << 40  # a video is read frame by frame: its size costs no memory
# Frames of a video whose time passed skipped per call at most: after a stall (a busy machine, a
# stopped process) a call does not decode seconds of video before its caller's loop turns again.
SKIPPED_PER_CALL = 64
# What FFmpeg's decoders write of a frame they could not decode whole ("[mjpeg @ 0x...] error
# count: ...", "concealing 120 DC, ... errors", "Invalid data found", "corrupt decoded frame"):
# such a frame decodes to something, but not to the picture, and is never projected.
VIDEO_DAMAGE = re.compile(r"\berror\b|[Cc]orrupt|[Ii]nvalid|concealing|[Mm]issing", re.ASCII)


@contextmanager
def _quiet_opencv() -> Iterator[None]:
    """OpenCV's video back-ends log to stderr when a device or file cannot be opened: camo says
    so in one line of its own instead. Only while opening: OpenCV's log level is the process's,
    and the image loader reads what the decoders log (inputs.images.load_image)."""
    logging = getattr(getattr(cv2, "utils", None), "logging", None)
    if logging is None:
        yield
        return
    before = logging.getLogLevel()
    logging.setLogLevel(logging.LOG_LEVEL_SILENT)
    try:
        yield
    finally:
        logging.setLogLevel(before)


class Source:
    """A stream of frames: `frame(now)` gives the frame to project at `now` (s, monotonic) if it
    is a new one, else None; `ended` once it has no more."""

    ended = False

    def frame(self, now: float) -> np.ndarray | None:
        raise NotImplementedError

    def close(self) -> None:
        pass


class VideoSource(Source):
    """A video file at its own frame rate (or `fps`), once or looped."""

    def __init__(
        self, path: str, fps: float = 0.0, loop: bool = False, grid: tuple[int, int] | None = None
    ) -> None:
        """`grid`: (rows, cols) of the swarm, if known: its frames must cover it."""
        self.path = checked_file(path, "video", MAX_VIDEO_BYTES, ImageError)
        with _quiet_opencv():  # FFmpeg's own words (a truncated file's "moov atom not found")
            self.capture, text = captured_stderr(lambda: cv2.VideoCapture(str(self.path)))
        if not self.capture.isOpened():
            said = decoder_messages(text)
            words = re.sub(r"^\[[^\]]*\] ", "", said[0]) if said else ""  # [mov,... @ 0x...]
            why = f": the decoder says {words[:MAX_QUOTED]!r}" if said else ""
            raise ImageError(
                f"video {shown(path)}: OpenCV cannot read it (not a video it knows){why}"
            )
        own = self.capture.get(cv2.CAP_PROP_FPS)
        self.fps = fps or (own if math.isfinite(own) and 0 < own <= 1000 else 25.0)
        self.loop = loop
        self.started: float | None = None
        self.shown = -1  # the index of the last frame given
        self.damaged = 0  # frames the decoder said it could not decode whole: not projected
        self.said = ""  # what it said of the latest
        first = self._read()
        if first is None:
            raise ImageError(f"video {shown(path)}: it holds no frame OpenCV can decode")
        if self.damaged:
            raise ImageError(
                f"video {shown(path)}: its first frame is damaged (the decoder says {self.said!r})"
            )
        if grid is not None:
            check_covers(first.shape[1], first.shape[0], *grid, what=f"video {shown(path)}")
        self.first = first

    def _read(self) -> np.ndarray | None:
        """The next frame decoded, what the decoder writes kept from the terminal; a frame it
        says is damaged is counted (`damaged`, `said`) and given all the same: the caller
        skips it."""
        (ok, frame), text = captured_stderr(self.capture.read)
        damage = [m for m in decoder_messages(text) if VIDEO_DAMAGE.search(m)]
        if damage:
            self.damaged += 1
            self.said = damage[0][:MAX_QUOTED]
        return frame if ok and frame is not None and frame.size else None

    def _next(self, keep: bool) -> np.ndarray | bool | None:
        """The next frame (`keep`: decoded into an image; else only grabbed: True), from the
        start again at the end of a looped video; None, and `ended`, at the end of the video."""
        for _ in range(2):
            if keep:
                frame = self._read()
                if frame is not None:
                    return frame
            elif self.capture.grab():
                return True
            if not self.loop:
                break
            self.capture.set(cv2.CAP_PROP_POS_FRAMES, 0)
        self.ended = True
        return None

    def frame(self, now: float) -> np.ndarray | None:
        if self.started is None:
            self.started, self.shown = now, 0
            return self.first
        due = int((now - self.started) * self.fps)
        if due <= self.shown or self.ended:
            return None
        # Frames whose time passed are skipped (grabbed, not retrieved as images), not shown late:
        # SKIPPED_PER_CALL at most, after which the call shows the frame it reached and the next
        # call goes on from there, in order, until the video has caught up with its time.
        last = min(due, self.shown + SKIPPED_PER_CALL + 1)
        while self.shown < last - 1:
            if self._next(keep=False) is None:
                return None
            self.shown += 1
        damaged = self.damaged
        frame = self._next(keep=True)
        if frame is not None:
            self.shown += 1
        if self.damaged > damaged:  # decoded, but not whole: never projected
            raise ImageError(
                f"video {shown(self.path)}: frame {self.shown} is damaged (the decoder says "
                f"{self.said!r}); skipped, {self.damaged} so far"
            )
        return frame

    def close(self) -> None:
        self.capture.release()


class ImagesSource(Source):
    """Image files matching a glob pattern, in name order, each for `period` seconds; looped."""

    def __init__(
        self, pattern: str, period: float, loop: bool = True, grid: tuple[int, int] | None = None
    ) -> None:
        """`grid`: (rows, cols) of the swarm, if known: every file must cover it."""
        names = sorted(glob.glob(pattern))
        files = [n for n in names if Path(n).is_file()]
        if not files:
            raise ImageError(f"--images {shown(pattern)}: no file matches it")
        if len(files) > MAX_SEQUENCE:
            raise ImageError(
                f"--images {shown(pattern)}: {len(files)} files, more than {MAX_SEQUENCE}"
            )
        for file in files:  # each header checked as --image checks it, at once; decoded when due
            width, height, _, _ = image_header(
                checked_file(file, "image", MAX_IMAGE_BYTES, ImageError)
            )
            if grid is not None:
                check_covers(
                    width, height, *grid, what=f"--images {shown(pattern)}: {shown(file)}"
                )
        self.files = files
        self.period, self.loop = period, loop
        self.started: float | None = None
        self.shown = -1

    def frame(self, now: float) -> np.ndarray | None:
        if self.started is None:
            self.started = now
        due = int((now - self.started) / self.period)
        if not self.loop and due >= len(self.files):
            self.ended = True
            return None
        if due == self.shown:
            return None
        self.shown = due
        return load_image(self.files[due % len(self.files)])  # ImageError: a file that broke


class CameraSource(Source):
    """A local camera (OpenCV's device `index`): its newest frame whenever asked."""

    def __init__(self, index: int, grid: tuple[int, int] | None = None) -> None:
        """`grid`: (rows, cols) of the swarm, if known: the camera's frames must cover it."""
        try:
            with _quiet_opencv():
                self.capture = cv2.VideoCapture(index)
        except (cv2.error, OverflowError, TypeError) as exc:
            said = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
            raise ImageError(f"camera {index}: OpenCV cannot open it ({said})") from None
        if not self.capture.isOpened():
            raise ImageError(f"camera {index}: there is none (OpenCV opened no device {index})")
        self.index = index
        width = int(self.capture.get(cv2.CAP_PROP_FRAME_WIDTH))
        height = int(self.capture.get(cv2.CAP_PROP_FRAME_HEIGHT))
        if grid is not None and width > 0 and height > 0:  # 0: a device that does not say
            try:
                check_covers(width, height, *grid, what=f"camera {index}")
            except ImageError:
                self.capture.release()
                raise

    def frame(self, now: float) -> np.ndarray | None:
        ok, frame = self.capture.read()
        if not ok or frame is None:
            self.ended = True  # unplugged
            return None
        return frame

    def close(self) -> None:
        self.capture.release()
