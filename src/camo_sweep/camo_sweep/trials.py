"""Running trials, where a worker runs them: a batch of simulator trials in this process, or one
whole `./camo run` swarm as a subprocess. Each trial gives one row of the table."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np
import pyarrow as pa

from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.patterns import PATTERN_NAMES
from camo_core.algorithm.result import SUMMARY_KEYS, RunResult, mean_p, pattern_of
from camo_core.algorithm.sensing import sense_colours, sense_image
from camo_core.cli.options import image_from, params_from
from camo_core.exceptions import CamoError, UsageError
from camo_core.results.summary import summary_bytes
from camo_core.schema import with_role
from camo_sweep.spec import Trial, defaults, sim_args
from camo_sweep.table import Layout, rows_table

RESULT_COLUMNS = (
    "chosen_pattern",
    "correct",
    "diff_cells",
    "grey_distance",
    "colour_distance",
    *(f"votes_{name}" for name in PATTERN_NAMES),
    *(f"mean_p_{name}" for name in PATTERN_NAMES),
)


@dataclass(frozen=True)
class Reference:
    """The error-free run of a trial's options: what its errors are measured against."""

    pattern: str
    final: np.ndarray  # rows x cols uint8
    # The background's block means before noise, read where the sweep runs: a worker on
    # another machine never opens the image (its path is the driver's); and its blocks' colours.
    raw: np.ndarray
    raw_colours: np.ndarray
    image: str | None  # the image's absolute path there, for a swarm trial's command line

    @property
    def sensed(self) -> tuple[np.ndarray, np.ndarray]:
        return self.raw, self.raw_colours


def namespace(options: dict[str, Any], seed: int) -> argparse.Namespace:
    """./camo sim's parsed options for a trial: the parser's defaults, the trial's values."""
    args = argparse.Namespace(**vars(defaults()))
    for name, value in options.items():
        setattr(args, name, value)
    args.seed = seed
    return args


# The parameters that make a trial noisy (declared with noise=True: rho_meas, rho_comm).
NOISE = tuple(with_role(CamoParams, "noise"))


def reference_options(options: dict[str, Any]) -> dict[str, Any]:
    """A trial's options without errors (the parameters declared with noise=True): its
    reference run's."""
    return {k: v for k, v in options.items() if k not in NOISE}


@cache
def _sensed(
    source: tuple[str | None, str | None, float | None], rows: int, cols: int, profile: str
):
    """The block means and colours of a background (image, pattern, contrast), once per worker
    (a sweep reuses a few backgrounds)."""
    image, pattern, contrast = source
    args = argparse.Namespace(
        image=image, pattern=pattern, contrast=contrast, default_pattern="forest"
    )
    image, _ = image_from(args)
    return sense_image(image, rows, cols, profile), sense_colours(image, rows, cols)


def background_of(args: argparse.Namespace) -> tuple[str | None, str | None, float | None]:
    return args.image, args.pattern, args.contrast


def _simulator():
    """The whole-grid simulator, imported where a trial is simulated: numba's start (0.5 s of
    CPU) is not paid by a sweep's own process, which plans, checks and writes the table while
    its workers simulate, nor by a sweep refused for its input."""
    from camo_core.algorithm.simulator import simulate

    return simulate


def simulate_options(
    options: dict[str, Any], seed: int, sensed: tuple[np.ndarray, np.ndarray] | None = None
) -> RunResult:
    """The trial's RunResult (`sensed`: its background's block means and colours, if known)."""
    args = namespace(options, seed)
    params = params_from(args)
    if sensed is None:
        sensed = _sensed(background_of(args), params.rows, params.cols, params.profile)
    return _simulator()(params, sensed[0], raw_colours=sensed[1])


def check_options(options: dict[str, Any]) -> None:
    """Raise the one-line error of options that cannot make a run (before any is run)."""
    # Before the parameters are checked together: a sweep's layout is refused for what it is.
    if namespace(options, 0).layout:
        raise UsageError("sweeps run on the grid: --layout is for ./camo sim and run, for now")
    params_from(namespace(options, 0))


def reference_of(options: dict[str, Any]) -> Reference:
    args = namespace(options, 0)
    params = params_from(args)
    sensed = _sensed(background_of(args), params.rows, params.cols, params.profile)
    result = simulate_options(reference_options(options), 0, sensed)
    image = os.path.abspath(args.image) if args.image else None
    label = pattern_of(
        {"pattern": result.majority_pattern, "orientation_deg": result.orientation_deg}
    )
    return Reference(label, result.final.copy(), *sensed, image)


