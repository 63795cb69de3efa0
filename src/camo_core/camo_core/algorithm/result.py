"""What one camouflage run produced, and its summary.json form."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from camo_core.algorithm import colours, levels
from camo_core.algorithm.modes import Modes, modes_of
from camo_core.algorithm.modes.descriptors import majority_name
from camo_core.algorithm.orientation import angle_of
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.patterns import MOTTLED
from camo_core.schema import values, with_role

# What every summary.json holds: the run's parameters that describe it (declared with
# summary=True), then what it computed.
SUMMARY_KEYS = (
    *with_role(CamoParams, "summary"),
    "pattern",
    "votes",
    "patterns",
    "mean_p",
    "sensed",
    "initial",
    "final",
    "display",
    "grey_distance",
    "colour_distance",
    "consensus_trace",
    "elapsed_s",
)


def pattern_of(summary: dict) -> str:
    """A summary's pattern with its direction, as sweeps compare them: horizontal, vertical or
    mottled; with --orientation any mottled or stripes_<degrees>."""
    angle = summary.get("orientation_deg")
    return summary["pattern"] if angle is None else f"{summary['pattern']}_{angle}"


def label_of(pattern: str, angle: int | None) -> str:
    """A pattern as a figure or a console names it: "vertical", "stripes at 45°"."""
    return pattern if angle is None else f"stripes at {angle}°"


def pattern_said(summary: dict) -> str:
    """How a console line names a summary's pattern: "vertical (horizontal 3, vertical 61,
    mottled 0)"; with --orientation any "stripes at 30° (stripes_15 110, stripes_30 146)", the
    selections no robot made left out."""
    label = label_of(summary["pattern"], summary.get("orientation_deg"))
    oriented = "orientation_deg" in summary
    counts = ", ".join(f"{k} {v}" for k, v in summary["votes"].items() if v or not oriented)
    return f"{label} ({counts})"


# Robots x width up to which p's statistics are taken with numpy rather than the compiled
# kernels: importing numba and loading its kernels costs a process most of a second, more than
# a small swarm's every step together (the launcher of a 3x3 run, a sweep's trial).
SMALL_P = 1 << 16


def _flat(p: np.ndarray) -> np.ndarray:
    p = np.asarray(p, dtype=np.float64)
    return np.ascontiguousarray(p).reshape(-1, p.shape[-1])


def _small(flat: np.ndarray) -> bool:
    """numpy gives the kernels' very bits here: sums in robot-id order (add.accumulate adds
    one robot at a time, where sum would add pairwise), least and greatest alike without NaN."""
    return 0 < flat.size <= SMALL_P and not np.isnan(flat).any()


def mean_p(p: np.ndarray) -> np.ndarray:
    """Mean p over robots (p: ... x width), summed in robot-id order by every driver."""
    flat = _flat(p)
    if _small(flat):
        return np.add.accumulate(flat, axis=0)[-1] / len(flat)
    from camo_core.algorithm import kernels  # numba: not for a robot's process

    return kernels.mean_p(flat)


def p_stats(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """mean_p(p), and width x 2: the least and the greatest p over robots, per entry."""
    flat = _flat(p)
    if _small(flat):
        spread = np.stack([flat.min(axis=0), flat.max(axis=0)], axis=1)
        return np.add.accumulate(flat, axis=0)[-1] / len(flat), spread
    from camo_core.algorithm import kernels  # numba: not for a robot's process

    return kernels.p_stats(flat)


@dataclass
class RunResult:
    params: CamoParams
    sensed: np.ndarray  # rows x cols float64, after measurement noise
    votes: np.ndarray  # rows x cols int, the local one-hot votes (pattern index)
    p: np.ndarray  # rows x cols x width float64, after the last consensus step
    selected: np.ndarray  # rows x cols int, each robot's selected pattern
    initial: np.ndarray  # rows x cols uint8, the binarised initial states
    final: np.ndarray  # rows x cols uint8, the states after the last formation step
    # (consensus_steps + 1) x width, mean p before step 0 and after each
    consensus_trace: np.ndarray
    elapsed_s: float = 0.0
    alive: np.ndarray | None = None  # rows x cols bool; None means every robot took part
    # (consensus_steps + 1) x width x 2: the least and the greatest p over robots at each step, the
    # spread the figure draws around the mean; None where a driver did not keep it.
    consensus_range: np.ndarray | None = None
    # --levels: rows x cols x K, the greys each robot's palette holds, darkest first.
    palette: np.ndarray | None = None
    # --layout: robots x 2, each robot's x and y (y down) in spacings; None on the grid.
    positions: np.ndarray | None = None
    # rows x cols x 3 float64: the colours robots sensed (sRGB 0-255, after measurement
    # error); None where the driver had none (a grey reading's colour is its grey).
    sensed_rgb: np.ndarray | None = None
    # --colours: rows x cols x K x 3, each robot's palette (sRGB, darkest first), and rows x
    # cols x 2, the two of it the robot shows (where its pattern is on, where it is off).
    palette_rgb: np.ndarray | None = None
    shades: np.ndarray | None = None

    @property
    def modes(self) -> Modes:
        """The run's variations (those its parameters choose)."""
        return modes_of(self.params)

    @property
    def display(self) -> np.ndarray:
        """rows x cols, the grey (0-255) each robot shows: black on, white off; with --levels
        its palette's grey for the layers it has on."""
        if self.palette is None:
            return np.where(self.final == 1, 0, 255).astype(np.int64)
        return levels.shown_grid(self.final, self.palette)

    @property
    def display_rgb(self) -> np.ndarray:
        """rows x cols x 3, the colour (sRGB 0-255) each robot shows: with --colours its
        palette's, else its grey."""
        if self.palette_rgb is None or self.shades is None:
            return np.repeat(self.display[..., None], 3, axis=-1)
        return colours.shown_grid(self.final, self.shades, self.palette_rgb)

    @property
    def colour_distance(self) -> float | None:
        """How far the colours shown are from the colours sensed: the mean CIEDE2000 over the
        robots that took part; None where the sensed colours are not known."""
        if self.sensed_rgb is None:
            return None
        took_part = np.isfinite(self.sensed_rgb).all(axis=-1)
        if self.alive is not None:
            took_part &= self.alive
        greys = self.palette_rgb is None or self.shades is None  # what display_rgb repeats
        shown = self.display[took_part] if greys else self.display_rgb[took_part]
        return colours.colour_distance(shown, self.sensed_rgb[took_part])

    @property
    def grey_distance(self) -> float:
        """How far the greys shown are from the greys sensed: the Wasserstein-1 distance between
        the two sets (the mean gap between them sorted), over the robots that took part."""
        sensed = np.asarray(self.sensed, dtype=np.float64)
        shown = self.display
        if self.modes.palette.colour and self.palette_rgb is not None:  # the colours' greys
            shown = self.modes.palette.shown_greys(self.display_rgb, self.params.profile)
        took_part = np.isfinite(sensed)  # a partial run's robots that never sensed hold NaN
        if self.alive is not None:
            took_part &= self.alive
        shown, sensed = shown[took_part], sensed[took_part]
        if shown.size == 0:
            return 0.0
        gaps = np.abs(np.sort(shown.ravel()) - np.sort(sensed.ravel()))
        return float(np.mean(gaps))

    @property
    def codes(self) -> range:
        """The pattern codes a robot of this run can select: the paper's three, or mottled and
        the twelve stripe directions of --orientation any."""
        return self.modes.descriptor.codes

    @property
    def selection_counts(self) -> dict[str, int]:
        chosen = self.selected if self.alive is None else self.selected[self.alive]
        name_of = self.modes.descriptor.name_of
        return {name_of(k): int(np.count_nonzero(chosen == k)) for k in self.codes}

    def chosen_names(self) -> np.ndarray:
        """rows x cols: each robot's chosen pattern by name (None where a robot did not finish
        or chose none)."""
        codes = self.modes.descriptor.codes
        names = np.array([None] * (codes.stop + 1), dtype=object)
        names[list(codes)] = [self.modes.descriptor.name_of(k) for k in codes]
        chosen = np.asarray(self.selected, dtype=np.int64)
        known = (chosen >= 0) & (chosen < codes.stop)
        if self.alive is not None:
            known &= self.alive
        return names[np.where(known, chosen, codes.stop)]

    @property
    def majority_code(self) -> int:
        """The selection most robots made; a tie for the most goes to mottled."""
        counts = list(self.selection_counts.values())
        best = max(counts)
        winners = [k for k, c in zip(self.codes, counts, strict=True) if c == best]
        return winners[0] if len(winners) == 1 else MOTTLED

    @property
    def majority_pattern(self) -> str:
        """horizontal, vertical or mottled; with --orientation any stripes or mottled."""
        return majority_name(self.majority_code)

    @property
    def orientation_deg(self) -> int | None:
        """The majority's stripe direction (--orientation any), None for mottled."""
        return angle_of(self.majority_code)

    @property
    def majority_label(self) -> str:
        """The majority pattern as a figure or a console names it ("stripes at 45°")."""
        return label_of(self.majority_pattern, self.orientation_deg)

    def summary(self, arrays: bool = False) -> dict[str, Any]:
        """The summary.json document. arrays: the sensed, initial and final grids stay NumPy
        arrays (float64, int64) instead of nested lists, which write_summary serialises directly;
        either way the written file holds the same values."""
        p = self.p if self.alive is None else self.p[self.alive]
        params = self.params
        grid: Callable[[np.ndarray], Any]  # (a conditional expression of the two is untyped)
        if arrays and self.alive is None:
            grid = np.ascontiguousarray
        else:
            grid = np.ndarray.tolist
        distance = self.colour_distance  # None where the colours sensed are not known
        summary = {
            **values(params, "summary"),
            "pattern": self.majority_pattern,
            **(
                {"orientation_deg": self.orientation_deg} if self.modes.descriptor.oriented else {}
            ),
            "votes": self.selection_counts,
            "patterns": self.chosen_names().tolist(),
            "mean_p": mean_p(p).tolist(),
            "sensed": grid(np.asarray(self.sensed, dtype=np.float64)),
            "initial": grid(self.initial.astype(int)),
            "final": grid(self.final.astype(int)),
            "display": grid(self.display_rgb if self.modes.palette.colour else self.display),
            "grey_distance": round(self.grey_distance, 6),
            "colour_distance": None if distance is None else round(distance, 6),
            "consensus_trace": self.consensus_trace.tolist(),
            "elapsed_s": round(float(self.elapsed_s), 6),
        }
        if self.modes.palette.colour and self.palette_rgb is not None:
            summary["sensed_rgb"] = grid(np.asarray(self.sensed_rgb, dtype=np.float64))
            summary["palette"] = grid(np.asarray(self.palette_rgb).astype(np.int64))
        elif self.palette is not None:  # --levels: each robot's greys, darkest first
            summary["palette"] = grid(np.asarray(self.palette).astype(np.int64))
        summary |= self.modes.layout.summary()  # where robots stood (grids are by robot id)
        if self.alive is not None:
            # A swarm run in which robots died: their cells hold null, and they are listed.
            dead = ~self.alive
            for key in ("initial", "final", "display"):
                cells = np.asarray(getattr(self, key)).astype(int).astype(object)  # Python ints
                if key == "display" and self.modes.palette.colour:  # a colour a cell, or null
                    cells = np.empty(dead.shape, object)
                    cells[...] = [[list(map(int, c)) for c in row] for row in self.display_rgb]
                cells[dead] = None
                summary[key] = cells.tolist()
            summary["dead"] = [[int(i), int(j)] for i, j in zip(*np.nonzero(dead), strict=True)]
        return summary
