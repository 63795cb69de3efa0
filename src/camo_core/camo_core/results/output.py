"""A round's summary.json and figure.png, as `./camo sim`, the swarm's monitor and `camo render`
write them."""

from __future__ import annotations

import gc
import math
import multiprocessing
import signal
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from camo_core.exceptions import CamoError
from camo_core.algorithm.modes import modes_of
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.result import RunResult
from camo_core.results.summary import write_summary


def run_title(label: str, params: CamoParams, robots: str = "robots") -> str:
    where = modes_of(params).layout.name
    layout = f", layout {where}" if where else ""
    return (
        f"{label}: {params.rows}x{params.cols} {robots}, {params.profile} profile, "
        f"seed {params.seed}, rho_meas {params.rho_meas:g}, rho_comm {params.rho_comm:g}{layout}"
    )


def no_nan(value):
    """A summary value with every NaN (in nested lists too) as None."""
    if isinstance(value, float):
        return None if math.isnan(value) else value
    if isinstance(value, list):
        return [no_nan(v) for v in value]
    return value


def write_round(
    result: RunResult,
    image: np.ndarray | None,
    folder: Path,
    title: str,
    incomplete: str | None = None,
    extra: dict | None = None,
    marks: dict[str, np.ndarray] | None = None,
) -> dict:
    """summary.json (with `incomplete` saying how far a stopped run got, and `extra` keys) and
    figure.png (with `marks`: the robots it marks, as figures.run_figure takes them)."""
    from camo_core.results import figures  # matplotlib: imported by what draws

    summary = result.summary()
    if incomplete is not None:
        # What robots never said is unknown, not a number: null, never NaN.
        summary = {key: no_nan(value) for key, value in summary.items()}
        summary["incomplete"] = incomplete
    summary.update(extra or {})
    write_summary(summary, folder)
    figures.run_figure(result, image, folder / "figure.png", title=title, marks=marks)
    return summary


FORK_SIGNALS = {signal.SIGINT, signal.SIGTERM}


class Parallel:
    """`work()` in a forked process of its own (where fork is there; else at once, here), so
    that what a run writes at its end shares the machine's cores. `wait` joins it (`limit`
    seconds at most): an error in it is one line here. Whoever forks it and cannot wait for it
    (an error of its own) calls `stop`."""

    LIMIT = 300.0  # s: drawing a round's outputs takes seconds; more is a process that hangs

    def __init__(self, work: Callable[[], None]) -> None:
        self.process = None
        if "fork" not in multiprocessing.get_all_start_methods():
            work()
            return
        self.process = multiprocessing.get_context("fork").Process(
            target=_run_reporting, args=(work,), daemon=True
        )
        # Forked with Ctrl-C and SIGTERM held back until the child has its own handlers: one
        # that came between the fork and them would run the parent's there (a KeyboardInterrupt
        # before multiprocessing's bootstrap would even go on as a copy of the parent).
        held = signal.pthread_sigmask(signal.SIG_BLOCK, FORK_SIGNALS)
        try:
            self.process.start()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, held)

    def wait(self, what: str, limit: float = LIMIT) -> None:
        if self.process is None:
            return
        try:
            self.process.join(limit)
        finally:
            if self.process.is_alive():  # Ctrl-C in the join, or it hangs: it is stopped
                self.stop()
        if self.process.exitcode != 0:
            raise CamoError(f"writing {what} failed (exit code {self.process.exitcode})")

    def stop(self) -> None:
        """Stop it, without waiting for what it writes."""
        if self.process is not None and self.process.is_alive():
            self.process.terminate()
            self.process.join(2.0)
            if self.process.is_alive():  # SIGTERM came before it took its own handler
                self.process.kill()
                self.process.join()


def _run_reporting(work: Callable[[], None]) -> None:
    """A forked worker's body: an error is one line on stderr and exit code 1."""
    # What the parent held is never finalized here: a forked copy of a ROS process would call
    # into DDS, whose threads it does not have. Its parent's Ctrl-C and stop flags are not its
    # own: Ctrl-C leaves it to finish, SIGTERM (stop) ends it.
    gc.freeze()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, FORK_SIGNALS)  # held back since the fork
    try:
        work()
    except Exception as exc:  # noqa: BLE001 - whatever it is, one line, as the parent says
        print(f"camo: error: {type(exc).__name__}: {exc}", file=sys.stderr)
        sys.exit(1)
