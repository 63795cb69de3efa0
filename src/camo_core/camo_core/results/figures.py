"""The paper's simulation figure for one run, and the error-analysis figure."""

from __future__ import annotations

from pathlib import Path

import cv2
import matplotlib

matplotlib.use("Agg")
import matplotlib.collections
import matplotlib.colors
import matplotlib.figure
import matplotlib.patches
import matplotlib.pyplot as plt
import numpy as np

from camo_core.algorithm.modes.palettes import GridPalette
from camo_core.algorithm.orientation import CODES, COHERENCE_MIN, ORIENTED, STEP_DEG
from camo_core.algorithm.patterns import MOTTLED, PATTERN_COLORS
from camo_core.algorithm.result import RunResult
from camo_core.results.snapshots import code_colours
from camo_core.results.tensor_colours import direction_legend

# The initial state's panel, by palette: the greys or colours a robot starts from.
INITIAL_LABELS = {
    "": "initial state (dark: sensed < 127)",
    "greys": "initial greys (each robot's class)",
    "colours": "initial colours (dark: sensed grey < 127)",
}
TENSOR_COLORS = {"Jxx": "tab:blue", "Jyy": "tab:green", "Jxy": "tab:purple"}

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


# How the run figure marks robots that did not simply run (name -> scatter style and legend).
MARK_STYLES = {
    "dead": {"marker": "x", "color": "red", "label": "dead: no result"},
    "silent": {
        "marker": "o",
        "facecolors": "none",
        "edgecolors": "darkorange",
        "label": "silent for a while: a neighbour gave up on it",
    },
    "bridged": {
        "marker": "s",
        "facecolors": "none",
        "edgecolors": "deepskyblue",
        "label": "real Droplet (bridged)",
    },
    "real reading": {
        "marker": "D",
        "facecolors": "none",
        "edgecolors": "deepskyblue",
        "label": "real sensor reading (--sensed)",
    },
}


def run_figure(
    result: RunResult,
    image: np.ndarray | None,
    path: str | Path,
    title: str = "",
    marks: dict[str, np.ndarray] | None = None,
) -> Path:
    """figure.png: run_plot's figure, saved."""
    return _save(run_plot(result, image, title, marks), path)


