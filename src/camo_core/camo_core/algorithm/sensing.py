"""docs/algorithm.md §2.1: what each robot senses of the projected background."""

from __future__ import annotations

import hashlib
import math
import os
import re
import struct
import sys
import threading
import warnings
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from camo_core.algorithm import rng
from camo_core.exceptions import CamoError
from camo_core.inputs.files import checked_file, shown
from camo_core.inputs.strict_yaml import described, read_yaml
from camo_core.schema import ParameterError


class ImageError(CamoError):
    """An image that cannot be used: missing, unreadable, too big, of an odd kind or too small."""


MAX_IMAGE_BYTES = 512 * 1024 * 1024  # on disk: a 2**27-pixel BMP is 400 MB
MAX_IMAGE_PIXELS = 2**27  # 16384 x 8192: a 8192 x 8192 grid's image and more, 400 MB as BGR
CALIBRATION_MAX_BYTES = 64 * 1024  # a calibration is two lines
MAX_GAIN = 1e6  # a gain above this maps every grey but black to white: not a calibration
MAX_OFFSET = 1e6  # as far: an offset beyond +-255 already clips every grey
DEPTHS = (np.uint8, np.uint16, np.float32)  # what OpenCV's codecs decode to


# Pillow's limits name its internals ("Decompressed data too large for
# PngImagePlugin.MAX_TEXT_CHUNK"): say what they limit instead.
_PILLOW_LIMITS = re.compile(r"\b\w+ImagePlugin\.MAX_\w+")


def _check_raw_dimensions(path: Path) -> None:
    """ImageError for a PNG or BMP header whose width or height is zero or negative. Pillow
    does not say so: a PNG of width 0 is "not a known image format" to it, and a BMP of width
    -64 one of 4294967232 pixels, "more than MAX_IMAGE_PIXELS"."""
    try:
        with open(path, "rb") as file:
            head = file.read(26)
    except OSError:
        return  # Pillow, next, says what is wrong
    if head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR" and len(head) >= 24:
        kind, (width, height) = "PNG", struct.unpack(">ii", head[16:24])  # at most 2**31 - 1
    elif head[:2] == b"BM" and len(head) >= 26 and struct.unpack("<I", head[14:18])[0] >= 40:
        kind, (width, height) = "BMP", struct.unpack("<ii", head[18:26])
        height = abs(height)  # a negative height is a top-down BMP
    else:
        return
    for name, value in (("width", width), ("height", height)):
        if value < 1:
            raise ImageError(
                f"image {shown(path)}: its {kind} header says {name} {value}, not at least 1"
            )


