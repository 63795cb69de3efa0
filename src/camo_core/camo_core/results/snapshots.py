"""The frames of a round's GIF (run.gif), taken as the round goes: what both drivers hand the
animation (results/animation.py draws them). No matplotlib here: a simulator run takes its
frames before anything is drawn, and drawing can happen in another process."""

from __future__ import annotations

import math

import numpy as np

from camo_core.algorithm.modes import modes_of
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.patterns import PATTERN_COLORS
from camo_core.algorithm.orientation import CODES, ORIENTED, STEP_DEG
from camo_core.results.tensor_colours import tensor_at, tensor_rgb

MAX_FRAMES = 80
MAX_SIDE = 256  # robots per side a frame shows: one pixel each at most, in a 3 inch panel
UNKNOWN = np.array([0.5, 0.5, 0.5])
# The patterns' colours (the table's, "#rrggbb"), as RGB in 0..1: a p is painted their mix.
PALETTE = np.array(
    [[int(c[k : k + 2], 16) / 255 for k in (1, 3, 5)] for c in PATTERN_COLORS.values()]
)


def code_colours(oriented: bool = True) -> np.ndarray:
    """RGB (0..1) of every pattern code, then of "none" (the last): the table's colours, then
    for --orientation any each stripe direction's (as tensor_rgb paints its tensor; grey
    unless `oriented`)."""
    angles = np.tile(UNKNOWN, (CODES - ORIENTED, 1))
    if oriented:
        angles = np.array([tensor_rgb(np.array(tensor_at(k * STEP_DEG))) for k in range(len(angles))])
    return np.array([*PALETTE, *angles, UNKNOWN])


def shown_steps(consensus_steps: int, formation_steps: int) -> tuple[list[int], list[int]]:
    """The consensus steps (0 is before the first) and formation steps a GIF shows: all of
    them, or MAX_FRAMES evenly spread with the first and the last."""
    total = consensus_steps + formation_steps + 2
    keep = np.unique(np.linspace(0, total - 1, min(total, MAX_FRAMES)).round().astype(int))
    consensus = [int(k) for k in keep if k <= consensus_steps]
    formation = [int(k) - consensus_steps - 1 for k in keep if k > consensus_steps]
    return consensus, formation


class Snapshots:
    """The frames of a round's GIF, taken as the round goes. Call it with ("consensus", step,
    p) for the p-vectors before consensus step `step` (rows x cols x width or robots x width, NaN:
    unknown), ("chosen", 0, pattern codes) once consensus ends (-1: none) and ("formation", step,
    state) (-1: unknown); it keeps the steps it shows."""

    def __init__(self, params: CamoParams) -> None:
        self.params = params
        self.modes = modes_of(params)
        # A layout's robots are drawn at their positions, every one of them.
        side = max(params.rows, params.cols)
        self.stride = max(1, math.ceil(side / MAX_SIDE)) if self.modes.layout.grid else 1
        self.consensus_steps = self.modes.scope.steps(params)
        consensus, formation = shown_steps(self.consensus_steps, params.formation_steps)
        self.wanted = {"consensus": set(consensus), "chosen": {0}, "formation": set(formation)}
        self.colours = code_colours(self.modes.descriptor.oriented)
        self.frames: dict[tuple[int, int], tuple[str, np.ndarray]] = {}

    def cells(self, values: np.ndarray) -> np.ndarray:
        """Per robot values as the grid a frame shows (every `stride`-th robot)."""
        values = np.asarray(values)
        rows, cols = self.params.rows, self.params.cols
        if values.shape[:2] != (rows, cols):  # by robot id: as the grid
            shape = (rows, cols) if values.size == rows * cols else (rows, cols, -1)
            values = values.reshape(shape)
        # Strided as it is: reshaping a view (a wider p's first columns) would copy it whole.
        return values[:: self.stride, :: self.stride]

    def __call__(self, phase: str, step: int, values: np.ndarray) -> None:
        if step not in self.wanted[phase]:
            return
        if phase == "consensus":
            # Gathered into one block first: on a large grid's strided view each step below
            # costs several times as much (a 1024x1024 run spent 0.12 s of 0.48 here).
            p = np.ascontiguousarray(self.cells(values))
            nan = np.isnan(p)
            # A tensor's direction, or the mix of the pattern colours a p holds.
            paint = tensor_rgb if self.modes.descriptor.oriented else (lambda p: p @ PALETTE)
            if not nan.any():  # every robot's p known: the same colours, without NaN's passes
                rgb = paint(p)
            else:
                known = ~nan.any(axis=-1)
                rgb = np.where(known[..., None], paint(np.nan_to_num(p)), UNKNOWN)
            total, order = self.consensus_steps, 0
        elif phase == "chosen":  # each robot's pattern in its colour
            codes = self.cells(values).astype(np.int64)
            none = (codes < 0) | (codes >= len(self.colours) - 1)
            self.frames[(1, 0)] = ("chosen pattern", self.colours[np.where(none, -1, codes)])
            return
        else:  # states, greys or colours shown (-1: unknown)
            rgb = self.modes.palette.frame_rgb(self.cells(values))
            total, order = self.params.formation_steps, 2
        self.frames[(order, step)] = (f"{phase} step {step}/{total}", rgb)

    @classmethod
    def of_record(cls, record) -> Snapshots:
        """The frames of a swarm's round (a `record.RoundRecord`)."""
        snapshots = cls(record.params)
        for step in sorted(snapshots.wanted["consensus"]):
            snapshots("consensus", step, record.p_trace[step])
        snapshots("chosen", 0, record.selected)
        palette, shape = record.grid_palette(), (record.params.rows, record.params.cols)
        for step in sorted(snapshots.wanted["formation"]):
            states = record.state_trace[step].reshape(shape)
            snapshots("formation", step, record.modes.palette.frame(states, palette))
        return snapshots

    def shown(self) -> list[tuple[str, np.ndarray]]:
        """(caption, RGB grid) per frame, in order."""
        return [self.frames[key] for key in sorted(self.frames)]
