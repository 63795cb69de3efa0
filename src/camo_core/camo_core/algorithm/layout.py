"""--layout: swarms that are not square grids (docs/algorithm.md §2.7).

Robots stand at positions (x right, y down, in units of the spacing between neighbours): a
hexagonal packing (every other row offset by half a spacing, rows sqrt(3)/2 apart, so that
each robot has six neighbours at one spacing), square positions jittered by up to A spacings
(seeded), or the positions of a CSV file (x,y a line). A robot knows its neighbours by range
and bearing, as a real one would measure them: those within NEAR spacings (colours, energies,
consensus) and within FAR (formation). Its slots are the near ones in id order, then the far
ones in id order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np

from camo_core.algorithm import rng
from camo_core.algorithm.grid import neighbor_ids
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.sensing import to_gray, to_rgb
from camo_core.inputs.numeric import number
from camo_core.inputs.positions import LayoutError, read_positions

NEAR = 1.5
FAR = 2.3
MAX_SLOTS = 64  # neighbours within FAR: RobotStatus.known_slots is a 64-bit mask
KINDS = ("hex", "jitter:A", "FILE")
STREAM_JITTER = rng.STREAM_JITTER  # the jitter draws (a = coordinate, b = robot)


@dataclass(frozen=True)
class Layout:
    name: str  # as given: hex, jitter:0.3 or the file's path
    positions: np.ndarray  # robots x 2 float64: x, y in spacings

    @property
    def count(self) -> int:
        return len(self.positions)

    def neighbours(self) -> list[tuple[list[int], list[int]]]:
        """Per robot: (ids within NEAR, ids within FAR but beyond NEAR), each in id order."""
        return neighbours_of(self.positions)


@dataclass(frozen=True)
class Place:
    """One robot's neighbours on a layout: its slots (ids, the near ones first) and their
    offsets from it (dx, dy in spacings, y down)."""

    neighbors: tuple[int, ...]
    near: int  # slots 0..near-1 are within NEAR
    offsets: tuple[tuple[float, float], ...]


@lru_cache(maxsize=8)
def layout_for(params: CamoParams) -> Layout:
    """The layout a run's parameters name (the same positions in every process)."""
    if params.layout == "file":
        return Layout("file", np.array(params.positions, dtype=np.float64).reshape(-1, 2))
    return layout_of(params.layout, params.rows, params.cols, params.seed)


@lru_cache(maxsize=8)
def places_for(params: CamoParams) -> tuple[Place, ...]:
    layout = layout_for(params)
    out = []
    for robot, (near, far) in enumerate(layout.neighbours()):
        slots = (*near, *far)
        here = layout.positions[robot]
        offsets = tuple(
            (float(layout.positions[j, 0] - here[0]), float(layout.positions[j, 1] - here[1]))
            for j in slots
        )
        if len(slots) > MAX_SLOTS:
            raise LayoutError(
                f"robot {robot} has {len(slots)} neighbours within {FAR:g} spacings: at most "
                f"{MAX_SLOTS} (spread the robots out)"
            )
        out.append(Place(slots, len(near), offsets))
    return tuple(out)


def slot_ids(params: CamoParams, robot: int) -> list[int | None]:
    """The ids in a robot's slots: the grid's twelve (None off the grid), or a layout's."""
    if params.layout:
        return list(places_for(params)[robot].neighbors)
    return neighbor_ids(*divmod(robot, params.cols), params.rows, params.cols)


def layout_of(spec: str, rows: int, cols: int, seed: int) -> Layout:
    """hex, jitter:A (A in [0, 0.5)) over rows x cols, or a CSV file of x,y positions."""
    if spec == "hex":
        i, j = np.mgrid[0:rows, 0:cols].astype(np.float64)
        positions = np.stack([j + 0.5 * (i % 2), i * (math.sqrt(3) / 2)], axis=-1)
        return Layout(spec, positions.reshape(-1, 2))
    if spec.startswith("jitter:"):
        try:
            amount = number(spec.split(":", 1)[1])
        except ValueError:
            raise LayoutError(f"jitter:A needs a number A of spacings (got {spec!r})") from None
        if not 0.0 <= amount < 0.5:
            raise LayoutError(f"jitter:A needs 0 <= A < 0.5 spacings (got {amount:g})")
        ids = np.arange(rows * cols, dtype=np.uint64)
        shift = [2 * rng.uniform_array(seed, STREAM_JITTER, axis, ids, 0) - 1 for axis in (0, 1)]
        i, j = np.divmod(np.arange(rows * cols), cols)
        positions = np.stack([j + amount * shift[0], i + amount * shift[1]], axis=-1)
        return Layout(spec, positions.astype(np.float64))
    return Layout(spec, read_positions(Path(spec)))


def neighbours_of(positions: np.ndarray) -> list[tuple[list[int], list[int]]]:
    """Robots within NEAR and FAR of each, found through a grid of FAR-sized buckets."""
    buckets: dict[tuple[int, int], list[int]] = {}
    cells = np.floor(positions / FAR).astype(np.int64)
    for robot, (cx, cy) in enumerate(cells.tolist()):
        buckets.setdefault((cx, cy), []).append(robot)
    out = []
    for robot, (cx, cy) in enumerate(cells.tolist()):
        near, far = [], []
        x, y = positions[robot]
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for other in buckets.get((cx + dx, cy + dy), ()):
                    if other == robot:
                        continue
                    distance = math.hypot(positions[other, 0] - x, positions[other, 1] - y)
                    if distance <= NEAR:
                        near.append(other)
                    elif distance <= FAR:
                        far.append(other)
        out.append((sorted(near), sorted(far)))
    return out


def sense_at(image: np.ndarray, layout: Layout, profile: str = "paper") -> np.ndarray:
    """Each robot's grey: the mean of the image (grey by the profile's weights) over one
    spacing around its position, the layout's extent (plus half a spacing round it)
    stretched over the image."""
    return means_at(to_gray(image, profile), layout)


def colours_at(image: np.ndarray, layout: Layout) -> np.ndarray:
    """Each robot's mean colour (robots x 3, sRGB) over the spacing sense_at takes its grey."""
    rgb = to_rgb(image)
    return np.stack([means_at(rgb[:, :, c], layout) for c in range(3)], axis=-1)


def means_at(gray: np.ndarray, layout: Layout) -> np.ndarray:
    """The mean of one channel over one spacing around each robot's position (see sense_at)."""
    height, width = gray.shape
    low = layout.positions.min(axis=0) - 0.5
    span = layout.positions.max(axis=0) + 0.5 - low
    scale = np.array([width, height]) / span  # pixels per spacing, per axis
    sums = cv2.integral(gray.astype(np.float64))
    out = np.empty(layout.count)
    for robot, (x, y) in enumerate(layout.positions):
        x0, y0 = (np.array([x, y]) - 0.5 - low) * scale
        x1, y1 = (np.array([x, y]) + 0.5 - low) * scale
        left, right = int(np.clip(round(x0), 0, width - 1)), int(np.clip(round(x1), 1, width))
        top, bottom = int(np.clip(round(y0), 0, height - 1)), int(np.clip(round(y1), 1, height))
        right, bottom = max(right, left + 1), max(bottom, top + 1)
        total = sums[bottom, right] - sums[top, right] - sums[bottom, left] + sums[top, left]
        out[robot] = total / ((bottom - top) * (right - left))
    return out
