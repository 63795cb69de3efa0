"""`./camo errors`: the paper's error analysis (its Fig. "errorAnalysis") as a preset sweep.

Three blocks of trials over the error probability rho: measurement errors only
(rho_meas = rho), communication errors only (rho_comm = rho), and both at once (tied axes). The
table is the sweep's (OUT/trials/, resumable with --force); errors.csv and errors.png are drawn
from it: per mode and rho, the mean, spread and percentiles of the cells that differ from the
error-free run, and the rate of trials that chose the error-free run's pattern.
"""

from __future__ import annotations

import csv
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from camo_core.algorithm.modes import modes_of
from camo_core.cli.options import (
    Parser,
    add_contrast_option,
    add_run_options,
    image_from,
    out_dir,
    params_from,
)
from camo_core.exceptions import UsageError, reported
from camo_core.inputs.numeric import items, number
from camo_core.inputs.strict_yaml import dump_yaml
from camo_core.results import figures
from camo_sweep import engines
from camo_sweep.cli import SPEC_FILE, check_folder
from camo_sweep.spec import SweepSpec
from camo_sweep.sweep import plan, run_sweep
from camo_sweep.table import read

MODES = ("measurement", "communication", "both")
CSV_COLUMNS = (
    "mode",
    "rho",
    "trials",
    "mean_diff",
    "std_diff",
    "p10_diff",
    "p90_diff",
    "correct_rate",
    "mean_grey_distance",
    "mean_colour_distance",
)


@dataclass
class ErrorPoint:
    mode: str
    rho: float
    trials: int
    mean_diff: float
    std_diff: float
    p10_diff: float  # the trials' 10th and 90th percentiles: the figure's band
    p90_diff: float
    correct_rate: float
    mean_grey_distance: float  # greys shown against greys sensed (RunResult.grey_distance)
    # Colours shown against colours sensed (RunResult.colour_distance, mean CIEDE2000).
    mean_colour_distance: float

    def as_row(self) -> dict:
        return {k: getattr(self, k) for k in CSV_COLUMNS}


def error_spec(args, rhos: list[float]) -> SweepSpec:
    """The preset: the run options given, three blocks over rho, --trials replicates."""
    if args.layout:
        raise UsageError("./camo errors runs on the grid: --layout is for ./camo sim and run")
    options = {"image": args.image} if args.image else {"pattern": args.pattern or "forest"}
    options |= {"rows": args.rows, "cols": args.cols, "profile": args.profile}
    options["threshold"] = args.threshold
    if args.orientation != "axes":
        options["orientation"] = args.orientation
    if args.levels:
        options["levels"] = args.levels
    if args.colours:
        options["colours"] = args.colours
    for name in ("consensus_steps", "formation_steps", "contrast"):
        if getattr(args, name) is not None:
            options[name] = getattr(args, name)
    blocks = [{"rho_meas": rhos}, {"rho_comm": rhos}, {"rho_meas,rho_comm": rhos}]
    return SweepSpec(blocks=blocks, options=options, trials=args.trials, seed=args.seed)


def points_from(folder: Path, rhos: list[float], spec: SweepSpec) -> list[ErrorPoint]:
    """The points of `spec`'s trials (a folder run with more --trials before holds more)."""
    columns = ["trial_id", "rho_meas", "rho_comm", "diff_cells", "correct", "status"]
    columns += ["grey_distance", "colour_distance"]
    data = read(folder, columns=columns).to_pydict()
    meas, comm = np.array(data["rho_meas"]), np.array(data["rho_comm"])
    ids = {t.trial_id for t in spec.trial_list()}
    pairs = zip(data["status"], data["trial_id"], strict=True)
    ok = np.array([status == "ok" and trial in ids for status, trial in pairs])
    diff = np.array([np.nan if d is None else d for d in data["diff_cells"]], dtype=float)
    correct = np.array([bool(c) for c in data["correct"]])
    grey = np.array([np.nan if g is None else g for g in data["grey_distance"]], dtype=float)
    colour = np.array([np.nan if c is None else c for c in data["colour_distance"]], dtype=float)
    points = []
    for mode in MODES:
        for rho in rhos:
            if mode == "measurement":
                keep = (meas == rho) & (comm == 0)
            elif mode == "communication":
                keep = (meas == 0) & (comm == rho)
            else:
                keep = (meas == rho) & (comm == rho)
            keep &= ok
            if not keep.any():
                continue
            values = np.sort(diff[keep])  # one order, whatever order the parts hold
            points.append(
                ErrorPoint(
                    mode,
                    rho,
                    int(keep.sum()),
                    float(np.mean(values)),
                    float(np.std(values)),
                    float(np.percentile(values, 10)),
                    float(np.percentile(values, 90)),
                    float(np.mean(correct[keep])),
                    float(np.mean(grey[keep])),
                    float(np.mean(colour[keep])),
                )
            )
    return points


