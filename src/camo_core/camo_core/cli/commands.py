"""Command line of the ROS-free tools: `./camo sim`, `./camo errors`, `./camo bench sim`.

Bad input (a missing or unreadable image, a bad parameter) is one line on
stderr and exit code 2, never a traceback.
"""

from __future__ import annotations

import argparse
import json
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from camo_core.algorithm.modes import Modes, modes_of
from camo_core.algorithm.modes.palettes import GridPalette
from camo_core.algorithm.modes.scopes import Previous
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.result import pattern_said
from camo_core.cli.options import (
    Parser,
    add_contrast_option,
    add_run_options,
    image_from,
    out_dir,
    params_from,
)
from camo_core.cli.params_file import write_params_file
from camo_core.cli.progress import ProgressBar
from camo_core.exceptions import UsageError, reported
from camo_core.inputs.files import checked_file
from camo_core.inputs.images import load_image
from camo_core.inputs.numeric import integer, items, number
from camo_core.results.output import run_title, start_drawings
from camo_core.results.snapshots import Snapshots
from camo_core.results.summary import write_summary
from camo_core.swarm.keys import fingerprint, new_key_file


def sensed_overrides(
    texts: list[str], rows: int, cols: int
) -> dict[tuple[int, int], tuple[float, tuple[float, float, float]]]:
    """--sensed ROW,COL=VALUE[/R,G,B] options: real readings (a bridged Droplet's) for some
    cells, a grey and its colour (by default the grey's)."""
    overrides = {}
    for text in texts:
        try:
            cell, reading = text.split("=")
            row, col = (integer(x) for x in items(cell, "--sensed"))
            grey, _, colour = reading.partition("/")
            value = number(grey)
            rgb = tuple(number(x) for x in items(colour, "--sensed")) if colour else (value,) * 3
            if len(rgb) != 3:
                raise ValueError
        except ValueError:
            raise UsageError(
                f"--sensed takes ROW,COL=VALUE or ROW,COL=VALUE/R,G,B (got {text!r})"
            ) from None
        if not (0 <= row < rows and 0 <= col < cols):
            raise UsageError(f"--sensed {text}: outside the {rows}x{cols} grid")
        if not all(0.0 <= v <= 255.0 for v in (value, *rgb)):
            raise UsageError(f"--sensed {text}: a grey value or colour channel is in 0..255")
        if (row, col) in overrides:
            raise UsageError(f"--sensed {row},{col}: that cell is given twice")
        overrides[(row, col)] = (value, (rgb[0], rgb[1], rgb[2]))
    return overrides


def cmd_sim(args: argparse.Namespace) -> int:
    params = params_from(args)
    modes = modes_of(params)
    # The background is read and sensed in a thread while numba loads the kernels (a third of
    # a second on one core, the other idle): OpenCV lets go of the GIL as it decodes and resizes.
    with ThreadPoolExecutor(1) as pool:
        sensing = pool.submit(_sensed_background, args, params, modes)
        from camo_core.algorithm.perrobot import run_per_robot  # numba: only for what simulates
        from camo_core.algorithm.simulator import simulate

        image, label, (raw, raw_colours) = sensing.result()
    exempt = None
    overrides = sensed_overrides(args.sensed, params.rows, params.cols)
    if overrides:
        # Real readings: they replace the image's value and get no simulated noise.
        exempt = np.zeros(raw.shape, bool)
        for (row, col), (value, rgb) in overrides.items():
            raw[row, col] = value
            raw_colours[row, col] = rgb
            exempt[row, col] = True
    previous = previous_round(args.after, params, modes) if args.after else None
    folder = out_dir(args)
    big = params.count >= 256 * 256
    bar = (
        ProgressBar(modes.scope.steps(params) + params.formation_steps, "simulating")
        if big
        else None
    )
    progress = (lambda phase, step, total: bar.update(note=phase)) if bar else None
    snapshots = Snapshots(params)
    if modes.layout.grid:
        result = simulate(
            params,
            raw,
            exempt,
            progress=progress,
            observe=snapshots,
            raw_colours=raw_colours,
            previous=previous,
        )
    else:  # no vectorised kernels for positions: the robots' own rules, one by one
        result = run_per_robot(
            params, raw, observe=snapshots, raw_colours=raw_colours, previous=previous
        )
    title = run_title(label, params)
    marks = None if exempt is None else {"real reading": exempt}
    sensed = modes.sensing.shown(result.sensed, result.sensed_rgb)
    dead = np.zeros(result.params.count, bool)  # the simulator loses messages, never robots
    drawings = start_drawings(result, image, snapshots, sensed, dead, folder, title, marks)
    summary = result.summary(arrays=True)
    write_summary(summary, folder)
    write_params_file(args.options_parser, args, folder)
    drawings.wait("figure.png and run.gif")
    how = "" if modes.layout.grid else "robot by robot "
    print(
        f"pattern: {pattern_said(summary)}; wrote {folder}/summary.json, "
        f"figure.png and run.gif; simulated {how}in {result.elapsed_s:.3f} s"
    )
    return 0


