"""A round's summary.json and figure.png, as `./camo sim`, the swarm's monitor and `camo render`
write them."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import figures
from .params import CamoParams
from .result import RunResult, write_summary


def run_title(label: str, params: CamoParams, robots: str = "robots") -> str:
    return (
        f"{label}: {params.rows}x{params.cols} {robots}, {params.profile} profile, "
        f"seed {params.seed}, rho_meas {params.rho_meas:g}, rho_comm {params.rho_comm:g}"
    )


def write_round(
    result: RunResult,
    image: np.ndarray | None,
    folder: Path,
    title: str,
    incomplete: str | None = None,
) -> dict:
    """summary.json (with `incomplete` saying how far a stopped run got) and figure.png."""
    summary = result.summary()
    if incomplete is not None:
        summary["incomplete"] = incomplete
    write_summary(summary, folder)
    figures.run_figure(result, image, folder / "figure.png", title=title)
    return summary
