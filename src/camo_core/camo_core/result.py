"""What one camouflage run produced, and its summary.json form."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from . import kernels
from .params import CamoParams
from .rules import MOTTLED, PATTERN_NAMES

SUMMARY_KEYS = (
    "rows",
    "cols",
    "profile",
    "seed",
    "rho_meas",
    "rho_comm",
    "pattern",
    "votes",
    "mean_p",
    "sensed",
    "initial",
    "final",
    "consensus_trace",
    "elapsed_s",
)


def mean_p(p: np.ndarray) -> np.ndarray:
    """Mean p over robots (p: ... x 3), summed in robot-id order by every driver."""
    return kernels.mean_p(np.ascontiguousarray(p, dtype=np.float64).reshape(-1, 3))


@dataclass
class RunResult:
    params: CamoParams
    sensed: np.ndarray  # rows x cols float64, after measurement noise
    votes: np.ndarray  # rows x cols int, the local one-hot votes (pattern index)
    p: np.ndarray  # rows x cols x 3 float64, after the last consensus step
    selected: np.ndarray  # rows x cols int, each robot's selected pattern
    initial: np.ndarray  # rows x cols uint8, the binarised initial states
    final: np.ndarray  # rows x cols uint8, the states after the last formation step
    consensus_trace: np.ndarray  # (consensus_steps + 1) x 3, mean p before step 0 and after each
    elapsed_s: float = 0.0
    alive: np.ndarray | None = None  # rows x cols bool; None means every robot took part

    @property
    def selection_counts(self) -> dict[str, int]:
        chosen = self.selected if self.alive is None else self.selected[self.alive]
        return {name: int(np.count_nonzero(chosen == k)) for k, name in enumerate(PATTERN_NAMES)}

    @property
    def majority_pattern(self) -> str:
        """The selection most robots made; a tie for the most goes to mottled."""
        counts = list(self.selection_counts.values())
        best = max(counts)
        winners = [k for k, c in enumerate(counts) if c == best]
        return PATTERN_NAMES[winners[0] if len(winners) == 1 else MOTTLED]

    def summary(self) -> dict[str, Any]:
        p = self.p if self.alive is None else self.p[self.alive]
        params = self.params
        summary = {
            "rows": params.rows,
            "cols": params.cols,
            "profile": params.profile,
            "seed": params.seed,
            "rho_meas": params.rho_meas,
            "rho_comm": params.rho_comm,
            "pattern": self.majority_pattern,
            "votes": self.selection_counts,
            "mean_p": mean_p(p).tolist(),
            "sensed": self.sensed.tolist(),
            "initial": self.initial.astype(int).tolist(),
            "final": self.final.astype(int).tolist(),
            "consensus_trace": self.consensus_trace.tolist(),
            "elapsed_s": round(float(self.elapsed_s), 6),
        }
        if self.alive is not None:
            # A swarm run in which robots died: their cells hold null, and they are listed.
            dead = ~self.alive
            for key in ("initial", "final"):
                summary[key] = [
                    [None if dead[i, j] else v for j, v in enumerate(row)]
                    for i, row in enumerate(summary[key])
                ]
            summary["dead"] = [[int(i), int(j)] for i, j in zip(*np.nonzero(dead), strict=False)]
        return summary


def write_summary(summary: dict[str, Any], folder: Path) -> Path:
    path = folder / "summary.json"
    path.write_text(json.dumps(summary, indent=1) + "\n")
    return path
