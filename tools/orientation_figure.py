"""docs/img/orientation_any.png: stripes at several angles drawn by the paper's two directions
and by --orientation any, at 32x32 robots; and how many of 72 striped images (12 angles, 3
periods, 2 noise levels) --orientation any reads within 15 degrees.

    .venv/bin/python tools/orientation_figure.py [OUT.png]
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from camo_core.algorithm.backgrounds import stripes
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.sensing import sense_image
from camo_core.algorithm.simulator import simulate

SIDE = 32
SHOWN = (0, 30, 45, 60, 90, 135)
PERIODS = (32, 48, 64)  # pixels of a 256-pixel image: 4, 6 and 8 robots
NOISES = (20, 50)


def run(image: np.ndarray, orientation: str):
    params = CamoParams(rows=SIDE, cols=SIDE, orientation=orientation)
    result = simulate(params, sense_image(image, SIDE, SIDE, params.profile))
    agreement = float(np.mean(result.final == (result.sensed < 127)))
    return result, agreement


def angle_error(a: float, b: float) -> float:
    d = abs(a - b) % 180
    return min(d, 180 - d)


def main(argv: list[str]) -> int:
    out = Path(argv[0]) if argv else Path("docs/img/orientation_any.png")
    fig, axes = plt.subplots(3, len(SHOWN), figsize=(2.3 * len(SHOWN), 7.4))
    for column, degrees in enumerate(SHOWN):
        image = stripes(degrees, period=48, seed=degrees)
        axes[0, column].imshow(image, cmap="gray", vmin=0, vmax=255)
        axes[0, column].set_title(f"stripes at {degrees}°", fontsize=9)
        for row, orientation in ((1, "axes"), (2, "any")):
            result, agreement = run(image, orientation)
            axes[row, column].imshow(1 - result.final, cmap="gray", vmin=0, vmax=1)
            label = result.majority_label
            axes[row, column].set_title(f"{label}\nagreement {agreement:.2f}", fontsize=8)
            print(f"{degrees:3d}° {orientation:4s} {label:16s} agreement {agreement:.2f}")
    for ax in axes.flat:
        ax.set_xticks([])
        ax.set_yticks([])
    axes[1, 0].set_ylabel("--orientation axes\n(the paper)", fontsize=9)
    axes[2, 0].set_ylabel("--orientation any", fontsize=9)
    right = 0
    total = 0
    for degrees in range(0, 180, 15):
        for period in PERIODS:
            for noise in NOISES:
                result, _ = run(stripes(degrees, period, noise=noise, seed=period + noise), "any")
                angle = result.orientation_deg
                total += 1
                right += angle is not None and angle_error(angle, degrees) <= 15
    fig.suptitle(
        f"{SIDE}x{SIDE} robots; agreement: share of robots whose final state is their sensed "
        f"binarised grey. --orientation any reads {right} of {total} striped images within 15°",
        fontsize=9,
    )
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    print(f"{right}/{total} striped images read within 15 degrees; wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