def _sensed_background(args: argparse.Namespace, params: CamoParams, modes: Modes) -> tuple:
    """The background, its label and what the robots sense of it (greys, colours)."""
    image, label = image_from(args)
    if args.sensed and not modes.layout.grid:  # the mode, not a flag: from a file too
        raise UsageError("--sensed names grid cells: it does not go with a layout")
    return image, label, modes.layout.sense(image, params.profile)


def previous_round(folder: str, params: CamoParams, modes: Modes) -> Previous:
    """A round's folder (summary.json and background.png) as the next round compares with it:
    its frame's greys (before noise), each robot's pattern, final state and palette."""
    path = Path(folder)
    summary_path = checked_file(path / "summary.json", "--after's summary", 1 << 31, UsageError)
    try:
        summary = json.loads(summary_path.read_bytes())
    except (ValueError, RecursionError):
        raise UsageError(f"--after {folder}: its summary.json is not JSON") from None
    if not isinstance(summary, dict):
        raise UsageError(f"--after {folder}: its summary.json is not a summary")
    image = load_image(path / "background.png")
    raw, _ = modes.layout.sense(image, params.profile)
    shape = (params.rows, params.cols)
    codes = {modes.descriptor.name_of(k): k for k in modes.descriptor.codes}
    try:
        pattern = np.array([[codes[n] for n in row] for row in summary["patterns"]])
        final = np.array(summary["final"], dtype=np.int64)
        palette = np.array(summary.get("palette", []), dtype=np.int64)
        shown = np.array(summary["display"], dtype=np.int64)
        if pattern.shape != shape or final.shape != shape:
            raise ValueError
    except (KeyError, TypeError, ValueError):
        raise UsageError(
            f"--after {folder}: its summary.json is not of a finished {shape[0]}x{shape[1]} "
            "round with these options"
        ) from None
    grid = GridPalette()
    if modes.palette.colour:  # the colour each robot showed, for the state it keeps
        where = np.all(palette == shown[:, :, None, :], axis=-1).argmax(axis=-1)
        grid = GridPalette(colours=palette, shades=np.stack([where, where], axis=-1))
    elif modes.palette.k:
        grid = GridPalette(greys=palette)
    return Previous(raw, pattern, final, grid)


def cmd_key(args: argparse.Namespace) -> int:
    Path(args.file).parent.mkdir(parents=True, exist_ok=True)
    made = new_key_file(args.file)
    print(f"wrote {args.file} (key {fingerprint(made)}); give it to every process of the run")
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    from camo_core.cli import bench  # numba: only for what simulates

    sizes: tuple[int, ...] = bench.SIZES
    if args.sizes is not None:
        sizes = tuple(integer(s, "--sizes") for s in items(args.sizes, "--sizes"))
        if not sizes or not all(8 <= n <= bench.MAX_SIZE for n in sizes):
            raise UsageError(
                f"--sizes takes grid sides in 8..{bench.MAX_SIZE}, comma-separated "
                f"(got {args.sizes!r})"
            )
    report = bench.run(sizes=sizes, whole=args.whole)
    print(json.dumps(report) if args.json else bench.format_table(report))
    return 0


def add_sim_arguments(sim: Parser) -> Parser:
    """`./camo sim`'s options on `sim` (also the options a sweep's trials take)."""
    add_run_options(sim)
    add_contrast_option(sim)
    sim.add_argument(
        "--sensed",
        action="append",
        default=[],
        metavar="ROW,COL=VALUE[/R,G,B]",
        help="this cell's sensed grey value (and colour) is a real reading (e.g. a bridged "
        "Droplet's, as its run's summary.json says): it replaces the image's and gets no "
        "measurement noise (repeatable)",
    )
    sim.add_argument(
        "--after",
        metavar="DIR",
        default=None,
        help="a later round of a --scope local run: the previous round's folder (its "
        "summary.json and background.png, as ./camo run --continuous writes them); its robots "
        "that saw no change keep what they showed",
    )
    sim.add_params_file_option("camo_sim")
    sim.set_defaults(func=cmd_sim, options_parser=sim)
    return sim


def build_parser() -> Parser:
    parser = Parser(prog="camo", description="camouflage swarm: reference tools")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    add_sim_arguments(sub.add_parser("sim", help="run the centralized reference simulator once"))
    key = sub.add_parser(
        "key",
        help="write a new random run key (0600) for ./camo run --key-file and the processes "
        "that talk to the run",
    )
    key.add_argument("file", help="the key file to create (it must not exist)")
    key.set_defaults(func=cmd_key)
    ben = sub.add_parser("bench", help="benchmarks")
    ben.add_argument("what", choices=["sim"], help="what to benchmark")
    ben.add_argument("--json", action="store_true", help="print one JSON object")
    ben.add_argument(
        "--sizes", default=None, help="grid sides, comma-separated (default 64,256,1024)"
    )
    ben.add_argument(
        "--whole",
        action="store_true",
        help="also time the whole `camo sim` process at 1024x1024 (a 2048x2048 image)",
    )
    ben.set_defaults(func=cmd_bench)
    return parser


def main(argv: list[str] | None = None) -> int:
    def work() -> int:
        args = build_parser().parse_args(argv)
        return args.func(args)

    return reported("camo", work)