def image_header(path: Path) -> tuple[int, int, str, str]:
    """(width, height, format, mode) from the file's header alone (Pillow reads no pixels), or
    ImageError: not an image Pillow recognises, or one that claims more than MAX_IMAGE_PIXELS."""
    from PIL import Image  # only here: Pillow is matplotlib's, we read headers with it

    _check_raw_dimensions(path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(path) as header:
                width, height = header.size
                kind, mode = header.format or "?", header.mode
                # MPO (a JPEG with previews or a stereo pair's second view) counts as one.
                animated = kind != "MPO" and bool(getattr(header, "is_animated", False))
    except Image.DecompressionBombError:
        raise ImageError(
            f"image {shown(path)}: its header claims more than {MAX_IMAGE_PIXELS} pixels"
        ) from None
    except (OSError, SyntaxError, ValueError, EOFError, struct.error, MemoryError) as exc:
        detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if isinstance(exc, Image.UnidentifiedImageError):
            detail = "not a known image format (PNG, JPEG, BMP, TIFF, WebP, ...)"
        detail = _PILLOW_LIMITS.sub("Pillow's limit on metadata", detail)
        raise ImageError(f"cannot read image {shown(path)}: {detail}") from None
    if width < 1 or height < 1:
        raise ImageError(f"image {shown(path)}: its header says {width}x{height} pixels")
    if width * height > MAX_IMAGE_PIXELS:
        raise ImageError(
            f"image {shown(path)}: its header claims {width}x{height} pixels, more than "
            f"{MAX_IMAGE_PIXELS} are not decoded"
        )
    if animated:
        raise ImageError(
            f"image {shown(path)}: a {kind} of more than one frame (an animation or a "
            "multi-page file); camo reads still images: save the one frame as its own file"
        )
    return width, height, kind, mode


# What the native decoders write to file descriptor 2 while they decode, as lines. Those that
# mean damaged or unreadable data refuse the image, quoting the first; the rest are dropped as
# harmless: libpng's warnings (about ancillary chunks: iCCP and sRGB colour profiles, text,
# gamma; common in valid PNGs, and none changes the pixels read), libjpeg's other warnings
# (an unknown JFIF revision, a thumbnail's size) and OpenCV's notes on a decoded image.
DECODER_DAMAGE = re.compile(
    r"libpng error|Premature end of JPEG|Corrupt JPEG data|JPEG datastream contains no image"
    r"|Invalid (SOS|JPEG)|Bogus|TIFF.*\b([Ee]rror|Sorry|[Cc]annot|can ?not)\b|\[\s*ERROR:"
)
_OPENCV_LOG = re.compile(r"^\[\s*\w+:[^\]]*\]\s+(?:global\s+)?\S+:\d+\s+\S+\s+(.*)$")
_STDERR = threading.Lock()  # fd 2 is the process's: one capture at a time
MAX_DECODER_TEXT = 64 * 1024  # read of what was written
MAX_QUOTED = 200  # characters of a decoder's message in camo's one line


def decoder_messages(text: str) -> list[str]:
    """What native decoders wrote, one message a line, OpenCV's log prefix taken off."""
    lines = (line.strip() for line in text.splitlines())
    return [(_OPENCV_LOG.sub(r"\1", line)).strip() for line in lines if line]


def _captured_stderr(decode):
    """decode()'s result and what native code wrote to file descriptor 2 meanwhile (libpng,
    libjpeg and OpenCV's logging write there, around camo's one line of error), through a
    pipe a thread drains (no disk needed, no writer blocked on a full pipe). Anything another
    thread writes to fd 2 in that window is taken too: decoding is short."""
    with _STDERR:
        sys.stderr.flush()
        try:
            saved = os.dup(2)
        except OSError:  # no fd 2 (started with 2>&-): nothing to keep apart
            return decode(), ""
        try:
            read_end, write_end = os.pipe()
        except OSError:  # out of file descriptors: decode as OpenCV alone would
            os.close(saved)
            return decode(), ""
        chunks: list[bytes] = []

        def drain() -> None:
            kept = 0
            while block := os.read(read_end, 65536):
                if kept < MAX_DECODER_TEXT:
                    chunks.append(block)
                    kept += len(block)
            os.close(read_end)

        drainer = threading.Thread(target=drain, name="decoder-stderr", daemon=True)
        drainer.start()
        try:
            os.dup2(write_end, 2)
            try:
                result = decode()
            finally:
                os.dup2(saved, 2)
        finally:
            os.close(write_end)  # the drainer reads to its end
            os.close(saved)
            drainer.join()
    return result, b"".join(chunks)[:MAX_DECODER_TEXT].decode("utf-8", "replace")


def _decoded(path: Path, flags: int) -> np.ndarray | None:
    """cv2.imread, with what the decoders write to fd 2 kept from the terminal: an image they
    say is damaged (a truncated JPEG decodes, half grey, with only a warning) is an
    ImageError quoting their first word on it."""
    try:
        image, text = _captured_stderr(lambda: cv2.imread(str(path), flags))
    except cv2.error as exc:
        detail = str(exc).strip().splitlines()[-1].strip() if str(exc).strip() else "cv2.error"
        raise ImageError(f"cannot decode image {shown(path)}: {detail}") from None
    messages = decoder_messages(text)
    damage = [m for m in messages if DECODER_DAMAGE.search(m)]
    if damage or (image is None and messages):
        said = (damage or messages)[0][:MAX_QUOTED]
        raise ImageError(f"cannot decode image {shown(path)}: the decoder says {said!r}")
    return image


def load_image(path: str | Path) -> np.ndarray:
    """Read an image as uint8, grey (H x W) or BGR (H x W x 3); alpha is dropped.

    Checked level by level, each failure an ImageError in one line: the path (empty, too long,
    missing, a folder, unreadable), the size on disk (MAX_IMAGE_BYTES), the header's dimensions
    before any pixel is decoded (at least 1, MAX_IMAGE_PIXELS in all) and its frames (one: an
    animation or a multi-page file is refused), the decoding (refused if the decoder says the
    data is damaged, see DECODER_DAMAGE; nothing it writes reaches stderr), and what it decoded
    to (dimensions as the header said, 1, 3 or 4 channels of 8 or 16 bits or float)."""
    path = checked_file(path, "image", MAX_IMAGE_BYTES, ImageError)
    width, height, kind, _ = image_header(path)
    image = _decoded(path, cv2.IMREAD_UNCHANGED)
    if image is None or image.size == 0:
        raise ImageError(
            f"cannot read image (not an image OpenCV understands, or corrupt): {shown(path)}"
        )
    if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (1, 3, 4)):
        raise ImageError(f"image {shown(path)}: {image.shape} is not 1, 3 or 4 channels")
    if image.dtype not in DEPTHS:
        raise ImageError(f"image {shown(path)}: pixels of {image.dtype} are not read")
    if image.shape[0] * image.shape[1] != width * height:
        raise ImageError(
            f"image {shown(path)}: decoded as {image.shape[1]}x{image.shape[0]} pixels, its "
            f"{kind} header says {width}x{height}"
        )
    if image.dtype != np.uint8:
        # 16-bit or float images: bring to 0..255 the way OpenCV's IMREAD_COLOR does.
        image = _decoded(path, cv2.IMREAD_COLOR)
        if image is None or image.dtype != np.uint8:
            raise ImageError(f"cannot convert image {shown(path)} to 8 bits")
    if image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    return image


