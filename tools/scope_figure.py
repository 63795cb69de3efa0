"""docs/simulator.md's --scope local figures and numbers: composite scenes (tools/scenes.py) of
2-4 regions, each robot's chosen pattern against its region's, with --scope global and local.

    ./camo python tools/scope_figure.py [--scenes 30] [--out docs/img/scope_local.png]

Prints, per grid side and noise, the share of robots two or more cells from a boundary that
choose their region's pattern (pooled over the scenes, the mean over regions, the worst scene),
the stripes regions' formation energy ratios, how the rows at a boundary choose, and the share
of robots choosing global's pattern on single textures; draws three scenes.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import sys
from pathlib import Path

# One numba thread in each of the two processes the table is made in, on two cores: two
# threads each waited on each other (about twice the CPU on a busy machine). Read as numba is
# imported.
os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import matplotlib

matplotlib.use("Agg")
import matplotlib.patches
import matplotlib.pyplot as plt
import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from scenes import make_scene, robot_truth

from camo_core.algorithm.backgrounds import BACKGROUNDS, background
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.sensing import sense_image
from camo_core.algorithm.simulator import simulate
from camo_core.results.snapshots import code_colours

SIDES = (16, 32, 64)
NOISES = {
    "clean": {},
    "loss 0.1": {"rho_comm": 0.1},
    "loss and noise 0.1": {"rho_comm": 0.1, "rho_meas": 0.1},
}
FIRST_SEED = 1000  # held out: the rule's constants were chosen on other seeds


def energy_ratio(states: np.ndarray, pattern: int, where: np.ndarray) -> float | None:
    """A stripes region's second-difference energy across its stripes over that along them
    (the descriptor's |Py| direction over |Px| for horizontal stripes), where `where`."""
    s = states.astype(float)
    across_rows = (s[:-2, 1:-1] + s[2:, 1:-1] - 2 * s[1:-1, 1:-1]) ** 2
    across_cols = (s[1:-1, :-2] + s[1:-1, 2:] - 2 * s[1:-1, 1:-1]) ** 2
    inner = where[1:-1, 1:-1]
    along, across = (across_cols, across_rows) if pattern == 0 else (across_rows, across_cols)
    if not inner.any():
        return None
    return float(across[inner].sum() / max(along[inner].sum(), 1e-9))


def scene_rows(side: int, noise: str, seed: int) -> dict:
    """One scene's counts: per scope, robots right and robots counted (two or more cells from
    a boundary) and per region its share right; with local at 32x32 clean, its stripes
    regions' energy ratios and its boundary rows."""
    scene = make_scene(seed, cells=side)
    truth, region, distance = robot_truth(scene, side, side)
    grey = sense_image(scene.image, side, side, "paper")
    far = distance >= 2
    out: dict = {"energies": [], "boundary": np.zeros((3, 3))}
    for scope in ("global", "local"):
        params = CamoParams(rows=side, cols=side, scope=scope, seed=seed, **NOISES[noise])
        result = simulate(params, grey)
        right = result.selected == truth
        regions = [right[far & (region == k)] for k in np.unique(region)]
        # (A region of a small grid may have no interior.)
        out[scope] = (int(right[far].sum()), int(far.sum()), [r.mean() for r in regions if r.size])
        if scope == "local" and side == 32 and noise == "clean":
            for k in np.unique(region):
                pattern = int(scene.patterns[k])
                ratio = energy_ratio(result.final, pattern, far & (region == k))
                if pattern != 2 and ratio is not None:
                    out["energies"].append(ratio)
            patterns = [int(scene.patterns[k]) for k in np.unique(region)]
            for band in range(3):
                at = (distance >= band) & (distance < band + 1)
                nowhere = at & ~np.isin(result.selected, patterns)
                out["boundary"][band] += (at.sum(), (~right & at).sum(), nowhere.sum())
    return out


def evaluate(scenes: int) -> dict:
    """scene_rows over the held-out scenes, at every side and noise (two processes)."""
    jobs = [
        (side, noise, seed)
        for side in SIDES
        for noise in NOISES
        for seed in range(FIRST_SEED, FIRST_SEED + scenes)
    ]
    with multiprocessing.get_context("fork").Pool(2) as pool:
        done = pool.starmap(scene_rows, jobs)
    rows, energies, boundary = [], [], np.zeros((3, 3))
    for side in SIDES:
        for noise in NOISES:
            mine = [d for (s, n, _), d in zip(jobs, done, strict=True) if (s, n) == (side, noise)]
            for scope in ("global", "local"):
                right = sum(d[scope][0] for d in mine)
                total = sum(d[scope][1] for d in mine)
                regions = [share for d in mine for share in d[scope][2]]
                worst = min(d[scope][0] / d[scope][1] for d in mine)
                rows.append((side, noise, scope, right / total, np.mean(regions), worst))
            for d in mine:
                energies += d["energies"]
                boundary += d["boundary"]
    return {"rows": rows, "energies": energies, "boundary": boundary}


def single_textures() -> list[tuple[str, int, float]]:
    """The share of robots choosing global's pattern, on the built-in backgrounds."""
    out = []
    for name in BACKGROUNDS:
        for side in (8, 16, 32, 64):
            grey = sense_image(background(name), side, side, "paper")
            local = simulate(CamoParams(rows=side, cols=side, scope="local"), grey).selected
            paper = simulate(CamoParams(rows=side, cols=side), grey).selected
            out.append((name, side, float(np.mean(local == paper))))
    return out


def figure(path: Path, seeds=(1010, 1017, 1002), side: int = 32) -> None:
    """Each scene: the image, the chosen patterns with --scope global (the paper's 35 steps, and
    run to completion: --consensus-steps auto) and local, and the pattern local robots show."""
    colours = code_colours(oriented=False)
    fig, axes = plt.subplots(len(seeds), 5, figsize=(13.5, 2.9 * len(seeds)))
    for row, seed in zip(axes, seeds, strict=True):
        scene = make_scene(seed, cells=side)
        grey = sense_image(scene.image, side, side, "paper")

        def chosen(grey=grey, **options):
            params = CamoParams.from_options(rows=side, cols=side, **options)
            return simulate(params, grey)

        local = chosen(scope="local")
        panels = [
            (scene.image, "scene", "gray"),
            (colours[chosen().selected], "global (the paper's 35 steps)", None),
            (colours[chosen(consensus_steps="auto").selected], "global, to completion", None),
            (colours[local.selected], "--scope local", None),
            (local.display, "local: the pattern shown", "gray"),
        ]
        for ax, (picture, title, cmap) in zip(row, panels, strict=True):
            ax.imshow(picture, cmap=cmap, vmin=0, vmax=255, interpolation="nearest")
            ax.set_title(title, fontsize=9)
            ax.set_xticks([])
            ax.set_yticks([])
    handles = [
        matplotlib.patches.Patch(color=colours[k], label=name)
        for k, name in enumerate(("horizontal", "vertical", "mottled"))
    ]
    fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=8)
    fig.suptitle(f"composite scenes (tools/scenes.py), {side}x{side} robots: each robot's pattern")
    fig.tight_layout(rect=(0, 0.03, 1, 0.97))
    fig.savefig(path, dpi=80)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=30)
    parser.add_argument("--out", type=Path, default=Path("docs/img/scope_local.png"))
    args = parser.parse_args()
    found = evaluate(args.scenes)
    print("| robots | links and sensors | scope | pooled | mean over regions | worst scene |")
    print("|---|---|---|---|---|---|")
    for side, noise, scope, pooled, regions, worst in found["rows"]:
        print(
            f"| {side}x{side} | {noise} | {scope} | {100 * pooled:.1f}% | {100 * regions:.1f}% "
            f"| {100 * worst:.0f}% |"
        )
    ratios = np.array(found["energies"])
    print(
        f"\nstripes regions' energy ratio (32x32, local, clean): {len(ratios)} regions, "
        f"median {np.median(ratios):.1f}, least {ratios.min():.1f}, "
        f"{np.count_nonzero(ratios >= 3)} of them at least 3"
    )
    count, wrong, neither = found["boundary"].T
    for band in range(3):
        other = 100 * (wrong[band] - neither[band]) / count[band]
        print(
            f"row {band + 1} at a boundary: {other:.0f}% another region's pattern, "
            f"{100 * neither[band] / count[band]:.1f}% one that no region of its scene has"
        )
    print("\nsingle textures, robots choosing global's pattern:")
    for name, side, agree in single_textures():
        print(f"  {name} {side}x{side}: {100 * agree:.0f}%")
    figure(args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
