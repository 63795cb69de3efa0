"""`./camo sweep [SWEEP.yaml] --out DIR [--axis NAME=VALUES ...]` and `./camo sweep plot DIR`."""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

from camo_core.cli.options import Combination, Parser, a_path
from camo_core.exceptions import CamoError, UsageError, reported
from camo_core.inputs.numeric import integer
from camo_core.inputs.strict_yaml import dump_yaml, read_yaml
from camo_sweep import engines
from camo_sweep.spec import (
    DRIVERS,
    MAX_FILE_BYTES,
    MAX_TRIALS,
    SweepSpec,
    build_spec,
    spec_from_yaml,
)
from camo_sweep.sweep import plan, run_sweep

SPEC_FILE = "sweep.yaml"


SLURM_FLAGS = {
    "queue": "partition",
    "account": "account",
    "cores": "cores per job: one worker process each",
    "memory": "memory per job, e.g. 8GB",
    "walltime": "time limit per job, e.g. 02:00:00",
    "max-jobs": "jobs at most",
}


def build_parser() -> Parser:
    parser = Parser(
        prog="camo sweep",
        description="trials of ./camo sim (or of the swarm) over the product of axes, into a "
        "resumable Parquet table DIR/trials/; `./camo sweep plot DIR --x AXIS` draws it",
    )
    parser.add_argument("file", nargs="?", type=a_path, help="SWEEP.yaml (docs/sweeps.md)")
    parser.add_argument("--out", type=a_path, help="the sweep's folder (resumable); required")
    parser.add_argument(
        "--axis",
        action="append",
        default=[],
        metavar="NAME=VALUES",
        help="an axis over a ./camo sim option: FROM:TO:STEP, a,b,c; tied options share "
        "values: rho_meas,rho_comm=0:0.5:0.1 (repeatable)",
    )
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a fixed ./camo sim option of every trial, e.g. rows=16 (repeatable)",
    )
    parser.add_argument("--trials", type=int, default=None, help="replicates per point (1)")
    parser.add_argument("--seed", type=int, default=None, help="the root seed (default 0)")
    parser.add_argument("--driver", choices=DRIVERS, default=None, help="sim (default) or ros")
    engine = parser.add_mutually_exclusive_group()
    engine.add_argument(
        "--workers",
        type=int,
        default=None,
        help="local Dask worker processes (default: one per core); 1: in this process, no Dask",
    )
    engine.add_argument(
        "--scheduler", metavar="tcp://HOST:PORT", help="submit to this Dask scheduler"
    )
    engine.add_argument(
        "--slurm", action="store_true", help="Dask workers in SLURM jobs (dask-jobqueue)"
    )
    for key, what in SLURM_FLAGS.items():
        parser.add_argument(f"--slurm-{key}", default=None, help=f"SLURM {what}")
    parser.add_argument(
        "--print-job-script",
        action="store_true",
        help="with --slurm: print the job script and submit nothing",
    )
    parser.add_argument(
        "--ros-per-worker",
        type=int,
        default=1,
        help="--driver ros: swarms a local worker runs at once (default 1)",
    )
    parser.add_argument(
        "--ros-timeout", type=float, default=300.0, help="--driver ros: seconds a swarm may take"
    )
    parser.add_argument(
        "--batch-s", type=float, default=0.25, help="seconds of simulator trials per task"
    )
    parser.add_argument(
        "--max-trials",
        type=int,
        default=MAX_TRIALS,
        help=f"refuse a sweep of more trials than this (default and at most {MAX_TRIALS:,}: "
        "a sweep lists its trials in memory before it starts)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.combine(
        *(
            Combination(flag, needs=("--slurm",), why="a setting of SLURM jobs")
            for flag in ("--print-job-script", *(f"--slurm-{k}" for k in SLURM_FLAGS))
        )
    )
    return parser


def slurm_settings(args, given: dict) -> dict:
    """The SLURM settings: a sweep file's `slurm:` section, then the --slurm-* options."""
    settings = dict(given)
    for key in engines.SLURM_KEYS:
        value = getattr(args, f"slurm_{key}")
        if value is not None:
            settings[key] = (
                integer(value, f"--slurm-{key.replace('_', '-')}, a whole number")
                if key in ("cores", "max_jobs")
                else value
            )
    return settings


def check_folder(folder: Path, spec: SweepSpec) -> SweepSpec | None:
    """A folder holds one sweep: refuse another sweep's folder, or one that is not a sweep's;
    the sweep it holds, if any."""
    if not folder.exists() or (folder.is_dir() and not any(folder.iterdir())):
        return None
    saved = folder / SPEC_FILE
    if not saved.is_file():
        raise UsageError(f"{folder} exists and holds no {SPEC_FILE}: it is not a sweep's folder")
    try:
        before = SweepSpec(**read_yaml(saved, "sweep's spec", MAX_FILE_BYTES))
    except (TypeError, CamoError):
        raise UsageError(f"{saved} is damaged; give another --out") from None
    if not spec.same_sweep(before):
        raise UsageError(
            f"{folder} holds another sweep (see {saved}); give another --out "
            "(only --trials may change between runs of one sweep)"
        )
    return before


