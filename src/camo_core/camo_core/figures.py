"""The paper's simulation figure for one run, and the error-analysis figure."""

from __future__ import annotations

from pathlib import Path

import cv2
import matplotlib

matplotlib.use("Agg")
import matplotlib.patches
import matplotlib.pyplot as plt
import numpy as np

from .result import RunResult

PATTERN_COLORS = {"horizontal": "tab:blue", "vertical": "tab:green", "mottled": "tab:orange"}

# A panel is about 260 px wide in the saved figure; a grid or image with a side above this is
# drawn from a copy resized to it (imshow of a 1024x1024 grid takes 0.3 s, and shows no more of
# it). Smaller ones are drawn as they are.
MAX_PANEL_PX = 512


def _shown(values: np.ndarray, nearest: bool) -> tuple[np.ndarray, dict]:
    """values (rows x cols, or x 3) as a panel draws them, and imshow's extra arguments: a side
    above MAX_PANEL_PX is resized to it, by sampling cells (nearest: as imshow's "nearest" draws
    a large grid) or by area averaging (as imshow's antialiasing), and drawn over the full
    extent, so that the axes (limits, aspect) are those of the full grid."""
    rows, cols = values.shape[:2]
    if rows <= MAX_PANEL_PX and cols <= MAX_PANEL_PX:
        return values, {}
    size = (min(cols, MAX_PANEL_PX), min(rows, MAX_PANEL_PX))  # OpenCV: width, height
    how = cv2.INTER_NEAREST_EXACT if nearest else cv2.INTER_AREA
    small = cv2.resize(np.ascontiguousarray(values), size, interpolation=how)
    return small, {"extent": (-0.5, cols - 0.5, rows - 0.5, -0.5)}


def run_figure(
    result: RunResult, image: np.ndarray | None, path: str | Path, title: str = ""
) -> Path:
    """One row of five panels: input, sensed grid, consensus curves, initial and final states."""
    fig, axes = plt.subplots(1, 5, figsize=(17, 3.6))
    if image is not None:
        shown, extent = _shown(image, nearest=False)
        shown = shown if shown.ndim == 2 else shown[:, :, ::-1]
        axes[0].imshow(shown, cmap="gray", vmin=0, vmax=255, **extent)
    axes[0].set_title("input image")
    shown, extent = _shown(result.sensed, nearest=True)
    axes[1].imshow(shown, cmap="gray", vmin=0, vmax=255, interpolation="nearest", **extent)
    axes[1].set_title(f"sensed ({result.params.rows}x{result.params.cols})")
    trace = result.consensus_trace
    for k, name in enumerate(PATTERN_COLORS):
        axes[2].plot(
            range(len(trace)),
            trace[:, k],
            label=f"p_{name[0]} ({name})",
            color=PATTERN_COLORS[name],
        )
    axes[2].axhline(0.5, color="red", linewidth=1.2)
    axes[2].set_ylim(-0.02, 1.02)
    axes[2].set_xlabel("consensus step")
    axes[2].set_ylabel("mean p over robots")
    axes[2].legend(fontsize=7, loc="best")
    axes[2].set_title(f"consensus: {result.majority_pattern}")
    for ax, states, label in (
        (axes[3], result.initial, "initial state"),
        (axes[4], result.final, "generated pattern"),
    ):
        shown = np.where(states == 1, 0, 255).astype(float)
        if result.alive is not None:
            shown[~result.alive] = 128
        shown, extent = _shown(shown, nearest=True)
        ax.imshow(shown, cmap="gray", vmin=0, vmax=255, interpolation="nearest", **extent)
        ax.set_title(label)
    for ax in (axes[0], axes[1], axes[3], axes[4]):
        ax.set_xticks([])
        ax.set_yticks([])
    if title:
        fig.suptitle(title)
    return _save(fig, path)


def errors_figure(
    rows: list[dict], random_level: float, path: str | Path, title: str = ""
) -> Path:
    """Mean total absolute difference against error probability, one line per mode."""
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for mode, label in (
        ("measurement", "measurement error only"),
        ("communication", "communication error only"),
        ("both", "both, equal probability"),
    ):
        data = [r for r in rows if r["mode"] == mode]
        ax.errorbar(
            [r["rho"] for r in data],
            [r["mean_diff"] for r in data],
            yerr=[r["std_diff"] for r in data],
            marker="o",
            capsize=3,
            label=label,
        )
    ax.axhline(
        random_level, color="gray", linestyle="--", label=f"random pattern ({random_level:g})"
    )
    ax.set_xlabel("error probability")
    ax.set_ylabel("total absolute difference to error-free pattern")
    ax.legend()
    if title:
        ax.set_title(title)
    return _save(fig, path)


def timeline_figure(
    frames: list[tuple[str, np.ndarray]], path: str | Path, title: str = ""
) -> Path:
    """A strip of small grids: selected pattern at each consensus step (c<k>), state at each
    formation step (f<k>).

    Consensus frames hold 0/1/2 (horizontal/vertical/mottled), formation frames 0/1 (off/on); -1 is
    a robot that did not report that step (grey).
    """
    consensus = [f for f in frames if f[0].startswith("c")]
    formation = [f for f in frames if f[0].startswith("f")]
    per_row = max(1, min(12, max(len(consensus), len(formation))))
    rows = -(-len(consensus) // per_row) + -(-len(formation) // per_row)
    fig, axes = plt.subplots(
        rows, per_row, figsize=(1.2 * per_row, 1.35 * rows + 0.8), squeeze=False
    )
    for ax in axes.flat:
        ax.axis("off")
    colors = np.array(
        [matplotlib.colors.to_rgb(c) for c in PATTERN_COLORS.values()] + [(0.5, 0.5, 0.5)]
    )
    grey = {0: 1.0, 1: 0.0, -1: 0.5}
    row = 0
    for group, paint in (
        (consensus, lambda g: colors[np.where(g < 0, 3, g)]),
        (formation, lambda g: np.vectorize(grey.get)(g).astype(float)[..., None].repeat(3, -1)),
    ):
        for k, (label, grid) in enumerate(group):
            ax = axes[row + k // per_row, k % per_row]
            ax.imshow(paint(np.asarray(grid)), interpolation="nearest")
            ax.set_title(label, fontsize=7)
        row += -(-len(group) // per_row)
    handles = [matplotlib.patches.Patch(color=c, label=n) for n, c in PATTERN_COLORS.items()]
    fig.legend(handles=handles, loc="upper right", fontsize=7, ncol=3)
    fig.suptitle(
        title or "consensus steps (c: selected pattern), then formation steps (f: dark = on)",
        fontsize=9,
        x=0.02,
        ha="left",
    )
    return _save(fig, path)


def _save(fig, path: str | Path) -> Path:
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