def run_plot(
    result: RunResult,
    image: np.ndarray | None,
    title: str = "",
    marks: dict[str, np.ndarray] | None = None,
) -> matplotlib.figure.Figure:
    """One row of six panels: background, sensed grid, consensus curves, each robot's chosen
    pattern, initial and final states.

    marks: name (a key of MARK_STYLES) -> rows x cols bool, the robots to mark on the grids;
    dead robots (those not alive in the result) are always marked.
    """
    fig, axes = plt.subplots(1, 6, figsize=(20.4, 3.9))
    if image is not None:
        shown, extent = _shown(image, nearest=False)
        shown = shown if shown.ndim == 2 else shown[:, :, ::-1]
        axes[0].imshow(shown, cmap="gray", vmin=0, vmax=255, **extent)
    axes[0].set_title("background")
    modes = result.modes
    coloured = modes.palette.colour and result.palette_rgb is not None and result.shades is not None
    sensed = modes.sensing.shown(result.sensed, result.sensed_rgb) if coloured else result.sensed
    if result.positions is not None:
        draw_discs(axes[1], result.positions, sensed)
    else:
        _grid_panel(axes[1], sensed)
    what = "colour" if coloured else "grey"
    axes[1].set_title(f"sensed {what} ({result.params.rows}x{result.params.cols} robots)")
    _consensus_panel(axes[2], result)
    _chosen_panel(axes[3], result)
    axes = np.delete(axes, 3)  # the states' panels follow, as in the paper's figure
    palette = GridPalette(result.palette, result.palette_rgb, result.shades)
    shows = modes.palette.shows if result.palette is not None or coloured else ""
    for ax, states, label in (
        (axes[3], result.initial, INITIAL_LABELS[shows]),
        (axes[4], result.final, f"generated pattern ({result.majority_label})"),
    ):
        shown = np.where(states == 1, 0, 255).astype(float)
        if shows:  # the greys or colours shown
            shown = modes.palette.shown_grid(states, palette).astype(float)
            if ax is axes[4]:
                label = f"shown {modes.palette.shows} ({result.majority_label}), "
                label += modes.palette.describe()
        if result.alive is not None:
            shown[~result.alive] = 128
        if result.positions is not None:
            draw_discs(ax, result.positions, shown)
        else:
            _grid_panel(ax, shown)
        ax.set_title(label)
    if result.orientation_deg is not None:
        if result.positions is not None:
            low, high = result.positions.min(axis=0), result.positions.max(axis=0)
            box = (high[1] - low[1] + 1, high[0] - low[0] + 1, *((low + high) / 2)[::-1])
        else:
            rows, cols = result.params.rows, result.params.cols
            box = (rows, cols, (rows - 1) / 2, (cols - 1) / 2)
        _direction(axes[4], result.orientation_deg, *box)
    all_marks = dict(marks or {})
    if result.alive is not None:
        all_marks["dead"] = ~result.alive
    handles = [h for ax in axes[[1, 3, 4]] for h in mark(ax, all_marks, result.positions)]
    if handles:
        legend = {h.get_label(): h for h in handles}
        fig.legend(legend.values(), legend.keys(), loc="lower right", fontsize=8, ncol=4)
    for ax in fig.axes:
        if ax is not axes[2]:
            ax.set_xticks([])
            ax.set_yticks([])
    if title:
        fig.suptitle(title)
    fig.tight_layout(rect=(0, 0.07 if handles else 0, 1, 1))
    return fig


def _chosen_panel(ax, result: RunResult) -> None:
    """Each robot's chosen pattern in its colour (a --scope local swarm's regions), grey where
    a robot chose none; its legend names the patterns chosen."""
    colours = code_colours()
    chosen = np.asarray(result.selected, dtype=np.int64)
    none = (chosen < 0) | (chosen >= CODES)
    if result.alive is not None:
        none |= ~result.alive
    codes = np.where(none, CODES, chosen)
    if result.positions is not None:
        draw_discs(ax, result.positions, colours[codes] * 255)
    else:
        _grid_panel(ax, codes, palette=colours * 255)
    counts = result.selection_counts
    named = [(k, n) for k, n in zip(result.codes, counts, strict=True) if counts[n]]
    handles = [matplotlib.patches.Patch(color=colours[k], label=label_of(n)) for k, n in named]
    ax.legend(handles=handles, fontsize=6.5, loc="lower left", framealpha=0.8)
    ax.set_title("chosen pattern by robot")


def label_of(name: str) -> str:
    """A pattern's name as a legend says it ("stripes_30" is "stripes at 30°")."""
    kind, _, angle = name.partition("_")
    return f"stripes at {angle}°" if angle else kind


def _grid_panel(ax, values: np.ndarray, palette: np.ndarray | None = None) -> None:
    """A grid of greys (rows x cols) or colours (rows x cols x 3, sRGB), 0..255, a cell each.
    With a `palette` (n x 3, sRGB 0..255) values are indices into it, looked up once the cells
    a panel shows are picked: a large grid's colours are not all worked out."""
    if palette is None:
        shown, extent = _shown(np.asarray(values, dtype=float), nearest=True)
    else:
        picked, extent = _shown(np.asarray(values, dtype=np.uint16), nearest=True)
        shown = np.asarray(palette, dtype=float)[picked]
    if shown.ndim == 3:
        ax.imshow(np.clip(shown / 255.0, 0, 1), interpolation="nearest", **extent)
    else:
        ax.imshow(shown, cmap="gray", vmin=0, vmax=255, interpolation="nearest", **extent)


