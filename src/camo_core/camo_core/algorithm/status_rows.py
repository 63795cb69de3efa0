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
from dataclasses import dataclass, fields
from itertools import chain
from operator import attrgetter
from typing import Any

import numpy as np

# The columns with one value per robot, and their dtype.
SCALARS: dict[str, Any] = {
    "sender_id": np.int64,
    "phase": np.int64,
    "step": np.int64,
    "round": np.int64,
    "sensed": np.float64,
    "pattern": np.int64,
    "state": np.int64,
    "alive": np.bool_,
    "known_slots": np.uint64,
    "deadlines": np.int64,
    "p_from": np.int64,
    "state_from": np.int64,
}
# The variable-length ones: flattened, with a count per robot (p_trace counts steps of 3).
LISTS: dict[str, tuple[str, Any, int]] = {
    "silent": ("silent_count", np.int64, 1),
    "p_trace": ("p_trace_count", np.float64, 3),
    "state_trace": ("state_trace_count", np.int64, 1),
    "palette": ("palette_count", np.int64, 1),
    "sensed_rgb": ("sensed_rgb_count", np.float64, 3),
    "palette_rgb": ("palette_rgb_count", np.int64, 3),
    "shades": ("shades_count", np.int64, 2),
}


_SCALAR_FIELDS = attrgetter(*SCALARS)


class RowsError(ValueError):
    """Columns that do not make a table (lengths that disagree)."""


@dataclass
class StatusRows:
    sender_id: np.ndarray
    phase: np.ndarray
    step: np.ndarray
    round: np.ndarray
    sensed: np.ndarray
    p: np.ndarray  # (rows, 3)
    pattern: np.ndarray
    state: np.ndarray
    alive: np.ndarray
    known_slots: np.ndarray
    deadlines: np.ndarray
    p_from: np.ndarray
    state_from: np.ndarray
    silent_count: np.ndarray
    silent: np.ndarray
    p_trace_count: np.ndarray
    p_trace: np.ndarray  # (steps, 3)
    state_trace_count: np.ndarray
    state_trace: np.ndarray
    palette_count: np.ndarray
    palette: np.ndarray
    sensed_rgb_count: np.ndarray
    sensed_rgb: np.ndarray  # (colours, 3)
    palette_rgb_count: np.ndarray
    palette_rgb: np.ndarray  # (colours, 3)
    shades_count: np.ndarray
    shades: np.ndarray  # (pairs, 2)
    wrong_cell: np.ndarray  # a RobotStatus whose row and column are not its sender's cell
    ragged: np.ndarray  # a RobotStatus whose p_trace is not 3 values a step

    def __len__(self) -> int:
        return len(self.sender_id)

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
        p = np.fromiter(chain.from_iterable(r.p for r in reports), np.float64)
        columns["p"] = p.reshape(-1, 3)
        ragged = np.zeros(len(reports), bool)
        for name, (count, dtype, width) in LISTS.items():
            values = [getattr(r, name, ()) for r in reports]
            lengths = np.fromiter(map(len, values), np.int64, len(values))
            # A trace that is not a whole number of steps is dropped, and its row refused.
            uneven = lengths % width != 0
            if uneven.any():
                values = [() if bad else v for v, bad in zip(values, uneven, strict=True)]
                lengths[uneven] = 0
                ragged |= uneven
            columns[count] = lengths // width
            flat = np.fromiter(chain.from_iterable(values), dtype)
            columns[name] = flat.reshape(-1, width) if width > 1 else flat
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
        p = np.asarray(msg.p, np.float64)
        if len(p) != 3 * n:
            raise RowsError("a status array's p is not 3 values a row")
        columns["p"] = p.reshape(n, 3)
        for name, (count, dtype, width) in LISTS.items():
            counts = np.asarray(getattr(msg, count, ()), np.int64)
            values = np.asarray(getattr(msg, name, ()), dtype)
            if len(counts) == 0 and len(values) == 0:  # an array of an older camo: none
                counts = np.zeros(n, np.int64)
            if len(counts) != n or int(counts.sum()) * width != len(values):
                raise RowsError(f"a status array's {name} does not match its counts")
            columns[count] = counts
            columns[name] = values.reshape(-1, width) if width > 1 else values
        columns["wrong_cell"] = columns["ragged"] = np.zeros(n, bool)
        return cls(**columns)

    def message_fields(self) -> dict[str, Any]:
        """The columns as a StatusArray's fields (lists of plain numbers)."""
        out: dict[str, Any] = {name: getattr(self, name).tolist() for name in SCALARS}
        out["alive"] = self.alive.astype(np.uint8).tolist()
        out["p"] = self.p.ravel().tolist()
        for name, (count, _, _) in LISTS.items():
            out[count] = getattr(self, count).tolist()
            out[name] = getattr(self, name).ravel().tolist()
        return out

    def select(self, keep: np.ndarray) -> StatusRows:
        """The rows where `keep` holds."""
        columns: dict[str, Any] = {}
        for f in fields(self):
            name = f.name
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