def with_contrast(image: np.ndarray, contrast: float) -> np.ndarray:
    """The image with its contrast scaled by `contrast` (0 < contrast <= 1): every value pulled
    toward the image's mean, v' = m + contrast * (v - m), rounded to uint8 by OpenCV."""
    if not 0.0 < contrast <= 1.0:
        raise ImageError(f"--contrast must be in (0, 1] (got {contrast:g})")
    mean = float(image.mean())
    return cv2.addWeighted(image, contrast, image, 0.0, (1.0 - contrast) * mean)


def image_digest(image: np.ndarray) -> str:
    """A short fingerprint of an image's pixels (and shape): the run's setup lists its
    backgrounds' so that a process takes a background only if it is one of them."""
    image = np.ascontiguousarray(image, dtype=np.uint8)
    shape = "x".join(str(n) for n in image.shape).encode()
    return hashlib.sha256(shape + b":" + image.tobytes()).hexdigest()[:32]


def to_gray(image: np.ndarray, profile: str) -> np.ndarray:
    """Grey values 0..255 as float64.

    paper: BT.601 luma exactly as cv2.cvtColor(BGR2GRAY) rounds it;
    droplet: 0.5 R + 0.5 G (fw rgb_weights), unrounded. A grey image is used as is.
    """
    if image.ndim == 2:
        return image.astype(np.float64)
    if profile == "paper":
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY).astype(np.float64)
    bgr = image.astype(np.float64)
    return 0.5 * bgr[:, :, 2] + 0.5 * bgr[:, :, 1]


def rgb_to_gray(r: float, g: float, b: float, profile: str) -> float:
    """One colour reading (0..255 per channel) as the profile's grey value, exactly as to_gray does
    for a pixel of that colour: r = g = b = v gives v."""
    if not all(0 <= c <= 255 and float(c).is_integer() for c in (r, g, b)):
        raise ValueError(f"a colour reading has integer channels in 0..255 (got {r}, {g}, {b})")
    pixel = np.array([[[b, g, r]]], dtype=np.uint8)
    return float(to_gray(pixel, profile)[0, 0])


@dataclass(frozen=True)
class Calibration:
    """A real sensor's grey = gain * profile_grey(r, g, b) + offset, clipped to 0..255
    (identity by default)."""

    gain: float = 1.0
    offset: float = 0.0

    def __post_init__(self) -> None:
        gain_ok = math.isfinite(self.gain) and 0 < self.gain <= MAX_GAIN
        if not (gain_ok and math.isfinite(self.offset) and abs(self.offset) <= MAX_OFFSET):
            raise ParameterError(
                f"calibration: gain must be in (0, {MAX_GAIN:g}] and offset within "
                f"+-{MAX_OFFSET:g} "
                f"(got gain {self.gain}, offset {self.offset})"
            )

    def apply(self, grey: float) -> float:
        return min(255.0, max(0.0, self.gain * grey + self.offset))

    @classmethod
    def from_yaml(cls, path: str | Path) -> Calibration:
        """A YAML file (read by `inputs.strict_yaml.read_yaml`: a regular file of at most
        CALIBRATION_MAX_BYTES) mapping `gain` and/or `offset` to numbers (not text, not
        true/false): gain in (0, MAX_GAIN], offset within +-MAX_OFFSET."""
        data = read_yaml(path, "calibration", CALIBRATION_MAX_BYTES, ParameterError)
        name = shown(path)
        if data is None:
            data = {}
        if not isinstance(data, dict) or set(data) - {"gain", "offset"}:
            raise ParameterError(f"calibration {name} may hold only `gain` and `offset`")
        values = {"gain": 1.0, "offset": 0.0}
        for key, value in data.items():
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ParameterError(
                    f"calibration {name}: {key} must be a number (got {described(value)})"
                )
            values[key] = float(value)
        gain, offset = values["gain"], values["offset"]
        if not (math.isfinite(gain) and 0 < gain <= MAX_GAIN):
            raise ParameterError(
                f"calibration {name}: gain must be in (0, {MAX_GAIN:g}] (got {described(gain)})"
            )
        if not (math.isfinite(offset) and abs(offset) <= MAX_OFFSET):
            raise ParameterError(
                f"calibration {name}: offset must be within +-{MAX_OFFSET:g} "
                f"(got {described(offset)})"
            )
        return cls(gain, offset)


