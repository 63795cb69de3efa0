"""One sweep from start (or resumption) to its table: the trials not yet in the table, their
error-free references (each computed once, here), batches of about `batch_s` seconds handed to
an engine, and every finished batch written as a part of the table."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from camo_core.exceptions import CamoError
from camo_core.progress import ProgressBar

from .spec import SweepSpec, Trial, canonical
from .table import Layout, TableWriter, done_ids, rows_table
from .trials import Reference, reference_of, reference_options, run_ros_batch, run_sim_batch

MAX_BATCH = 5000


@dataclass
class SweepReport:
    total: int  # trials in the sweep
    skipped: int  # already in the table when it started
    ran: int  # run and written now
    failed: int  # of those, trials whose status is an error
    seconds: float  # from the first task handed out to the last part written


def references_for(trials: list[Trial]) -> tuple[dict[bytes, Reference | str], float]:
    """Each distinct error-free reference once (or the one-line error that stops its trials),
    and what one trial costs: a reference run again, once the kernels are compiled (the first
    run may have compiled them)."""
    references: dict[bytes, Reference | str] = {}
    timed = None
    for trial in trials:
        key = canonical(reference_options(trial.options))
        if key in references:
            continue
        try:
            references[key] = reference_of(trial.options)
        except CamoError as exc:
            references[key] = f"error: {exc}"
            continue
        timed = timed or trial
    if timed is None:
        return references, 0.001
    start = time.perf_counter()
    reference_of(timed.options)
    return references, max(time.perf_counter() - start, 1e-5)


def batches(work: list[tuple[Trial, Reference]], size: int) -> list[list[tuple[Trial, Reference]]]:
    return [work[k : k + size] for k in range(0, len(work), size)]


def run_sweep(
    spec: SweepSpec,
    folder: Path,
    engine,
    batch_s: float = 0.25,
    ros_timeout: float = 300.0,
    progress: bool = True,
    on_part: Callable[[int], None] | None = None,
) -> SweepReport:
    """Run what the table in `folder` lacks of `spec`. Interrupted (Ctrl-C), it stops with every
    finished batch written; running it again goes on from there."""
    trials = spec.trial_list()
    done = done_ids(folder)
    todo = [t for t in trials if t.trial_id not in done]
    writer = TableWriter(folder)
    layout = Layout.of(spec)
    report = SweepReport(len(trials), len(trials) - len(todo), 0, 0, 0.0)
    if not todo:
        return report
    references, cost = references_for(todo)
    failed_rows, work = [], []
    for trial in todo:
        reference = references[canonical(reference_options(trial.options))]
        if isinstance(reference, str):  # its options cannot run at all
            failed_rows.append((trial, {"status": reference, "run_s": 0.0}))
        else:
            work.append((trial, reference))
    bar = ProgressBar(len(trials), "sweep", already=report.skipped) if progress else None
    if failed_rows:
        writer.write(rows_table(layout, failed_rows))
        report.ran += len(failed_rows)
        report.failed += len(failed_rows)
        if bar:
            bar.update(report.skipped + report.ran)
    if spec.driver == "ros":
        tasks = [(run_ros_batch, (batch, layout, ros_timeout)) for batch in batches(work, 1)]
        resources = {"ros": 1}
    else:
        size = max(1, min(MAX_BATCH, round(batch_s / cost)))
        tasks = [(run_sim_batch, (batch, layout)) for batch in batches(work, size)]
        resources = None
    start = time.perf_counter()
    for table in engine.run(tasks, resources=resources):
        writer.write(table)
        report.ran += table.num_rows
        report.failed += table.num_rows - table.column("status").to_pylist().count("ok")
        if on_part:
            on_part(report.ran)
        if bar:
            bar.update(report.skipped + report.ran, note=engine.name)
    report.seconds = time.perf_counter() - start
    return report