def check_numbers(args) -> None:
    """The options that are numbers, each in its range (one line if not)."""
    if args.ros_per_worker < 1:
        raise UsageError(f"--ros-per-worker must be at least 1 (got {args.ros_per_worker})")
    if not 1 <= args.max_trials <= MAX_TRIALS:
        raise UsageError(f"--max-trials must be in 1..{MAX_TRIALS} (got {args.max_trials})")
    for name in ("ros_timeout", "batch_s"):
        value = getattr(args, name)
        if not (math.isfinite(value) and 0 < value <= 86400):
            flag = "--" + name.replace("_", "-")
            raise UsageError(f"{flag} must be a number of seconds in (0, 86400] (got {value})")


def said_of(work) -> str:
    """What a sweep is about to do, said before it starts."""
    done = work.total - len(work.todo)
    table = f" ({done:,} in the table already)" if done else ""
    return f"{work.total:,} trials{table}, {len(work.todo):,} to run"


def make_engine(args, spec: SweepSpec):
    if args.scheduler:
        return engines.remote_engine(args.scheduler)
    if args.slurm:
        return engines.slurm_engine(slurm_settings(args, spec.slurm))
    workers = (os.cpu_count() or 1) if args.workers is None else args.workers
    engines.check_local_workers(workers)
    if workers == 1:
        return engines.InProcess()
    return engines.local_engine(workers, args.ros_per_worker)


LISTED_SLOWLY = 100_000  # trials: listing this many (and the table's) takes seconds or more


ROS_ONLY = ("--ros-per-worker", "--ros-timeout")


def check_driver_options(parser: Parser, args, driver: str) -> None:
    """The ros driver's options, in a sweep of the simulator: given by mistake (without
    --driver ros), they would change nothing and say nothing."""
    given = [flag for flag in ROS_ONLY if parser.given(args, flag)]
    if given and driver != "ros":
        verb = "is" if len(given) == 1 else "are"
        raise UsageError(
            f"{' and '.join(given)} {verb} for --driver ros (this sweep's driver is {driver})"
        )


def cmd_sweep(argv: list[str]) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    check_numbers(args)
    data = spec_from_yaml(args.file) if args.file else None
    if args.print_job_script:
        cluster = engines.slurm_cluster(slurm_settings(args, (data or {}).get("slurm", {})))
        try:
            print(cluster.job_script())
        finally:
            cluster.close()
        return 0
    if args.out is None:
        raise UsageError("the following arguments are required: --out")
    spec = build_spec(data, args.axis, args.set, args.trials, args.seed, args.driver)
    check_driver_options(parser, args, spec.driver)
    spec.refuse_more_than(args.max_trials, "--max-trials")
    if spec.count() >= LISTED_SLOWLY and not args.quiet:  # listing 10^7 trials takes minutes
        print(f"camo sweep: listing {spec.count():,} trials before it starts", file=sys.stderr)
    before = check_folder(args.out, spec)
    work = plan(spec, args.out)  # options that cannot run fail here, before any write
    engine = make_engine(args, spec)  # and an unreachable scheduler here
    try:
        if spec.driver == "ros" and isinstance(engine, engines.DaskEngine):
            if engine.ros_slots() < 1:
                raise UsageError(
                    f"no worker of {engine.name} offers the 'ros' resource: start workers with "
                    "--resources ros=1"
                )
        if not args.quiet:  # once nothing is left to refuse: an error stays one line
            print(f"camo sweep: {said_of(work)}", file=sys.stderr)
        args.out.mkdir(parents=True, exist_ok=True)
        # The most replicates any run of this sweep asked for: what the table may hold.
        kept = spec.with_trials(max(spec.trials, before.trials if before else 0))
        (args.out / SPEC_FILE).write_text(dump_yaml(kept.as_dict()))
        if isinstance(engine, engines.DaskEngine):
            if engine.client.dashboard_link and not args.quiet:
                print(
                    f"camo sweep: Dask dashboard {engine.client.dashboard_link}", file=sys.stderr
                )
            engine.warm()
        report = run_sweep(
            spec,
            args.out,
            engine,
            args.batch_s,
            args.ros_timeout,
            progress=not args.quiet,
            planned=work,
        )
    except engines.lost_cluster() as exc:
        print(
            f"camo sweep: error: lost the Dask cluster ({type(exc).__name__}); every finished "
            f"trial is in {args.out}/trials/: the same command goes on from there",
            file=sys.stderr,
        )
        return 1
    except KeyboardInterrupt:
        print(
            f"camo sweep: interrupted; every finished trial is in {args.out}/trials/: "
            "the same command goes on from there",
            file=sys.stderr,
        )
        return 130
    finally:
        engine.close()
    rate = f", {report.ran / report.seconds:.0f} trials/s" if report.seconds > 0 else ""
    print(
        f"sweep: {report.total} trials, {report.skipped} already in the table, {report.ran} run "
        f"({report.failed} failed){rate} on {engine.name}; table {args.out}/trials/"
    )
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["plot"]:
        from camo_sweep.plot import cmd_plot

        return reported("camo sweep", lambda: cmd_plot(argv[1:]))
    return reported("camo sweep", lambda: cmd_sweep(argv))


if __name__ == "__main__":
    sys.exit(main())
