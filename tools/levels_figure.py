"""docs/img/levels.png: what the swarm shows with the paper's black and white, --levels 2 and
--levels 4, beside what it sensed, at 32x32 robots with --threshold auto; the grey distance
(greys shown to greys sensed) under each, and its mean over the images.

    .venv/bin/python tools/levels_figure.py [OUT.png]
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from camo_core.algorithm.backgrounds import background, stripes
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.sensing import sense_image
from camo_core.algorithm.simulator import simulate

SIDE = 32
LEVELS = (0, 2, 4)
HEADS = ("background", "sensed", "paper: black and white", "--levels 2", "--levels 4")


def images() -> dict[str, np.ndarray]:
    shown = {name: background(name) for name in ("desert", "forest", "leopard")}
    shown["stripes at 60°"] = stripes(60, period=48)
    gravel = np.random.default_rng(2).normal(128, 40, (64, 64))
    shown["gravel"] = np.clip(np.kron(gravel, np.ones((4, 4))), 0, 255).astype(np.uint8)
    return shown


def main(argv: list[str]) -> int:
    out = Path(argv[0]) if argv else Path("docs/img/levels.png")
    cards = images()
    fig, axes = plt.subplots(len(cards), 2 + len(LEVELS), figsize=(11, 2.3 * len(cards)))
    distances = {k: [] for k in LEVELS}
    for row, (name, image) in enumerate(cards.items()):
        raw = sense_image(image, SIDE, SIDE, "paper")
        axes[row, 0].imshow(image, cmap="gray", vmin=0, vmax=255)
        axes[row, 0].set_ylabel(name, fontsize=9)
        axes[row, 1].imshow(raw, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
        for column, k in enumerate(LEVELS, start=2):
            params = CamoParams(rows=SIDE, cols=SIDE, levels=k, threshold_auto=True)
            result = simulate(params, raw)
            distances[k].append(result.grey_distance)
            ax = axes[row, column]
            ax.imshow(result.display, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
            head = f"{HEADS[column]}\n" if row == 0 else ""
            ax.set_title(f"{head}grey distance {result.grey_distance:.1f}", fontsize=8)
    axes[0, 0].set_title(HEADS[0], fontsize=8)
    axes[0, 1].set_title(HEADS[1], fontsize=8)
    for ax in axes.flat:
        ax.set_xticks([])
        ax.set_yticks([])
    means = {k: float(np.mean(v)) for k, v in distances.items()}
    fig.suptitle(
        f"{SIDE}x{SIDE} robots, --threshold auto; mean grey distance: paper {means[0]:.1f}, "
        f"--levels 2 {means[2]:.1f}, --levels 4 {means[4]:.1f}",
        fontsize=10,
    )
    fig.tight_layout(rect=(0, 0, 1, 0.98))
    fig.savefig(out, dpi=80)
    print(", ".join(f"levels {k}: {m:.1f}" for k, m in means.items()), f"; wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
