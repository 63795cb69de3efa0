"""A round's summary.json and figure.png, as `./camo sim`, the swarm's monitor and `camo render`
write them."""

from __future__ import annotations

import gc
import math
import multiprocessing
import os
import signal
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from camo_core.algorithm.modes import modes_of
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.result import RunResult
from camo_core.exceptions import CamoError
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


def round_summary(
    result: RunResult, incomplete: str | None = None, extra: dict | None = None
) -> dict:
    """A round's summary.json document, with `incomplete` saying how far a stopped run got and
    `extra` keys."""
    summary = result.summary()
    if incomplete is not None:
        # What robots never said is unknown, not a number: null, never NaN.
        summary = {key: no_nan(value) for key, value in summary.items()}
        summary["incomplete"] = incomplete
    summary.update(extra or {})
    return summary


def write_round(
    result: RunResult,
    image: np.ndarray | None,
    folder: Path,
    title: str,
    incomplete: str | None = None,
    extra: dict | None = None,
    marks: dict[str, np.ndarray] | None = None,
) -> dict:
    """summary.json (round_summary) and figure.png (with `marks`: the robots it marks, as
    figures.run_figure takes them), here."""
    summary = round_summary(result, incomplete, extra)
    write_summary(summary, folder)
    draw_figure(result, image, folder / "figure.png", title, marks)
    return summary


# What draws imports matplotlib when it draws: a process that only simulates or runs robots
# never does. figure.png and run.gif are drawn side by side by a Parallel whose `prepare` is
# import_drawing (one import for both).


def import_drawing() -> None:
    import camo_core.results.animation  # (both imported for the works that draw)
    import camo_core.results.figures  # noqa: F401


def draw_figure(result: RunResult, image, path: Path, title: str, marks=None) -> None:
    from camo_core.results import figures

    figures.run_figure(result, image, path, title=title, marks=marks)


def draw_animation(snapshots, sensed, dead, path: Path, title: str, marks=None) -> None:
    from camo_core.results.animation import write_animation

    write_animation(snapshots, sensed, dead, path, title, marks)


def start_drawings(
    result: RunResult, image, snapshots, sensed, dead, folder: Path, title: str, marks=None
) -> Parallel:
    """figure.png and run.gif of a round, side by side in processes of their own (which import
    matplotlib once; the caller never does) while the caller writes summary.json: on two
    cores a large round's outputs take half the time. The caller waits for it, or stops it."""
    return Parallel(
        lambda: draw_figure(result, image, folder / "figure.png", title, marks),
        lambda: draw_animation(snapshots, sensed, dead, folder / "run.gif", title, marks),
        prepare=import_drawing,
    )


FORK_SIGNALS = {signal.SIGINT, signal.SIGTERM}


class Parallel:
    """`works` in a forked process of their own (where fork is there; else at once, here), so
    that what a run writes at its end shares the machine's cores. That process first runs
    `prepare` (the imports the works share: matplotlib's, say), then forks once more for each
    work after the first, so that they run side by side and import it once. `wait` joins it
    (`limit` seconds at most): an error in any work is one line here. Whoever forks it and
    cannot wait for it (an error of its own) calls `stop`, which ends the works too."""

    LIMIT = 300.0  # s: drawing a round's outputs takes seconds; more is a process that hangs

    def __init__(
        self, *works: Callable[[], None], prepare: Callable[[], None] | None = None
    ) -> None:
        self.process = None
        if "fork" not in multiprocessing.get_all_start_methods():
            for work in (prepare, *works):
                if work is not None:
                    work()
            return
        self.process = multiprocessing.get_context("fork").Process(
            target=_run_reporting, args=(works, prepare), daemon=True
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
        """Stop it (and the works it forked), without waiting for what they write."""
        if self.process is not None and self.process.is_alive():
            self.process.terminate()
            self.process.join(2.0)
            if self.process.is_alive():  # SIGTERM came before it took its own handler
                self.process.kill()
                self.process.join()


def _run_reporting(works: tuple[Callable[[], None], ...], prepare) -> None:
    """A forked process's body: `prepare`, then each work after the first in a process forked
    from this one, the first here. An error is one line on stderr and exit code 1."""
    # What the parent held is never finalized here: a forked copy of a ROS process would call
    # into DDS, whose threads it does not have. Its parent's Ctrl-C and stop flags are not its
    # own: Ctrl-C leaves it to finish, SIGTERM (stop) ends it and the works it forked. Nor
    # does it collect garbage: it draws a round and exits (matplotlib's many objects made the
    # collector take 3% of the drawing).
    gc.freeze()
    gc.disable()
    forked: list[int] = []
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, lambda *_: _end(forked))
    signal.pthread_sigmask(signal.SIG_UNBLOCK, FORK_SIGNALS)  # held back since the fork
    failed = False
    try:
        if prepare is not None:
            prepare()
        for work in works[1:]:
            forked.append(_fork(work))
        works[0]()
    except Exception as exc:  # noqa: BLE001 - whatever it is, one line, as the parent says
        _say(exc)
        failed = True
    for pid in forked:
        failed |= os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]) != 0
    if failed:
        sys.exit(1)


def _fork(work: Callable[[], None]) -> int:
    """`work` in a process forked from this one: its pid (it exits 1 after an error's line)."""
    held = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM})
    pid = os.fork()
    if pid:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)
        return pid
    code = 0
    try:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        signal.pthread_sigmask(signal.SIG_SETMASK, held)
        work()
    except Exception as exc:  # noqa: BLE001 - one line, as in the process it was forked from
        _say(exc)
        code = 1
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)  # never the forked-from process's exit handlers


def _end(forked: list[int]) -> None:
    """SIGTERM in a Parallel's process: its forked works end with it."""
    for pid in forked:
        try:
            os.kill(pid, signal.SIGTERM)
        except ProcessLookupError:
            pass
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    os.kill(os.getpid(), signal.SIGTERM)  # ended by the signal, as its parent asked


def _say(exc: Exception) -> None:
    print(f"camo: error: {type(exc).__name__}: {exc}", file=sys.stderr, flush=True)