def block_means(gray: np.ndarray, rows: int, cols: int) -> np.ndarray:
    """Mean grey value of the image block each robot covers (rows x cols float64)."""
    height, width = gray.shape[:2]
    if height < rows or width < cols:
        raise ImageError(
            f"image of {width}x{height} pixels is smaller than the {cols}x{rows} robot grid"
        )
    return cv2.resize(gray.astype(np.float64), (cols, rows), interpolation=cv2.INTER_AREA)


def sense_image(image: np.ndarray, rows: int, cols: int, profile: str) -> np.ndarray:
    return block_means(to_gray(image, profile), rows, cols)


def to_rgb(image: np.ndarray) -> np.ndarray:
    """An image's sRGB channels (H x W x 3, float64, 0..255); a grey image is that grey."""
    if image.ndim == 2:
        return np.repeat(image.astype(np.float64)[:, :, None], 3, axis=2)
    return image[:, :, ::-1].astype(np.float64)  # OpenCV's BGR


def sense_colours(image: np.ndarray, rows: int, cols: int) -> np.ndarray:
    """The mean colour of the image block each robot covers (rows x cols x 3, sRGB float64),
    as block_means takes the mean grey."""
    return block_means(to_rgb(image), rows, cols)


def noisy_value(seed: int, robot: int, value: float, rho_meas: float) -> float:
    """One robot's sensed value after measurement error (scalar)."""
    if rho_meas > 0.0 and rng.uniform(seed, rng.STREAM_SENSOR_REPLACED, 0, robot, 0) < rho_meas:
        return float(math.floor(256 * rng.uniform(seed, rng.STREAM_SENSOR_VALUE, 0, robot, 0)))
    return float(value)


def noisy_colour(
    seed: int, robot: int, rgb: tuple[float, float, float], rho_meas: float
) -> tuple[float, float, float]:
    """One robot's sensed colour after measurement error: a reading replaced by noise is the
    noise's grey (the draws of noisy_value: a robot's grey and colour are replaced together)."""
    if rho_meas > 0.0 and rng.uniform(seed, rng.STREAM_SENSOR_REPLACED, 0, robot, 0) < rho_meas:
        grey = float(math.floor(256 * rng.uniform(seed, rng.STREAM_SENSOR_VALUE, 0, robot, 0)))
        return grey, grey, grey
    return float(rgb[0]), float(rgb[1]), float(rgb[2])


def _replaced(shape: tuple[int, ...], seed: int, rho_meas: float, exempt: np.ndarray | None):
    """Which robots' readings measurement error replaces (bool, `shape`), and the greys they
    read instead."""
    ids = np.arange(math.prod(shape), dtype=np.uint64).reshape(shape)
    zero = np.uint64(0)
    replaced = rng.uniform_array(seed, rng.STREAM_SENSOR_REPLACED, 0, ids, zero) < rho_meas
    if exempt is not None:
        replaced &= ~exempt
    noise = np.floor(256 * rng.uniform_array(seed, rng.STREAM_SENSOR_VALUE, 0, ids, zero))
    return replaced, noise


def apply_noise(
    sensed: np.ndarray, seed: int, rho_meas: float, exempt: np.ndarray | None = None
) -> np.ndarray:
    """The whole grid's sensed values after measurement error (vectorised).

    `exempt` marks robots whose readings are real (a bridged Droplet): never replaced.
    """
    out = np.array(sensed, dtype=np.float64, copy=True)
    if rho_meas <= 0.0:
        return out
    replaced, noise = _replaced(out.shape, seed, rho_meas, exempt)
    out[replaced] = noise[replaced]
    return out


