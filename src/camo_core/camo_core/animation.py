"""run.gif: a round of the swarm step by step, as its robots reported it (matplotlib's animation,
written by Pillow).

Left, what the robots sensed (grey). Right, each consensus step with every robot coloured by
its p-vector (the mix of the three pattern colours it currently holds), then each formation
step with every robot's state (dark = on). Dead, silent and bridged robots carry the marks
of figure.png.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.colors
import matplotlib.patches
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.animation import FuncAnimation, PillowWriter

from .figures import PATTERN_COLORS, mark
from .record import RoundRecord

MAX_FRAMES = 80  # a long run is sampled: the GIF stays small and quick to look at
FRAME_S = 0.15
UNKNOWN = np.array([0.5, 0.5, 0.5])


def frames_of(record: RoundRecord) -> list[tuple[str, np.ndarray]]:
    """(caption, rows x cols x 3 RGB) per shown step: consensus steps, then formation steps."""
    params = record.params
    shape = (params.rows, params.cols, 3)
    palette = np.array([matplotlib.colors.to_rgb(c) for c in PATTERN_COLORS.values()])
    frames = []
    for step, p in enumerate(record.p_trace):
        known = ~np.isnan(p).any(axis=1)
        rgb = np.where(known[:, None], np.nan_to_num(p) @ palette, UNKNOWN)
        frames.append((f"consensus step {step}/{len(record.p_trace) - 1}", rgb.reshape(shape)))
    for step, state in enumerate(record.state_trace):
        grey = np.where(state < 0, 0.5, np.where(state == 1, 0.0, 1.0))
        caption = f"formation step {step}/{len(record.state_trace) - 1}"
        frames.append((caption, np.repeat(grey[:, None], 3, axis=1).reshape(shape)))
    if len(frames) > MAX_FRAMES:  # keep the first and the last, evenly between
        keep = np.unique(np.linspace(0, len(frames) - 1, MAX_FRAMES).round().astype(int))
        frames = [frames[k] for k in keep]
    return frames


def write_animation(
    record: RoundRecord,
    dead: np.ndarray,
    path: str | Path,
    title: str = "",
    marks: dict[str, np.ndarray] | None = None,
) -> Path:
    """run.gif of a round; `dead` (per robot) and `marks` (name -> rows x cols, as
    figures.run_figure takes them) say which robots carry a mark, with their legend."""
    params = record.params
    frames = frames_of(record)
    sensed = np.nan_to_num(record.sensed, nan=128.0).reshape(params.rows, params.cols)
    fig, (left, right) = plt.subplots(1, 2, figsize=(6.4, 3.9))
    left.imshow(sensed, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
    left.set_title("sensed grey", fontsize=9)
    shown = right.imshow(frames[0][1], interpolation="nearest")
    caption = right.set_title(frames[0][0], fontsize=9)
    all_marks = {**(marks or {}), "dead": np.asarray(dead, bool).reshape(params.rows, params.cols)}
    handles = []
    for ax in (left, right):
        ax.set_xticks([])
        ax.set_yticks([])
        handles = mark(ax, all_marks)
    handles += [matplotlib.patches.Patch(color=c, label=n) for n, c in PATTERN_COLORS.items()]
    handles += [
        matplotlib.patches.Patch(facecolor="black", edgecolor="grey", label="formation: on"),
        matplotlib.patches.Patch(facecolor="white", edgecolor="grey", label="formation: off"),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=7)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout(rect=(0, 0.16, 1, 0.95))

    def draw(k: int):
        shown.set_data(frames[k][1])
        caption.set_text(frames[k][0])
        return shown, caption

    path = Path(path)
    animation = FuncAnimation(fig, draw, frames=len(frames), blit=False)
    animation.save(path, writer=PillowWriter(fps=round(1 / FRAME_S)), dpi=80)
    plt.close(fig)
    return path
