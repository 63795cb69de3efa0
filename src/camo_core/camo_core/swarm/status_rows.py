"""Robots' reports as columns: how a process sends its robots' statuses, and a monitor reads them.

A process reports its robots as one array message per interval
(`camo_msgs/StatusArray`: a column per field, the variable-length fields
flattened with a count per robot), so that status traffic grows with
processes, not robots, and a monitor checks and records thousands of reports
with a few numpy operations rather than a Python call each. `StatusRows` is
that table without ROS: made from reports (a `Report`, a RobotStatus of any
camo version) or from an array message's fields, checked row by row
(`problems`), and recorded (`RoundRecord.add_rows`).
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import chain
from operator import attrgetter
from typing import Any

import numpy as np

from camo_core.swarm.robot_io import STATUS_COLUMNS, P

# The columns of a status table, derived from the status's declaration (robot_io.Report): those
# with one value per robot, and their dtype; the vector (p, its width's values a robot); the
# variable-length lists, flattened, with a count per robot (name: its count column, dtype, and
# values an entry, P: p's width).
SCALARS: dict[str, Any] = {
    name: meta["dtype"]
    for name, meta in STATUS_COLUMNS.items()
    if meta["array"] and meta["shape"] == "value"
}
VECTOR = next(name for name, meta in STATUS_COLUMNS.items() if meta["shape"] == "vector")
LISTS: dict[str, tuple[str, Any, int | str]] = {
    name: (f"{name}_count", meta["dtype"], meta["per"])
    for name, meta in STATUS_COLUMNS.items()
    if meta["shape"] == "list"
}
# Every column of a table: those above, the lists' counts, and two a table adds of reports:
# a report whose row and column are not its sender's cell (wrong_cell), and one whose lists are
# not whole entries or whose p is of another width than the others' (ragged).
COLUMNS = (*SCALARS, VECTOR, *LISTS, *(count for count, _, _ in LISTS.values()))
CHECKS = ("wrong_cell", "ragged")

_SCALAR_FIELDS = attrgetter(*SCALARS)


class RowsError(ValueError):
    """Columns that do not make a table (lengths that disagree)."""


class StatusRows:
    """Robots' reports as columns (COLUMNS and CHECKS, each a numpy array with an entry per
    row; p is rows x its width, a list's values entries x values an entry)."""

    def __init__(self, **columns: np.ndarray) -> None:
        missing = set(COLUMNS + CHECKS) - set(columns)
        if missing:
            raise TypeError(f"status rows without {', '.join(sorted(missing))}")
        self.__dict__.update(columns)

    def __getattr__(self, name: str) -> np.ndarray:
        raise AttributeError(name)  # (the columns are set in __init__; this types them)

    def __len__(self) -> int:
        return len(self.sender_id)

    @property
    def width(self) -> int:
        """p's width (the descriptor's: 3 for the paper's)."""
        return self.p.shape[1]

    @classmethod
    def from_reports(cls, reports: Sequence, cols: int | None = None) -> StatusRows:
        """From reports with RobotStatus's fields (fields an older camo's lack read as empty);
        `cols`: the grid's, to check a report's row and column against its sender's."""
        try:  # a process's own reports have every field: one C call a report takes them all
            rows = [_SCALAR_FIELDS(r) for r in reports]
        except AttributeError:
            rows = [tuple(getattr(r, name, 0) for name in SCALARS) for r in reports]
        by_column = zip(*rows, strict=True) if rows else ((),) * len(SCALARS)
        columns: dict[str, Any] = {
            name: np.array(column, dtype)
            for (name, dtype), column in zip(SCALARS.items(), by_column, strict=True)
        }
        # p: the first report's width; a report of another width is refused (ragged).
        vectors = [getattr(r, VECTOR) for r in reports]
        width = len(vectors[0]) if vectors else 3
        ragged = np.fromiter((len(v) != width for v in vectors), bool, len(vectors))
        if ragged.any():
            vectors = [
                (np.nan,) * width if bad else v for v, bad in zip(vectors, ragged, strict=True)
            ]
        p = np.fromiter(chain.from_iterable(vectors), np.float64)
        columns[VECTOR] = p.reshape(-1, width)
        for name, (count, dtype, per) in LISTS.items():
            entry = width if per == P else int(per)
            values = [getattr(r, name, ()) for r in reports]
            lengths = np.fromiter(map(len, values), np.int64, len(values))
            # A trace that is not a whole number of steps is dropped, and its row refused.
            uneven = lengths % entry != 0 if entry else lengths != 0
            if uneven.any():
                values = [() if bad else v for v, bad in zip(values, uneven, strict=True)]
                lengths[uneven] = 0
                ragged |= uneven
            columns[count] = lengths // max(entry, 1)
            flat = np.fromiter(chain.from_iterable(values), dtype)
            columns[name] = flat.reshape(-1, entry) if per != 1 else flat
        columns["ragged"] = ragged
        if cols is None:
            columns["wrong_cell"] = np.zeros(len(reports), bool)
        else:
            columns["wrong_cell"] = np.array(
                [
                    hasattr(r, "row") and (r.row, r.col) != divmod(r.sender_id, cols)
                    for r in reports
                ],
                bool,
            )
        return cls(**columns)

    @classmethod
    def from_message(cls, msg) -> StatusRows:
        """From a StatusArray's columns (RowsError if their lengths disagree)."""
        n = len(msg.sender_id)
        columns: dict[str, Any] = {}
        for name, dtype in SCALARS.items():
            column = np.asarray(getattr(msg, name), dtype)
            if len(column) != n:
                raise RowsError(f"a status array's {name} has {len(column)} rows, not {n}")
            columns[name] = column
        p = np.asarray(getattr(msg, VECTOR), np.float64)
        width = len(p) // n if n else 3
        if len(p) != width * n or (n and width == 0):
            raise RowsError(f"a status array's {VECTOR} is not the same number of values a row")
        columns[VECTOR] = p.reshape(n, width)
        for name, (count, dtype, per) in LISTS.items():
            entry = width if per == P else int(per)
            counts = np.asarray(getattr(msg, count, ()), np.int64)
            values = np.asarray(getattr(msg, name, ()), dtype)
            if len(counts) == 0 and len(values) == 0:  # an array of an older camo: none
                counts = np.zeros(n, np.int64)
            if len(counts) != n or int(counts.sum()) * entry != len(values):
                raise RowsError(f"a status array's {name} does not match its counts")
            columns[count] = counts
            columns[name] = values.reshape(-1, entry) if per != 1 else values
        columns["wrong_cell"] = columns["ragged"] = np.zeros(n, bool)
        return cls(**columns)

    def message_fields(self) -> dict[str, Any]:
        """The columns as a StatusArray's fields (lists of plain numbers)."""
        out: dict[str, Any] = {name: getattr(self, name).tolist() for name in SCALARS}
        out["alive"] = self.alive.astype(np.uint8).tolist()
        out[VECTOR] = getattr(self, VECTOR).ravel().tolist()
        for name, (count, _, _) in LISTS.items():
            out[count] = getattr(self, count).tolist()
            out[name] = getattr(self, name).ravel().tolist()
        return out

    def select(self, keep: np.ndarray) -> StatusRows:
        """The rows where `keep` holds."""
        columns: dict[str, Any] = {}
        for name in COLUMNS + CHECKS:
            if name in LISTS:
                counts = getattr(self, LISTS[name][0])
                columns[name] = getattr(self, name)[np.repeat(keep, np.maximum(counts, 0))]
            else:
                columns[name] = getattr(self, name)[keep]
        return StatusRows(**columns)

    def spans(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """For each element of list column `name`: its row, and its index within the row."""
        counts = np.maximum(getattr(self, LISTS[name][0]), 0)
        rows = np.repeat(np.arange(len(self)), counts)
        starts = np.cumsum(counts) - counts
        return rows, np.arange(len(rows)) - np.repeat(starts, counts)

    def occurrences(self) -> np.ndarray:
        """For each row, how many earlier rows report the same robot (0 for the first)."""
        order = np.argsort(self.sender_id, kind="stable")
        ids = self.sender_id[order]
        first = np.r_[True, ids[1:] != ids[:-1]] if len(ids) else np.zeros(0, bool)
        start = np.maximum.accumulate(np.where(first, np.arange(len(ids)), 0))
        rank = np.empty(len(ids), np.int64)
        rank[order] = np.arange(len(ids)) - start
        return rank


def rows_of_message(msg, cols: int | None = None) -> StatusRows:
    """The reports a status message holds: a StatusArray's rows, or a RobotStatus (of any camo
    version: a bag's) as one row."""
    if hasattr(msg, "silent_count"):
        return StatusRows.from_message(msg)
    return StatusRows.from_reports([msg], cols)
