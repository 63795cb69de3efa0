"""docs/img/colours.png: what the swarm shows of colour photographs with --levels 4 (greys) and
--colours 2, 4 and 8, beside what it sensed, at 32x32 robots; the colour distance (the mean
CIEDE2000 between the colour each robot shows and the colour it sensed) under each, and the
means and ratios over the photographs. The photographs are scikit-image's own (public domain
or CC0, shipped with it): a cat's fur, a cup of coffee, an astronaut, a rocket, a retina.

    .venv/bin/python tools/colours_figure.py [OUT.png]
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import cv2
import matplotlib.pyplot as plt
import numpy as np
from skimage import data

from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.sensing import sense_colours, sense_image
from camo_core.algorithm.simulator import simulate

SIDE = 32
PHOTOS = ("chelsea", "coffee", "astronaut", "rocket", "retina")
RUNS = (("levels", 4), ("colours", 2), ("colours", 4), ("colours", 8))


def main(argv: list[str]) -> int:
    out = Path(argv[0]) if argv else Path("docs/img/colours.png")
    fig, axes = plt.subplots(len(PHOTOS), 2 + len(RUNS), figsize=(13, 2.3 * len(PHOTOS)))
    distances: dict[tuple[str, int], list[float]] = {run: [] for run in RUNS}
    for row, name in enumerate(PHOTOS):
        rgb = np.ascontiguousarray(getattr(data, name)()[..., :3])
        image = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
        raw = sense_image(image, SIDE, SIDE, "paper")
        raw_colours = sense_colours(image, SIDE, SIDE)
        axes[row, 0].imshow(rgb)
        axes[row, 0].set_ylabel(name, fontsize=9)
        axes[row, 1].imshow(raw_colours / 255.0, interpolation="nearest")
        for column, (option, k) in enumerate(RUNS, start=2):
            params = CamoParams(rows=SIDE, cols=SIDE, **{option: k})
            result = simulate(params, raw, raw_colours=raw_colours)
            distance = result.colour_distance
            assert distance is not None  # the colours sensed were given
            distances[option, k].append(distance)
            ax = axes[row, column]
            ax.imshow(result.display_rgb / 255.0, interpolation="nearest")
            head = f"--{option} {k}\n" if row == 0 else ""
            ax.set_title(f"{head}colour distance {distance:.1f}", fontsize=8)
    axes[0, 0].set_title("photograph", fontsize=8)
    axes[0, 1].set_title("sensed colours", fontsize=8)
    for ax in axes.flat:
        ax.set_xticks([])
        ax.set_yticks([])
    means = {run: float(np.mean(v)) for run, v in distances.items()}
    greys = np.array(distances["levels", 4])
    ratios = {k: np.array(distances["colours", k]) / greys for k in (2, 4, 8)}
    said = ", ".join(f"--colours {k} {means['colours', k]:.1f}" for k in (2, 4, 8))
    fig.suptitle(
        f"{SIDE}x{SIDE} robots; mean colour distance (CIEDE2000): --levels 4 "
        f"{means['levels', 4]:.1f}, {said}",
        fontsize=10,
    )
    fig.tight_layout(rect=(0, 0, 1, 0.98))
    fig.savefig(out, dpi=80)
    for k, ratio in ratios.items():
        print(
            f"--colours {k}: mean distance {means['colours', k]:.2f} "
            f"(--levels 4: {means['levels', 4]:.2f}), per photograph "
            + ", ".join(f"{name} {r:.2f}x" for name, r in zip(PHOTOS, ratio, strict=True))
        )
    print(f"wrote {out}")
    ratios_on_crops()
    return 0


CROPPED = (*PHOTOS, "immunohistochemistry", "hubble_deep_field", "colorwheel")


def ratios_on_crops(crops: int = 3, seed: int = 1) -> None:
    """--colours 4 against --levels 4 on more photographs and `crops` random crops of each
    (30-60% of each side, drawn from `seed`): the spread of the ratio, printed."""
    generator = np.random.default_rng(seed)
    ratios = []
    for name in CROPPED:
        whole = np.ascontiguousarray(getattr(data, name)()[..., :3])
        height, width = whole.shape[:2]
        pictures = [whole]
        for _ in range(crops):
            share = generator.uniform(0.3, 0.6)
            h, w = int(height * share), int(width * share)
            top, left = generator.integers(0, height - h), generator.integers(0, width - w)
            pictures.append(whole[top : top + h, left : left + w])
        for picture in pictures:
            image = cv2.cvtColor(np.ascontiguousarray(picture), cv2.COLOR_RGB2BGR)
            raw = sense_image(image, SIDE, SIDE, "paper")
            colours = sense_colours(image, SIDE, SIDE)
            distance = {}
            for option in ("levels", "colours"):
                params = CamoParams(rows=SIDE, cols=SIDE, **{option: 4})
                distance[option] = simulate(params, raw, raw_colours=colours).colour_distance
            ratios.append(distance["colours"] / distance["levels"])
    print(
        f"--colours 4 / --levels 4 on {len(ratios)} photographs and crops: "
        f"least {min(ratios):.2f}, mean {np.mean(ratios):.2f}, greatest {max(ratios):.2f}"
    )


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