def draw_discs(ax, positions: np.ndarray, greys: np.ndarray):
    """--layout: each robot a disc at its position, in its grey or (robots x 3) colour (y down,
    as on the grid); the discs' collection."""
    values = np.asarray(greys, dtype=float)
    coloured = values.shape[-1:] == (3,) and values.size == 3 * len(positions)
    discs = matplotlib.collections.PatchCollection(
        [matplotlib.patches.Circle((x, y), 0.45) for x, y in positions],
        cmap=None if coloured else "gray",
        edgecolor="none",
    )
    if coloured:
        discs.set_facecolor(np.clip(values.reshape(-1, 3) / 255.0, 0, 1).tolist())
    else:
        discs.set_array(values.ravel())
        discs.set_clim(0, 255)
    ax.add_collection(discs)
    low, high = positions.min(axis=0) - 0.6, positions.max(axis=0) + 0.6
    ax.set_xlim(low[0], high[0])
    ax.set_ylim(high[1], low[1])
    ax.set_aspect("equal")
    ax.set_facecolor("#c8d2e0")
    return discs


def _direction(ax, degrees: int, height: float, width: float, y: float, x: float) -> None:
    """The chosen stripe direction, as a line through the swarm's centre (y up on the page)."""
    half = 0.42 * min(height, width)
    dx, dy = half * np.cos(np.radians(degrees)), half * np.sin(np.radians(degrees))
    ax.plot([x - dx, x + dx], [y + dy, y - dy], color="red", linewidth=2, alpha=0.8)
    ax.annotate(f"{degrees}°", (x + dx, y - dy), color="red", fontsize=9, fontweight="bold")


def _consensus_panel(ax, result: RunResult) -> None:
    """Each pattern's mean p over robots by consensus step, the band from the least to the
    greatest robot's p around it, and the p = 0.5 line the paper draws."""
    if result.modes.descriptor.oriented:
        _tensor_panel(ax, result)
        return
    trace = result.consensus_trace
    steps = range(len(trace))
    spread = result.consensus_range
    for k, name in enumerate(PATTERN_COLORS):
        color = PATTERN_COLORS[name]
        ax.plot(steps, trace[:, k], label=f"p_{name[0]} ({name}), mean", color=color)
        if spread is not None and len(spread) == len(trace):
            ax.fill_between(steps, spread[:, k, 0], spread[:, k, 1], color=color, alpha=0.15)
    if spread is not None and len(spread):
        ax.fill_between([], [], [], color="grey", alpha=0.3, label="band: least to greatest robot")
    ax.axhline(0.5, color="red", linewidth=1.2, label="p = 0.5: half of the weight")
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("consensus step")
    ax.set_ylabel("p over robots")
    ax.legend(fontsize=6.5, loc="best")
    ax.set_title(f"consensus: {result.majority_label}")