def apply_colour_noise(
    colours: np.ndarray, seed: int, rho_meas: float, exempt: np.ndarray | None = None
) -> np.ndarray:
    """apply_noise for sensed colours (rows x cols x 3): a replaced reading is its noise grey."""
    out = np.array(colours, dtype=np.float64, copy=True)
    if rho_meas <= 0.0:
        return out
    replaced, noise = _replaced(out.shape[:-1], seed, rho_meas, exempt)
    out[replaced] = noise[replaced][:, None]
    return out


# ---- a simulated robot's sensor: the projected image ------------------------------------------


@dataclass(frozen=True)
class Reading:
    """What a robot's sensor gives: a grey level, and whether it is a real sensor's (a real
    reading gets no simulated measurement noise)."""

    value: float
    real: bool = False
    rgb: tuple[float, float, float] | None = None  # its colour (sRGB); None: the grey's


FRAMES_KEPT = 256  # a process keeps the sensed grids of this many frames (a few seconds of video)


class Projection:
    """The frames projected so far, by the projector's frame number, as sensed grids (one resize
    per frame, shared by all the robots of a process); the latest FRAMES_KEPT of them."""

    def __init__(
        self, rows: int, cols: int, profile: str, sample=None, sample_colours=None
    ) -> None:
        self.rows, self.cols, self.profile = rows, cols, profile
        # How an image becomes the robots' greys (rows x cols, by robot id): block means, or
        # on a --layout the means round the robots' positions (layout.sense_at); and their
        # colours (rows x cols x 3) likewise.
        self.sample = sample or (lambda image: sense_image(image, rows, cols, profile))
        self.sample_colours = sample_colours or (lambda image: sense_colours(image, rows, cols))
        self.frames: dict[int, np.ndarray] = {}
        self.colours: dict[int, np.ndarray] = {}
        self.stamps: dict[int, float] = {}  # when each frame was projected (ROS time, s)
        self.newest = -1
        self.protected: set[int] = {0}  # frames robots' rounds still read: never let go
        self.substituted = 0  # reads of a frame let go (or never held), answered with a later

    def add(self, image: np.ndarray, number: int | None = None, stamp: float = 0.0) -> int:
        """Frame `number` (by default the one after the newest); its number. Raises ImageError
        for an image smaller than the grid."""
        number = self.newest + 1 if number is None else number
        self.frames[number] = self.sample(image)
        self.colours[number] = self.sample_colours(image)
        self.stamps[number] = stamp
        self.newest = max(self.newest, number)
        if len(self.frames) > FRAMES_KEPT:
            loose = sorted(n for n in self.frames if n not in self.protected)
            for oldest in loose[: len(self.frames) - FRAMES_KEPT]:
                del self.frames[oldest], self.stamps[oldest], self.colours[oldest]
        return number

    def grid(self, number: int) -> np.ndarray | None:
        """Frame `number`'s grid; None while it has not come. A frame let go already (a round
        its process joined very late) is read as the oldest frame kept after it."""
        kept = self.kept(number)
        return None if kept is None else self.frames[kept]

    def colour_grid(self, number: int) -> np.ndarray | None:
        """Frame `number`'s colours (rows x cols x 3), as grid reads its greys."""
        kept = self.kept(number)
        return None if kept is None else self.colours[kept]

    def kept(self, number: int) -> int | None:
        """The frame read for frame `number` (itself, or the oldest kept after it), or None."""
        if number in self.frames:
            return number
        if number < self.newest:
            later = [n for n in self.frames if n > number]
            if later:
                self.substituted += 1
                return min(later)
        return None

    @property
    def latest(self) -> np.ndarray | None:
        return self.frames.get(self.newest)


class ProjectedSensor:
    """A simulated robot's sensor: its cell's block mean of the frame of its round."""

    def __init__(self, projection: Projection, row: int, col: int) -> None:
        self.projection, self.row, self.col = projection, row, col
        self.frame = 0

    def read(self) -> Reading | None:
        kept = self.projection.kept(self.frame)
        if kept is None:
            return None
        grey = float(self.projection.frames[kept][self.row, self.col])
        r, g, b = self.projection.colours[kept][self.row, self.col].tolist()
        return Reading(grey, rgb=(r, g, b))

    def next_round(self, frame: int) -> None:
        self.frame = frame  # a round camouflages against the frame it is named after

    def ok(self) -> bool:
        return True