def result_columns(summary: dict, reference: Reference) -> dict[str, Any]:
    """The table's result columns, from a summary (a RunResult's or a swarm's summary.json)."""
    final = summary["final"]
    if not isinstance(final, np.ndarray):  # a summary.json's, where a dead robot is null
        final = np.array([[-1 if v is None else v for v in row] for row in final], np.int64)
    row = {
        "chosen_pattern": pattern_of(summary),
        "correct": pattern_of(summary) == reference.pattern,
        "diff_cells": int(np.count_nonzero(final != reference.final)),
        "grey_distance": float(summary["grey_distance"]),
        "colour_distance": summary.get("colour_distance"),
    }
    for k, name in enumerate(PATTERN_NAMES):
        row[f"votes_{name}"] = int(summary["votes"].get(name, 0))  # --orientation any: none
        row[f"mean_p_{name}"] = float(summary["mean_p"][k])
    return row


def failed(error: str) -> dict[str, Any]:
    return {**dict.fromkeys(RESULT_COLUMNS), "status": error}


def sim_row(trial: Trial, reference: Reference) -> dict[str, Any]:
    start = time.perf_counter()
    try:
        result = simulate_options(trial.options, trial.seed, reference.sensed)
    except CamoError as exc:
        return {**failed(f"error: {exc}"), "run_s": time.perf_counter() - start}
    except Exception as exc:  # noqa: BLE001 - one trial's failure is its row, not the sweep's
        said = f"error: {type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
        return {**failed(said), "run_s": time.perf_counter() - start}
    summary = {
        "pattern": result.majority_pattern,
        "orientation_deg": result.orientation_deg,
        "votes": result.selection_counts,
        "grey_distance": result.grey_distance,
        "colour_distance": result.colour_distance,
        "mean_p": mean_p(result.p).tolist(),
        "final": result.final,
    }
    row = result_columns(summary, reference)
    return {**row, "status": "ok", "run_s": time.perf_counter() - start}


def run_sim_batch(batch: list[tuple[Trial, Reference]], layout: Layout) -> pa.Table:
    """A task: simulator trials, one row each."""
    return rows_table(layout, [(trial, sim_row(trial, ref)) for trial, ref in batch])


def run_ros_batch(batch: list[tuple[Trial, Reference]], layout: Layout, timeout: float):
    """A task: each trial a whole `./camo run` (robot nodes in processes) with a time limit,
    compared with the simulator bit for bit."""
    return rows_table(layout, [(trial, ros_row(trial, ref, timeout)) for trial, ref in batch])


def ros_row(trial: Trial, reference: Reference, timeout: float) -> dict[str, Any]:
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="camo-sweep-") as folder:
        out = os.path.join(folder, "run")
        options = dict(trial.options)
        if reference.image:  # where the sweep runs; the same path on this worker's machine
            options["image"] = reference.image
        command = [sys.executable, "-m", "camo_bringup.launcher", *sim_args(options)]
        command += ["--seed", str(trial.seed), "--out", out, "--run-id", f"sw{trial.trial_id}"]
        try:
            done = subprocess.run(
                command, capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL
            )
        except subprocess.TimeoutExpired:
            error = f"error: the swarm did not finish within {timeout:g} s"
            return {**failed(error), "run_s": time.perf_counter() - start}
        elapsed = time.perf_counter() - start
        if done.returncode != 0:
            lines = [line for line in done.stderr.splitlines() if line.strip()]
            said = lines[-1] if lines else f"exit code {done.returncode}"
            return {**failed(f"error: {said}"), "run_s": elapsed}
        with open(os.path.join(out, "summary.json")) as handle:
            swarm = json.load(handle)
    row = result_columns(swarm, reference)
    result = simulate_options(trial.options, trial.seed, reference.sensed)
    sim = json.loads(summary_bytes(result.summary()))
    same = all(swarm.get(k) == sim[k] for k in SUMMARY_KEYS if k != "elapsed_s")
    return {**row, "status": "ok", "run_s": elapsed, "equals_sim": same}


def warm() -> str:
    """Compile the kernels in this process (a worker, before its first task)."""
    _simulator()(CamoParams(rho_meas=0.1, rho_comm=0.1), np.full((8, 8), 100.0))
    return "warm"
