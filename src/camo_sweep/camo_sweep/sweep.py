"""One sweep from start (or resumption) to its table: the trials not yet in the table (or that
failed), their error-free references (each computed once, here), batches of about `batch_s`
seconds handed to an engine, and every finished batch written as a part of the table."""

from __future__ import annotations

import shlex
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from camo_core.cli.progress import ProgressBar
from camo_core.exceptions import CamoError, UsageError
from camo_sweep.spec import SweepSpec, Trial, canonical, sim_args
from camo_sweep.table import Layout, TableWriter, done_ids, drop_failed
from camo_sweep.trials import (
    Reference,
    check_options,
    reference_of,
    reference_options,
    run_ros_batch,
    run_sim_batch,
)

MAX_BATCH = 5000


@dataclass
class SweepReport:
    total: int  # trials in the sweep
    skipped: int  # already in the table when it started
    ran: int  # run and written now
    failed: int  # of those, trials whose status is an error
    seconds: float  # from the first task handed out to the last part written


@dataclass
class Plan:
    """What a run of a sweep has to do, checked before anything is written."""

    total: int
    todo: list[Trial]
    failed_in_table: bool  # rows of trials that failed before, taken out before they rerun
    references: dict[bytes, Reference]
    cost: float  # seconds one simulator trial takes here


def plan(spec: SweepSpec, folder: Path) -> Plan:
    """The trials the table lacks (those that failed included), and their references. Options
    that cannot make a run (a value out of range, an image that cannot be read) are the
    sweep's one-line error, not rows."""
    trials = spec.trial_list()
    done, failed_before = done_ids(folder) if folder.exists() else (set(), False)
    todo = [t for t in trials if t.trial_id not in done]
    checked: set[bytes] = set()
    for trial in todo:
        key = canonical(trial.options)
        if key not in checked:
            checked.add(key)
            _refuse_unless(check_options, trial)
    references: dict[bytes, Reference] = {}
    timed = None
    for trial in todo:
        key = canonical(reference_options(trial.options))
        if key not in references:
            references[key] = _refuse_unless(reference_of, trial)
            timed = timed or trial
    cost = 0.001
    if timed is not None:  # a reference again, once the kernels are compiled: a trial's cost
        start = time.perf_counter()
        reference_of(timed.options)
        cost = max(time.perf_counter() - start, 1e-5)
    return Plan(len(trials), todo, failed_before, references, cost)


def _refuse_unless(check, trial: Trial):
    try:
        return check(trial.options)
    except CamoError as exc:
        raise UsageError(f"trials of {shlex.join(sim_args(trial.options))}: {exc}") from None


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
    planned: Plan | None = None,
) -> SweepReport:
    """Run what the table in `folder` lacks of `spec`. Interrupted (Ctrl-C), it stops with every
    finished batch written; running it again goes on from there."""
    work_plan = planned or plan(spec, folder)
    writer = TableWriter(folder)
    if work_plan.failed_in_table:  # their trials are in the plan again
        drop_failed(folder)
    layout = Layout.of(spec)
    todo = work_plan.todo
    report = SweepReport(work_plan.total, work_plan.total - len(todo), 0, 0, 0.0)
    if not todo:
        return report
    key = lambda t: canonical(reference_options(t.options))  # noqa: E731
    work = [(trial, work_plan.references[key(trial)]) for trial in todo]
    bar = ProgressBar(report.total, "sweep", already=report.skipped) if progress else None
    if spec.driver == "ros":
        tasks = [(run_ros_batch, (batch, layout, ros_timeout)) for batch in batches(work, 1)]
        resources = {"ros": 1}
    else:
        size = max(1, min(MAX_BATCH, round(batch_s / work_plan.cost)))
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
