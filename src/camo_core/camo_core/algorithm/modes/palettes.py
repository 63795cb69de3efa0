"""What a robot shows, and what it averages to choose it: the histogram averaged beside p
(none, greys, colours) and the palette and display (two tones, --levels K, --colours K).

Each is one object chosen once from a run's parameters (`modes.modes_of`). A histogram says
what each robot adds to the vector consensus averages and what a valid one looks like; a
palette turns a robot's averaged histogram into what it can show, sets its formation state's
layers, and says the grey or colour a state shows, for one robot and for the whole grid.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from camo_core.algorithm import colours, levels
from camo_core.algorithm.sensing import to_gray

RGB = tuple[int, int, int]

# ---- histograms: what consensus averages beside p ------------------------------------------


def _shares(values: Sequence[float], tolerance: float) -> bool:
    """Finite entries in [0, 1] that sum to 1 (up to `tolerance`)."""
    return all(math.isfinite(x) and -tolerance <= x <= 1.0 + tolerance for x in values) and (
        abs(sum(values) - 1.0) <= tolerance
    )


class NoHistogram:
    """The paper's: consensus averages p alone."""

    size = 0

    def start_vector(self, grey: float, rgb: Sequence[float]) -> tuple[float, ...]:
        return ()

    def start_vectors(self, greys: np.ndarray, rgbs: np.ndarray | None) -> np.ndarray | None:
        return None

    def ok(self, tail: Sequence[float], tolerance: float) -> bool:
        return len(tail) == 0


class GreyHistogram(NoHistogram):
    """--levels: the one-hot of a robot's 16-grey bin, then its grey in that bin (levels.py)."""

    size = levels.SIZE

    def start_vector(self, grey: float, rgb: Sequence[float]) -> tuple[float, ...]:
        return levels.start_vector(grey)

    def start_vectors(self, greys: np.ndarray, rgbs: np.ndarray | None) -> np.ndarray:
        return levels.start_vectors(greys)

    def ok(self, tail: Sequence[float], tolerance: float) -> bool:
        """16 shares summing to 1, then per bin a sum of greys that lies between the bin's
        least and greatest grey times its share."""
        bins = levels.BINS
        if len(tail) != self.size or not all(math.isfinite(x) for x in tail):
            return False
        histogram, sums = tail[:bins], tail[bins:]
        if not _shares(histogram, tolerance):
            return False
        return all(
            levels.BIN_WIDTH * b * h - tolerance * 256 <= s <= 256 * h + tolerance * 256
            for b, (h, s) in enumerate(zip(histogram, sums, strict=True))
        )


MAX_LAB = 128.0  # |a*|, |b*| of sRGB colours stay below it (and L* within 0..100)


class ColourHistogram(NoHistogram):
    """--colours: the one-hot of a robot's colour bin, then its L*, a*, b* there (colours.py)."""

    size = colours.SIZE

    def start_vector(self, grey: float, rgb: Sequence[float]) -> tuple[float, ...]:
        return colours.start_vector(rgb)

    def start_vectors(self, greys: np.ndarray, rgbs: np.ndarray | None) -> np.ndarray:
        assert rgbs is not None  # colour sensing gives colours (sensing.ColourSensing)
        return colours.start_vectors(rgbs)

    def ok(self, tail: Sequence[float], tolerance: float) -> bool:
        """64 shares summing to 1, then per bin sums of L*, a* and b* within what colours of
        that share can add up to."""
        if len(tail) != self.size or not all(math.isfinite(x) for x in tail):
            return False
        histogram = tail[: colours.BINS]
        if not _shares(histogram, tolerance):
            return False
        slack = tolerance * 256
        lightness, a, b = (tail[colours.BINS * k : colours.BINS * (k + 1)] for k in (1, 2, 3))
        return all(
            -slack <= lightness[k] <= 100.0 * h + slack
            and abs(a[k]) <= MAX_LAB * h + slack
            and abs(b[k]) <= MAX_LAB * h + slack
            for k, h in enumerate(histogram)
        )


Histogram = NoHistogram | GreyHistogram | ColourHistogram

# ---- palettes: what a robot shows ------------------------------------------------------------


@dataclass(frozen=True)
class RobotPalette:
    """One robot's palette once consensus ends: its greys (--levels, darkest first), its colours
    (--colours, sRGB darkest first) and the two of them it shows (on, off), and the formation
    state it starts from where the palette sets it (None: its sensed grey's, unchanged)."""

    greys: tuple[int, ...] = ()
    colours: tuple[RGB, ...] = ()
    shades: tuple[int, int] = (0, 0)
    initial: int | None = None


@dataclass(frozen=True)
class GridPalette:
    """RobotPalette for every robot (rows x cols x ...), None where the palette has none."""

    greys: np.ndarray | None = None
    colours: np.ndarray | None = None
    shades: np.ndarray | None = None
    initial: np.ndarray | None = None

    def kept(self, where: np.ndarray, previous: GridPalette) -> GridPalette:
        """This palette, but `previous`'s where `where` (robots that keep theirs)."""

        def mixed(now, before):
            if now is None or before is None:
                return now
            mask = where.reshape(where.shape + (1,) * (now.ndim - where.ndim))
            return np.where(mask, before, now)

        return GridPalette(
            mixed(self.greys, previous.greys),
            mixed(self.colours, previous.colours),
            mixed(self.shades, previous.shades),
            self.initial,
        )


