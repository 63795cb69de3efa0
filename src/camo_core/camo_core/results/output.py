"""A round's summary.json and figure.png, as `./camo sim`, the swarm's monitor and `camo render`
write them."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from camo_core.results import figures
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
    summary = result.summary()
    if incomplete is not None:
        # What robots never said is unknown, not a number: null, never NaN.
        summary = {key: no_nan(value) for key, value in summary.items()}
        summary["incomplete"] = incomplete
    summary.update(extra or {})
    write_summary(summary, folder)
    figures.run_figure(result, image, folder / "figure.png", title=title, marks=marks)
    return summary