def write_csv(points: list[ErrorPoint], path: Path) -> None:
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=CSV_COLUMNS)
        writer.writeheader()
        for point in points:
            writer.writerow(point.as_row())


def parse_rhos(text: str) -> list[float]:
    """'0,0.05,0.1' -> floats; each must be a probability."""
    try:
        values = [number(part) for part in items(text, "--rhos")]
    except ValueError:
        raise UsageError(f"--rhos must be comma-separated numbers (got {text!r})") from None
    if not values or any(not math.isfinite(v) or not 0.0 <= v <= 1.0 for v in values):
        raise UsageError(f"--rhos must be probabilities in [0, 1] (got {text!r})")
    return sorted(set(values))


def build_parser() -> Parser:
    parser = Parser(
        prog="camo errors",
        description="the paper's error analysis, as a sweep: errors.csv, errors.png and the "
        "sweep's table (trials/) in --out",
    )
    add_run_options(parser)
    add_contrast_option(parser)
    parser.add_argument("--trials", type=int, default=10, help="trials per point (default 10)")
    parser.add_argument(
        "--rhos",
        default=",".join(f"{x / 100:g}" for x in range(0, 51, 5)),
        help="comma-separated error probabilities (default 0,0.05,...,0.5)",
    )
    parser.add_argument(
        "--workers",
        type=int,
        default=1,
        help="local Dask worker processes (default 1: in this process; the paper's 310 trials "
        "take under a second)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    return parser


def main(argv: list[str] | None = None) -> int:
    return reported("camo errors", lambda: run(argv))


def run(argv: list[str] | None) -> int:
    args = build_parser().parse_args(argv)
    params = params_from(args)  # bad values fail here, in one line
    if args.trials < 1 or args.trials > 10_000:
        raise UsageError(f"--trials must be an integer in 1..10000 (got {args.trials})")
    engines.check_local_workers(args.workers)
    rhos = parse_rhos(args.rhos)
    _, label = image_from(args)  # an unreadable image fails here
    if args.rho_meas or args.rho_comm:
        raise UsageError("errors sweeps the error probabilities itself: give them as --rhos")
    spec = error_spec(args, rhos)
    folder = out_dir(args)  # a folder that holds something only with --force
    check_folder(folder, spec)  # and then this analysis again, not another
    work = plan(spec, folder)  # as ./camo sweep: what cannot run fails before anything is written
    (folder / SPEC_FILE).write_text(dump_yaml(spec.as_dict()))
    engine = engines.InProcess() if args.workers == 1 else engines.local_engine(args.workers)
    try:
        if isinstance(engine, engines.DaskEngine):
            engine.warm()
        run_sweep(spec, folder, engine, progress=not args.quiet, planned=work)
    finally:
        engine.close()
    points = points_from(folder, rhos, spec)
    write_csv(points, folder / "errors.csv")
    figures.errors_figure(
        [p.as_row() for p in points],
        params.count / 2,
        folder / "errors.png",
        title=f"{label}, {params.rows}x{params.cols} robots, {args.trials} trials per point",
        cells=params.count,
        colours=modes_of(params).sensing.colour,
    )
    print(f"wrote {folder}/errors.csv, errors.png and the trials' table trials/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
