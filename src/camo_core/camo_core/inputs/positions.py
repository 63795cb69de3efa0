"""--layout FILE: robots' positions from a CSV file of x,y lines, checked at every level (the
path, its size, its text and CSV, each line's two numbers, the count, how close two robots
stand) before a run uses them."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from camo_core.exceptions import CamoError
from camo_core.inputs.files import checked_file, shown
from camo_core.inputs.numeric import number

MAX_COORDINATE = 1e6  # spacings: a file layout's positions stay within this
MIN_GAP = 0.5  # spacings: closer robots would crowd a robot's reach
MAX_ROBOTS = 65536
MAX_FILE_BYTES = 16 * 1024 * 1024  # 65536 lines of x,y and then some


class LayoutError(CamoError):
    """A layout that cannot be read or made; the message says why in one line."""


def file_positions(path: str) -> tuple[tuple[float, float], ...]:
    """--layout FILE's positions, as CamoParams carries them."""
    return tuple((float(x), float(y)) for x, y in read_positions(path))


def read_positions(path: str | Path) -> np.ndarray:
    """x,y per line (spacings), numbers as camo_core.inputs.numeric.number reads them. The file is
    UTF-8, with or without a byte-order mark. Its first line is a header, and skipped, only if
    none of its fields is a number (`x,y`): a line with a number in it is data, and a data
    line that does not parse is an error, never taken for a header."""
    path = checked_file(path, "layout file", MAX_FILE_BYTES, LayoutError)
    try:
        with open(path, newline="", encoding="utf-8-sig") as handle:
            lines = [
                (number, row)
                for number, row in enumerate(csv.reader(handle), 1)
                if row and any(c.strip() for c in row)
            ]
    except OSError as exc:
        raise LayoutError(f"cannot read layout {shown(path)}: {exc.strerror or exc}") from None
    except (UnicodeDecodeError, csv.Error):
        raise LayoutError(f"layout {shown(path)} is not a CSV file of x,y positions") from None
    if lines and not any(_parses(c) for c in lines[0][1]):
        lines = lines[1:]  # a header of words
    bad = next((n for n, row in lines if len(row) != 2 or not _numbers(row)), None)
    if bad is not None or not lines:
        where = f"line {bad}" if bad is not None else "no positions"
        want = f"want x,y (two numbers within +-{MAX_COORDINATE:g}) a line"
        raise LayoutError(f"layout {shown(path)}: {where}: {want}")
    rows = [row for _, row in lines]
    if len(rows) > MAX_ROBOTS:
        raise LayoutError(f"layout {shown(path)} has {len(rows)} robots, above {MAX_ROBOTS}")
    positions = np.array([[number(x), number(y)] for x, y in rows])
    close = closest_pair(positions)
    if close is not None and close < MIN_GAP:
        raise LayoutError(
            f"layout {shown(path)} has two robots {close:.3g} spacings apart (< {MIN_GAP:g})"
        )
    return positions


def _parses(field: str) -> bool:
    try:
        number(field, special=True)
    except ValueError:
        return False
    return True


def _numbers(row: list[str]) -> bool:
    try:
        return all(abs(number(c)) <= MAX_COORDINATE for c in row)
    except ValueError:
        return False


def closest_pair(positions: np.ndarray) -> float | None:
    """The distance between the two closest robots (None for fewer than two)."""
    if len(positions) < 2:
        return None
    from scipy.spatial import KDTree  # a second's import: only a layout file needs it

    distances, _ = KDTree(positions).query(positions, k=2)
    return float(distances[:, 1].min())
