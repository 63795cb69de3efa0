"""The paper's error analysis (Fig. "errorAnalysis"): how far errors push the final pattern."""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .exceptions import UsageError
from .params import CamoParams
from .progress import ProgressBar
from .simulator import simulate

MODES = ("measurement", "communication", "both")
CSV_COLUMNS = (
    "mode",
    "rho",
    "trials",
    "mean_diff",
    "std_diff",
    "p10_diff",
    "p90_diff",
    "correct_rate",
)


@dataclass
class ErrorPoint:
    mode: str
    rho: float
    trials: int
    mean_diff: float
    std_diff: float
    p10_diff: float  # the trials' 10th and 90th percentiles: the figure's band
    p90_diff: float
    correct_rate: float

    def as_row(self) -> dict:
        return {k: getattr(self, k) for k in CSV_COLUMNS}


def params_for(base: CamoParams, mode: str, rho: float, trial: int) -> CamoParams:
    """Trial t uses seed base.seed + t; the mode decides which error probabilities are rho."""
    rho_meas = rho if mode in ("measurement", "both") else 0.0
    rho_comm = rho if mode in ("communication", "both") else 0.0
    return base.with_(seed=base.seed + trial, rho_meas=rho_meas, rho_comm=rho_comm)


def error_analysis(
    base: CamoParams,
    raw_sensed: np.ndarray,
    rhos: list[float],
    trials: int,
    show_progress: bool = True,
) -> list[ErrorPoint]:
    reference = simulate(base.with_(rho_meas=0.0, rho_comm=0.0), raw_sensed)
    target = reference.majority_pattern
    bar = ProgressBar(len(MODES) * len(rhos) * trials, "error analysis") if show_progress else None
    points = []
    for mode in MODES:
        for rho in rhos:
            diffs, correct = [], 0
            for trial in range(trials):
                result = simulate(params_for(base, mode, rho, trial), raw_sensed)
                diffs.append(
                    int(np.abs(result.final.astype(int) - reference.final.astype(int)).sum())
                )
                correct += result.majority_pattern == target
                if bar:
                    bar.update(note=f"{mode} rho={rho:g}")
            points.append(
                ErrorPoint(
                    mode,
                    rho,
                    trials,
                    float(np.mean(diffs)),
                    float(np.std(diffs)),
                    float(np.percentile(diffs, 10)),
                    float(np.percentile(diffs, 90)),
                    correct / trials,
                )
            )
    return points


def write_csv(points: list[ErrorPoint], path: Path) -> None:
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=CSV_COLUMNS)
        writer.writeheader()
        for point in points:
            writer.writerow(point.as_row())


def parse_rhos(text: str) -> list[float]:
    """'0,0.05,0.1' -> floats; each must be a probability."""
    try:
        values = [float(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise UsageError(f"--rhos must be comma-separated numbers (got {text!r})") from None
    if not values or any(not math.isfinite(v) or not 0.0 <= v <= 1.0 for v in values):
        raise UsageError(f"--rhos must be probabilities in [0, 1] (got {text!r})")
    return values
