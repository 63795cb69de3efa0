"""The sweep's table: a Parquet dataset `DIR/trials/`, one row per trial, written in parts.

Each part is written under a name Parquet readers skip (`_` first) and renamed into place, so a
reader never sees half a file and a killed driver leaves only whole parts; a temporary file it
left is removed on the next start. The rows already there are the trials a resumed sweep skips.
"""

from __future__ import annotations

import os
import shlex
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.compute
import pyarrow.dataset as ds
import pyarrow.parquet as pq

from camo_core.algorithm.patterns import PATTERN_NAMES
from camo_core.exceptions import CamoError
from camo_sweep.spec import SweepSpec, Trial

TABLE = "trials"


class TableError(CamoError):
    """A folder whose table cannot be read."""


def schema(spec: SweepSpec) -> pa.Schema:
    """The columns: identity, every axis's value, the results, how the trial went."""
    fields = [
        pa.field("trial_id", pa.string()),
        pa.field("replicate", pa.int64()),
        pa.field("seed", pa.uint64()),
        pa.field("driver", pa.string()),
    ]
    for name in spec.axis_names():
        values = [
            v
            for block in spec.blocks
            for axis, vs in block.items()
            if name in axis.split(",")
            for v in vs
        ]
        fields.append(pa.field(name, _arrow_type(values)))
    fields += [
        pa.field("chosen_pattern", pa.string()),
        pa.field("correct", pa.bool_()),
        pa.field("diff_cells", pa.int64()),
        pa.field("grey_distance", pa.float64()),
        pa.field("colour_distance", pa.float64()),
        *(pa.field(f"votes_{name}", pa.int64()) for name in PATTERN_NAMES),
        *(pa.field(f"mean_p_{name}", pa.float64()) for name in PATTERN_NAMES),
        pa.field("run_s", pa.float64()),
        pa.field("status", pa.string()),
        pa.field("equals_sim", pa.bool_()),
        pa.field("sim_args", pa.string()),
    ]
    return pa.schema(fields)


def _text(value: Any) -> str | None:
    return None if value is None else str(value)


def _arrow_type(values: list[Any]) -> pa.DataType:
    if all(isinstance(v, bool) for v in values):
        return pa.bool_()
    if all(isinstance(v, int) and not isinstance(v, bool) for v in values):
        return pa.int64()
    if all(isinstance(v, int | float) and not isinstance(v, bool) for v in values):
        return pa.float64()
    return pa.string()


@dataclass(frozen=True)
class Layout:
    """What a task needs to build its rows as a table: the workers build them, so that the
    driver only writes (its core is also a worker's, on a small machine)."""

    schema: pa.Schema
    axes: tuple[str, ...]
    driver: str
    # Axes whose values are not all of one kind (`consensus_steps=35,auto`): their column is
    # text, and every value is written as text.
    text_axes: frozenset[str] = frozenset()

    @classmethod
    def of(cls, spec: SweepSpec) -> Layout:
        columns = schema(spec)
        axes = tuple(spec.axis_names())
        text = frozenset(name for name in axes if columns.field(name).type == pa.string())
        return cls(columns, axes, spec.driver, text)


def rows_table(layout: Layout, done: list[tuple[Trial, dict[str, Any]]]) -> pa.Table:
    """Table rows: each trial's identity and axes, and what running it gave."""
    command: dict[int, str] = {}  # the trials of one point share their options (and command)
    rows = []
    for trial, result in done:
        key = id(trial.options)
        if key not in command:
            command[key] = shlex.join(trial.sim_args())
        row = {
            "trial_id": trial.trial_id,
            "replicate": trial.replicate,
            "seed": trial.seed,
            "driver": layout.driver,
            "sim_args": command[key],
            **{name: trial.options[name] for name in layout.axes},
            **{name: _text(trial.options[name]) for name in layout.text_axes},
            **result,
        }
        rows.append(row)
    return pa.Table.from_pylist(rows, schema=layout.schema)


class TableWriter:
    """Appends parts of rows to DIR/trials/."""

    def __init__(self, folder: Path) -> None:
        self.folder = Path(folder) / TABLE
        self.folder.mkdir(parents=True, exist_ok=True)
        for stale in self.folder.glob("_*.tmp"):  # a part a killed driver was writing
            stale.unlink()

    def write(self, table: pa.Table) -> Path | None:
        if not table.num_rows:
            return None
        return put(table, self.folder / f"part-{uuid.uuid4().hex}.parquet")


def put(table: pa.Table, path: Path) -> Path:
    """Write a part under a name readers skip, then rename it into place (over an older one)."""
    temporary = path.with_name(f"_{path.name}.tmp")
    pq.write_table(table, temporary)
    with open(temporary, "rb") as handle:  # on disk before it is visible under its name
        os.fsync(handle.fileno())
    os.replace(temporary, path)
    return path


def parts(folder: Path) -> list[Path]:
    return sorted((Path(folder) / TABLE).glob("part-*.parquet"))


REQUIRED = {"trial_id": pa.string(), "status": pa.string()}


def _check_parts(files: list[Path]) -> None:
    """Every part has the columns a table needs, or the one that lacks them is named."""
    for path in files:
        try:
            found = pq.read_schema(path)
        except (pa.ArrowInvalid, OSError):
            raise TableError(f"{path} is not a readable Parquet file") from None
        for name, kind in REQUIRED.items():
            if found.get_field_index(name) < 0 or found.field(name).type != kind:
                raise TableError(f"{path} is not a part of a sweep table (no {name} column)")


def done_ids(folder: Path) -> tuple[set[str], bool]:
    """The trial ids the table holds with status ok (a failed trial runs again), and whether
    it holds failed ones."""
    if not parts(folder):
        return set(), False
    table = read(folder, columns=["trial_id", "status"]).to_pydict()
    pairs = list(zip(table["trial_id"], table["status"], strict=True))
    ok = {trial for trial, status in pairs if status == "ok"}
    return ok, len(ok) < len(pairs)


def drop_failed(folder: Path) -> int:
    """Take the failed trials' rows out of their parts (each part rewritten whole and renamed
    into place), so that running them again leaves one row per trial; how many."""
    dropped = 0
    for path in parts(folder):
        table = pq.read_table(path)
        keep = pa.compute.equal(table.column("status"), "ok")
        kept = table.filter(keep)
        if kept.num_rows == table.num_rows:
            continue
        dropped += table.num_rows - kept.num_rows
        if kept.num_rows:
            put(kept, path)
        else:
            path.unlink()
    return dropped


def read(folder: Path, columns: list[str] | None = None) -> pa.Table:
    """The whole table (each trial once, should a part repeat one)."""
    files = parts(folder)
    if not files:
        raise TableError(f"{folder} holds no sweep table ({TABLE}/part-*.parquet)")
    _check_parts(files)
    try:
        table = ds.dataset([str(f) for f in files], format="parquet").to_table(columns=columns)
    except (pa.ArrowInvalid, OSError, ValueError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise TableError(f"{folder}/{TABLE} cannot be read: {first}") from None
    ids = table.column("trial_id").to_pylist() if "trial_id" in table.column_names else None
    if ids is not None and len(set(ids)) != len(ids):
        first = {}
        for index, trial_id in enumerate(ids):
            first.setdefault(trial_id, index)
        table = table.take(sorted(first.values()))
    return table
