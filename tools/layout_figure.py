"""docs/img/layouts.png: the same backgrounds on a square, a hexagonal and a jittered (0.3
spacings) swarm of 32x32 robots, --orientation any (and --threshold auto): what each draws.

    .venv/bin/python tools/layout_figure.py [OUT.png]
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from camo_core.algorithm.backgrounds import background, stripes
from camo_core.algorithm.layout import layout_for, sense_at
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.perrobot import run_per_robot
from camo_core.results import figures

SIDE = 32
LAYOUTS = ("jitter:0", "hex", "jitter:0.3")


def cards() -> dict[str, np.ndarray]:
    gravel = np.random.default_rng(2).normal(128, 40, (64, 64))
    return {
        "forest": background("forest"),
        "stripes at 45°": stripes(45, period=48),
        "stripes at 120°": stripes(120, period=48),
        "gravel": np.clip(np.kron(gravel, np.ones((4, 4))), 0, 255).astype(np.uint8),
    }


def main(argv: list[str]) -> int:
    out = Path(argv[0]) if argv else Path("docs/img/layouts.png")
    shown = cards()
    fig, axes = plt.subplots(len(shown), 1 + len(LAYOUTS), figsize=(10, 2.6 * len(shown)))
    for row, (name, image) in enumerate(shown.items()):
        axes[row, 0].imshow(image, cmap="gray", vmin=0, vmax=255)
        axes[row, 0].set_ylabel(name, fontsize=9)
        for column, spec in enumerate(LAYOUTS, start=1):
            params = CamoParams(rows=SIDE, cols=SIDE, orientation="any", threshold_auto=True,
                                layout=spec)  # fmt: skip
            layout = layout_for(params)
            raw = sense_at(image, layout).reshape(SIDE, SIDE)
            result = run_per_robot(params, raw)
            figures.draw_discs(axes[row, column], layout.positions, result.display)
            label = "square" if spec == "jitter:0" else spec
            axes[row, column].set_title(f"{label}: {result.majority_label}", fontsize=8)
            print(f"{name:16s} {label:10s} {result.majority_label}")
    for ax in axes.flat:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(f"{SIDE}x{SIDE} robots, --orientation any --threshold auto", fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=80)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
