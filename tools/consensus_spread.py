"""docs/img/consensus_spread.png: how far the robots' p-vectors still differ after each consensus
step, for square swarms of several sizes on the built-in forest, with the steps
`--consensus-steps auto` gives each size marked.

    .venv/bin/python tools/consensus_spread.py [OUT.png]
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from camo_core.algorithm.backgrounds import background
from camo_core.algorithm.params import CamoParams, auto_consensus_steps
from camo_core.algorithm.sensing import sense_image
from camo_core.algorithm.simulator import simulate

SIDES = (8, 16, 32, 64)
STEPS = 3500


def spread_per_step(side: int, steps: int = STEPS) -> np.ndarray:
    """max over the three patterns of (greatest - least robot's p), after each step."""
    params = CamoParams(rows=side, cols=side, consensus_steps=steps)
    image = background("forest")
    if image.shape[0] < side:
        image = cv2.resize(image, (side, side), interpolation=cv2.INTER_AREA)
    result = simulate(params, sense_image(image, side, side, params.profile))
    band = result.consensus_range  # steps + 1 x 3 x (least, greatest)
    return (band[:, :, 1] - band[:, :, 0]).max(axis=1)


def main(argv: list[str]) -> int:
    out = Path(argv[0]) if argv else Path("docs/img/consensus_spread.png")
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for side in SIDES:
        spread = spread_per_step(side)
        label = f"{side}x{side}" + ("" if spread.any() else " (every robot votes alike: 0)")
        line = ax.plot(np.arange(len(spread)), np.maximum(spread, 1e-6), label=label)
        auto = auto_consensus_steps("paper", side, side)
        ax.plot([auto], [max(spread[auto], 1e-6)], "o", color=line[0].get_color())
        ax.annotate(f"auto: {auto}", (auto, max(spread[auto], 1e-6)), fontsize=7,
                    xytext=(4, 4), textcoords="offset points")  # fmt: skip
    ax.axvline(35, color="grey", linestyle=":", label="35 steps (the paper's)")
    ax.set_xscale("symlog", linthresh=100)
    ax.set_xlim(0, STEPS)
    ax.set_yscale("log")
    ax.set_ylim(1e-6, 1.5)
    ax.set_xlabel("consensus step")
    ax.set_ylabel("spread of p across robots (greatest - least)")
    ax.set_title("Consensus on the built-in forest: residual spread against steps", fontsize=10)
    ax.legend(fontsize=8, loc="lower left")
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