def _tensor_panel(ax, result: RunResult) -> None:
    """--orientation any: the mean tensor's entries by consensus step (with the robots' band),
    and its coherence against the line below which the swarm says mottled."""
    trace = result.consensus_trace
    steps = range(len(trace))
    spread = result.consensus_range
    for k, (name, color) in enumerate(TENSOR_COLORS.items()):
        ax.plot(steps, trace[:, k], label=f"{name}, mean", color=color)
        if spread is not None and len(spread) == len(trace):
            ax.fill_between(steps, spread[:, k, 0], spread[:, k, 1], color=color, alpha=0.15)
    jxx, jyy, jxy = trace[:, 0], trace[:, 1], trace[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        coherence = np.sqrt((jxx - jyy) ** 2 + 4 * jxy**2) / (jxx + jyy)
    ax.plot(steps, coherence, color="black", label="coherence of the mean")
    ax.axhline(COHERENCE_MIN, color="red", linewidth=1.2, label="below: mottled")
    ax.set_ylim(-0.52, 1.02)
    ax.set_xlabel("consensus step")
    ax.set_ylabel("structure tensor over robots")
    ax.legend(fontsize=6.5, loc="best")
    ax.set_title(f"consensus: {result.majority_label}")


def mark(ax, marks: dict[str, np.ndarray], positions: np.ndarray | None = None) -> list:
    """Scatter the marked robots of each kind on a grid panel (or, with `positions`, a
    layout's); their legend handles."""
    handles = []
    for name, mask in marks.items():
        mask = np.asarray(mask, bool)
        if positions is None:
            ys, xs = np.nonzero(mask)
        else:
            xs, ys = positions[mask.ravel()].T
        if len(xs):
            handles.append(ax.scatter(xs, ys, s=28, linewidths=1.3, **MARK_STYLES[name]))
    return handles


# The paper's error figure in its colours: red measurement, blue communication (both: black).
ERROR_MODES = (
    ("measurement", "measurement error only", "tab:red"),
    ("communication", "communication error only", "tab:blue"),
    ("both", "both, equal probability", "black"),
)
# What the paper reports of its error analysis (Li, Klingner, Correll, arXiv 1709.07051, Fig.
# "errorAnalysis" and its text): it gives no table, only these two figures.
PAPER_ROBUST_UP_TO = (0.15, 0.2)  # "robust up to about 0.15-0.2, then sharply worse"
PAPER_RANDOM_8X8 = 32  # "a random 8x8 pattern differs by 32 on average"


def errors_figure(
    rows: list[dict],
    random_level: float,
    path: str | Path,
    title: str = "",
    cells: int = 64,
    colours: bool = False,
) -> Path:
    """errors.png: errors_plot's figure, saved."""
    return _save(errors_plot(rows, random_level, title, cells, colours), path)


def errors_plot(
    rows: list[dict], random_level: float, title: str = "", cells: int = 64, colours: bool = False
) -> matplotlib.figure.Figure:
    """Left: the mean total absolute difference to the error-free pattern against the error
    probability, with the 10th-90th percentile band of the trials (a count: never below zero);
    right: the rate of trials that chose the error-free run's pattern. What the paper reports is
    overlaid (its random-pattern level only for an 8x8 swarm, `cells` = 64). Then the grey
    distance, and with `colours` (a --colours sweep) the colour distance, against it."""
    greys = all("mean_grey_distance" in r for r in rows)
    colours = colours and all("mean_colour_distance" in r for r in rows)
    panels = 2 + greys + colours
    fig, axes = plt.subplots(1, panels, figsize=(6 * panels, 4.8))
    diff_ax, rate_ax = axes[0], axes[1]
    for mode, label, color in ERROR_MODES:
        data = sorted((r for r in rows if r["mode"] == mode), key=lambda r: r["rho"])
        if not data:
            continue
        rho = [r["rho"] for r in data]
        diff_ax.plot(rho, [r["mean_diff"] for r in data], marker="o", color=color, label=label)
        if all("p10_diff" in r for r in data):
            diff_ax.fill_between(
                rho,
                [r["p10_diff"] for r in data],
                [r["p90_diff"] for r in data],
                color=color,
                alpha=0.15,
            )
        rate_ax.plot(rho, [r["correct_rate"] for r in data], marker="o", color=color, label=label)
        if greys:
            shown = [r["mean_grey_distance"] for r in data]
            axes[2].plot(rho, shown, marker="o", color=color, label=label)
        if colours:
            shown = [r["mean_colour_distance"] for r in data]
            axes[-1].plot(rho, shown, marker="o", color=color, label=label)
    if colours:
        axes[-1].set_ylim(bottom=0)
        axes[-1].set_xlabel("error probability")
        axes[-1].set_ylabel("CIEDE2000 (mean over robots and trials)")
        axes[-1].set_title("colour distance: colours shown to colours sensed")
        axes[-1].legend(fontsize=7.5)
    if greys:
        axes[2].set_ylim(bottom=0)
        axes[2].set_xlabel("error probability")
        axes[2].set_ylabel("grey levels (mean over trials)")
        axes[2].set_title("grey distance: greys shown to greys sensed")
        axes[2].legend(fontsize=7.5)
    diff_ax.fill_between([], [], [], color="grey", alpha=0.3, label="band: 10th-90th percentile")
    diff_ax.axhline(
        random_level,
        color="grey",
        linestyle="--",
        label=f"a random pattern differs by {random_level:g} (half the robots)",
    )
    for ax in (diff_ax, rate_ax):
        ax.axvspan(
            *PAPER_ROBUST_UP_TO,
            color="gold",
            alpha=0.25,
            label="paper: robust up to 0.15-0.2, then sharply worse",
        )
        ax.set_xlabel("error probability")
    if cells == 64:
        diff_ax.plot(
            [], [], " ", label=f"paper: a random 8x8 pattern differs by {PAPER_RANDOM_8X8}"
        )
    diff_ax.set_ylim(bottom=0)
    diff_ax.set_ylabel(f"robots whose final state differs\nfrom the error-free run (of {cells})")
    diff_ax.set_title("pattern difference")
    diff_ax.legend(fontsize=7.5)
    rate_ax.set_ylim(-0.02, 1.02)
    rate_ax.set_ylabel("share of trials that chose the error-free pattern")
    rate_ax.set_title("correct-pattern rate")
    rate_ax.legend(fontsize=7.5, loc="lower left")
    fig.text(
        0.01,
        0.01,
        "paper: Li, Klingner, Correll, arXiv 1709.07051, Fig. errorAnalysis and its text "
        "(mean of 10 trials on its forest photograph; it gives no table of values)",
        fontsize=7,
        color="dimgray",
    )
    if title:
        fig.suptitle(title)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    return fig


def timeline_figure(
    frames: list[tuple[str, np.ndarray]], path: str | Path, title: str = ""
) -> Path:
    """A strip of small grids: selected pattern at each consensus step (c<k>), state at each
    formation step (f<k>).

    Consensus frames hold 0/1/2 (horizontal/vertical/mottled) or, with --orientation any, the
    stripe codes (orientation.ORIENTED + k, in their direction's colour); formation frames 0/1
    (off/on), or with --colours the colours shown (rows x cols x 3); -1 is a robot that did not
    report that step (grey).
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
    colors = code_colours()
    grey = {0: 1.0, 1: 0.0, -1: 0.5}

    def shown(g: np.ndarray) -> np.ndarray:  # states, or (--colours) the colours shown
        if g.ndim == 3:
            return np.where(g < 0, 0.5, g / 255.0)
        return np.vectorize(grey.get)(g).astype(float)[..., None].repeat(3, -1)

    row = 0
    for group, paint in (
        (consensus, lambda g: colors[np.where(g < 0, CODES, g)]),
        (formation, shown),
    ):
        for k, (label, grid) in enumerate(group):
            ax = axes[row + k // per_row, k % per_row]
            ax.imshow(paint(np.asarray(grid)), interpolation="nearest")
            ax.set_title(label, fontsize=7)
            ax.axis("on")  # a frame, so that an all-white (all off) grid is seen
            ax.set_xticks([])
            ax.set_yticks([])
        row += -(-len(group) // per_row)
    handles = [matplotlib.patches.Patch(color=c, label=n) for n, c in PATTERN_COLORS.items()]
    if any((np.asarray(g) >= ORIENTED).any() for _, g in consensus):
        handles = [handles[MOTTLED], *direction_legend()[:-1]]
    fig.legend(handles=handles, loc="upper right", fontsize=7, ncol=3)
    fig.suptitle(
        title or "consensus steps (c: selected pattern), then formation steps (f: dark = on)",
        fontsize=9,
        x=0.02,
        ha="left",
    )
    fig.tight_layout()
    return _save(fig, path)


def _save(fig, path: str | Path) -> Path:
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