class TwoTones:
    """The paper's: black where the pattern is on, white where it is off."""

    name = "two tones"
    shows = ""  # what it shows beyond black and white: "greys" or "colours"
    k = 0  # the palette's size, as --levels and --colours count it (0: the paper's two)
    layers = 1  # bits of a formation state, each formed on its own
    colour = False  # it shows colours (not only greys)

    @property
    def states(self) -> range:
        """The values a formation state can take."""
        return range(2**self.layers)

    def robot(self, tail: Sequence[float], sensed: float, sensed_rgb) -> RobotPalette:
        return RobotPalette()

    def grid(self, tails: np.ndarray, sensed: np.ndarray, sensed_rgb) -> GridPalette:
        return GridPalette()

    def shown(self, state: int, palette: RobotPalette) -> RGB:
        """The colour (sRGB) a robot with this palette shows in `state`."""
        grey = 0 if state == 1 else 255
        return grey, grey, grey

    def shown_grid(self, states: np.ndarray, palette: GridPalette) -> np.ndarray:
        """What every robot shows: greys (rows x cols, 0..255), or colours (... x 3) where the
        palette shows colours."""
        return np.where(states == 1, 0, 255).astype(np.int64)

    def shown_greys(self, shown: np.ndarray, profile: str) -> np.ndarray:
        """The greys of what shown_grid gives (a colour's by the profile's weights)."""
        return shown

    def frame(self, states: np.ndarray, palette: GridPalette) -> np.ndarray:
        """What a GIF's formation frame holds of every robot: its state (-1: unknown); with a
        palette of greys or colours, what it shows (rows x cols, or x 3)."""
        return states

    def frame_rgb(self, frame: np.ndarray) -> np.ndarray:
        """A frame's cells as RGB in 0..1 (... x 3), mid-grey where unknown (< 0)."""
        grey = np.where(frame < 0, 0.5, np.where(frame == 1, 0.0, 1.0))
        return np.repeat(grey[..., None], 3, axis=-1)

    def describe(self) -> str:
        return ""

    @property
    def chosen_by(self) -> str:
        """The option that chose it, beyond the paper's (two tones: none)."""
        return f"{self.name} {self.k} (--{self.name} {self.k})" if self.k else ""


class LevelPalette(TwoTones):
    """--levels K: K greys chosen by multi-Otsu on the averaged grey histogram; K - 1 binary
    layers, a robot with L layers on showing the (K - L)th grey (levels.py)."""

    name = "levels"
    shows = "greys"

    def __init__(self, k: int) -> None:
        self.k = k
        self.layers = k - 1

    def robot(self, tail: Sequence[float], sensed: float, sensed_rgb) -> RobotPalette:
        cuts, greys = levels.palette(tail, self.k)
        return RobotPalette(greys=greys, initial=levels.initial_layers(sensed, cuts))

    def grid(self, tails: np.ndarray, sensed: np.ndarray, sensed_rgb) -> GridPalette:
        cuts, greys = levels.palettes(tails, self.k)
        initial = np.zeros(sensed.shape, np.uint8)
        for k in range(self.k - 1):
            initial |= (sensed < cuts[..., k]).astype(np.uint8) << np.uint8(k)
        return GridPalette(greys=greys, initial=initial)

    def shown(self, state: int, palette: RobotPalette) -> RGB:
        grey = levels.shown(state, palette.greys)
        return grey, grey, grey

    def shown_grid(self, states: np.ndarray, palette: GridPalette) -> np.ndarray:
        assert palette.greys is not None
        return levels.shown_grid(states, palette.greys)

    def frame(self, states: np.ndarray, palette: GridPalette) -> np.ndarray:
        """The greys shown (-1 where the state is unknown)."""
        return np.where(states < 0, -1, self.shown_grid(np.maximum(states, 0), palette))

    def frame_rgb(self, frame: np.ndarray) -> np.ndarray:
        grey = np.where(frame < 0, 0.5, frame.astype(float) / 255)
        return np.repeat(grey[..., None], 3, axis=-1)

    def describe(self) -> str:
        return f"{self.k} levels"


class ColourPalette(TwoTones):
    """--colours K: K colours by k-means in CIELAB over the averaged colour histogram; a robot
    shows the two of them that bracket its own colour, the darker where its pattern is on
    (colours.py)."""

    name = "colours"
    shows = "colours"
    colour = True

    def __init__(self, k: int) -> None:
        self.k = k

    def robot(self, tail: Sequence[float], sensed: float, sensed_rgb) -> RobotPalette:
        chosen, shades = colours.robot_palette(tail, sensed_rgb, self.k)
        return RobotPalette(colours=chosen, shades=shades)

    def grid(self, tails: np.ndarray, sensed: np.ndarray, sensed_rgb) -> GridPalette:
        chosen, shades = colours.palettes(tails, sensed_rgb, self.k)
        return GridPalette(colours=chosen, shades=shades)

    def shown(self, state: int, palette: RobotPalette) -> RGB:
        return colours.shown(state, palette.shades, palette.colours)

    def shown_grid(self, states: np.ndarray, palette: GridPalette) -> np.ndarray:
        assert palette.colours is not None and palette.shades is not None
        return colours.shown_grid(states, palette.shades, palette.colours)

    def shown_greys(self, shown: np.ndarray, profile: str) -> np.ndarray:
        return to_gray(shown[..., ::-1].astype(np.uint8), profile)

    def frame(self, states: np.ndarray, palette: GridPalette) -> np.ndarray:
        """The colours shown (... x 3; -1 where the state is unknown)."""
        shown = self.shown_grid(np.maximum(states, 0), palette)
        return np.where(states[..., None] < 0, -1, shown)

    def frame_rgb(self, frame: np.ndarray) -> np.ndarray:
        return np.where(frame < 0, 0.5, frame.astype(float) / 255)

    def describe(self) -> str:
        return f"{self.k} colours"


Palette = TwoTones | LevelPalette | ColourPalette
