"""`./camo sweep plot DIR --x AXIS [--y METRIC] [--by AXIS | --heat AXIS]`: a metric of the
table against an axis (mean, and the 10th-90th percentile band of the trials), one line per
value of another axis, or a heat map of the mean over two axes."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from camo_core.cli.options import Parser
from camo_core.exceptions import UsageError
from camo_core.results.folders import PNG_SOFTWARE, check_replaceable_png
from camo_sweep.table import read

METRICS = (
    "diff_cells",
    "grey_distance",
    "colour_distance",
    "correct",
    "votes_horizontal",
    "votes_vertical",
    "votes_mottled",
    "mean_p_horizontal",
    "mean_p_vertical",
    "mean_p_mottled",
    "run_s",
    "equals_sim",
)
NOT_AXES = {
    *METRICS,
    "trial_id",
    "replicate",
    "seed",
    "driver",
    "chosen_pattern",
    "status",
    "sim_args",
}


def build_parser() -> Parser:
    parser = Parser(prog="camo sweep plot", description="draw a sweep's table")
    parser.add_argument("folder", type=Path, help="the sweep's folder (its --out)")
    parser.add_argument("--x", required=True, help="the axis along x")
    parser.add_argument(
        "--y", default="diff_cells", choices=METRICS, help="the metric (default diff_cells)"
    )
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--by", default=None, help="one line per value of this axis")
    group.add_argument("--heat", default=None, help="a heat map: this axis along y")
    parser.add_argument("--out", type=Path, default=None, help="the PNG (default in the folder)")
    return parser


def columns(folder: Path) -> dict[str, list]:
    table = read(folder)
    data = table.to_pydict()
    ok = [status == "ok" for status in data["status"]]
    return {
        name: [v for v, keep in zip(values, ok, strict=True) if keep]
        for name, values in data.items()
    }


def check_axis(name: str | None, data: dict[str, list]) -> None:
    if name is None:
        return
    axes = [c for c in data if c not in NOT_AXES]
    if name not in data or name in NOT_AXES:
        raise UsageError(f"{name!r} is not an axis of this sweep (axes: {', '.join(axes)})")


def _groups(keys: list, values: np.ndarray) -> tuple[list, list[np.ndarray]]:
    order = sorted(set(keys), key=_sort_key)
    index = {k: [] for k in order}
    for k, v in zip(keys, values, strict=True):
        index[k].append(v)
    return order, [np.asarray(index[k], dtype=float) for k in order]


def _sort_key(value):
    """Numbers (also those of a text column: `consensus_steps=35,auto`), then text, then unset
    values (None), each in their own order."""
    if value is None:
        return (2, 0.0, "")
    if isinstance(value, str):
        try:
            return (0, float(value), value)
        except ValueError:
            return (1, 0.0, value)
    return (0, value, "")


def plot(folder: Path, x: str, y: str, by: str | None, heat: str | None, out: Path) -> Path:
    data = columns(folder)
    for name in (x, by, heat):
        check_axis(name, data)
    if not data["trial_id"]:
        raise UsageError(f"{folder} holds no trial that ran (status ok)")
    values = np.asarray([np.nan if v is None else float(v) for v in data[y]])
    if np.isnan(values).all():
        raise UsageError(f"{y} has no values in {folder} (equals_sim: only --driver ros has it)")
    for name in (x, by, heat):  # a block that leaves an axis alone: the default, by name
        if name and None in data[name]:
            data[name] = ["default" if v is None else str(v) for v in data[name]]
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    if heat:
        xs, ys = sorted(set(data[x]), key=_sort_key), sorted(set(data[heat]), key=_sort_key)
        grid = np.full((len(ys), len(xs)), np.nan)
        for i, yv in enumerate(ys):
            for j, xv in enumerate(xs):
                cell = values[
                    [a == xv and b == yv for a, b in zip(data[x], data[heat], strict=True)]
                ]
                if len(cell):
                    grid[i, j] = np.nanmean(cell)
        shown = ax.imshow(grid, origin="lower", aspect="auto", cmap="viridis")
        ax.set_xticks(range(len(xs)), [f"{v:g}" if isinstance(v, float) else v for v in xs])
        ax.set_yticks(range(len(ys)), [f"{v:g}" if isinstance(v, float) else v for v in ys])
        ax.set_ylabel(heat)
        fig.colorbar(shown, ax=ax, label=f"mean {y}")
    else:
        series = [(None, np.ones(len(values), bool))]
        if by:
            series = [
                (v, np.array([b == v for b in data[by]]))
                for v in sorted(set(data[by]), key=_sort_key)
            ]
        for label, keep in series:
            keys = [k for k, kept in zip(data[x], keep, strict=True) if kept]
            order, groups = _groups(keys, values[keep])
            mean = [np.nanmean(g) for g in groups]
            low = [np.nanpercentile(g, 10) for g in groups]
            high = [np.nanpercentile(g, 90) for g in groups]
            name = y if label is None else f"{by} = {label}"
            line = ax.plot(order, mean, marker="o", label=f"{name}, mean")[0]
            ax.fill_between(order, low, high, color=line.get_color(), alpha=0.15)
        ax.fill_between([], [], [], color="grey", alpha=0.3, label="band: 10th-90th percentile")
        ax.set_ylabel(y)
        if np.nanmin(values) >= 0:
            ax.set_ylim(bottom=0)
        ax.legend(fontsize=8)
    ax.set_xlabel(x)
    ax.set_title(f"{y} against {x} ({len(values)} trials)")
    fig.tight_layout()
    fig.savefig(out, dpi=100, metadata={"Software": f"{PNG_SOFTWARE} sweep plot"})
    plt.close(fig)
    return out


def cmd_plot(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    by = f"_by_{args.by}" if args.by else f"_heat_{args.heat}" if args.heat else ""
    out = args.out or args.folder / f"{args.y}_{args.x}{by}.png"
    if out.suffix.lower() != ".png":
        raise UsageError(f"--out names a .png file (got {out})")
    if not out.parent.is_dir():
        raise UsageError(f"--out {out}: no folder {out.parent}")
    check_replaceable_png(out, "--out")
    plot(args.folder, args.x, args.y, args.by, args.heat, out)
    print(f"wrote {out}")
    return 0
