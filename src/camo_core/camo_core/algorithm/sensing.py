"""docs/algorithm.md §2.1: what each robot senses of the projected background."""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from camo_core.algorithm import rng
from camo_core.inputs.files import shown
from camo_core.inputs.images import ImageError
from camo_core.inputs.strict_yaml import described, read_yaml
from camo_core.schema import ParameterError

CALIBRATION_MAX_BYTES = 64 * 1024  # a calibration is two lines
MAX_GAIN = 1e6  # a gain above this maps every grey but black to white: not a calibration
MAX_OFFSET = 1e6  # as far: an offset beyond +-255 already clips every grey


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


def check_covers(width: int, height: int, rows: int, cols: int, what: str = "image") -> None:
    """ImageError unless an image of `width` x `height` pixels gives each robot of the
    `rows` x `cols` grid a pixel at least."""
    if height < rows or width < cols:
        raise ImageError(
            f"{what} of {width}x{height} pixels is smaller than the {cols}x{rows} robot grid"
        )


def block_means(gray: np.ndarray, rows: int, cols: int) -> np.ndarray:
    """Mean grey value of the image block each robot covers (rows x cols float64)."""
    height, width = gray.shape[:2]
    check_covers(width, height, rows, cols)
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
    as block_means takes the mean grey. A grey image's colours are its greys' means (the same
    numbers as its three channels' means, a third of the work)."""
    if image.ndim == 2:
        return np.repeat(block_means(image.astype(np.float64), rows, cols)[:, :, None], 3, axis=2)
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
