"""`./camo bench sweep`: trials per second of 8x8 simulator trials as a plain loop in one
process, against the same trials through the sweep (its table, batches and engine) in this
process and on a LocalCluster of 2 workers, measured in one run.

Targets: 2 workers at least 1.7x the plain loop, 1 worker within 10% of it (the sweep's
trial phase: from the first task handed out to the last part written; the cluster's start and
the workers' kernel warm-up are printed apart).
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from camo_core.cli.options import Parser
from camo_core.exceptions import EXIT_USAGE, CamoError, UsageError
from camo_sweep import engines
from camo_sweep.spec import SweepSpec
from camo_sweep.sweep import run_sweep
from camo_sweep.trials import reference_of, simulate_options


def the_spec(trials: int) -> SweepSpec:
    rhos = [round(0.05 * k, 2) for k in range(11)]
    per_point = max(1, trials // len(rhos))
    return SweepSpec(blocks=[{"rho_comm": rhos}], options={"pattern": "forest"}, trials=per_point)


def plain_loop(spec: SweepSpec) -> float:
    """The trials with nothing around them: simulate, compare with the reference, keep."""
    trials = spec.trial_list()
    reference = reference_of(trials[0].options)
    kept = []
    start = time.perf_counter()
    for trial in trials:
        result = simulate_options(trial.options, trial.seed)
        diff = int(np.count_nonzero(result.final != reference.final))
        kept.append((trial.trial_id, result.majority_pattern == reference.pattern, diff))
    return time.perf_counter() - start


def through_sweep(spec: SweepSpec, workers: int) -> dict:
    with tempfile.TemporaryDirectory(prefix="camo-bench-sweep-") as folder:
        start = time.perf_counter()
        engine = engines.InProcess() if workers == 1 else engines.local_engine(workers)
        try:
            if isinstance(engine, engines.DaskEngine):
                engine.warm()
            ready = time.perf_counter() - start
            report = run_sweep(spec, Path(folder), engine, progress=False)
        finally:
            engine.close()
        whole = time.perf_counter() - start
    return {"trials_s": report.seconds, "start_s": ready, "whole_s": whole, "ran": report.ran}


def run(trials: int) -> dict:
    spec = the_spec(trials)
    count = spec.count()
    reference_of(spec.trial_list()[0].options)  # compile the kernels before any timing
    loop = plain_loop(spec)
    one = through_sweep(spec, 1)
    two = through_sweep(spec, 2)
    assert one["ran"] == two["ran"] == count
    report = {
        "trials": count,
        "plain_loop": {"seconds": loop, "trials_per_s": count / loop},
        "sweep_1_worker": {**one, "trials_per_s": count / one["trials_s"]},
        "sweep_2_workers": {**two, "trials_per_s": count / two["trials_s"]},
    }
    report["ratio_1_worker"] = loop / one["trials_s"]
    report["ratio_2_workers"] = loop / two["trials_s"]
    report["overhead_per_trial_ms"] = (one["trials_s"] - loop) / count * 1e3
    return report


def format_table(report: dict) -> str:
    loop, one, two = report["plain_loop"], report["sweep_1_worker"], report["sweep_2_workers"]
    lines = [
        f"{report['trials']} trials of 8x8 (forest, rho_comm 0..0.5)",
        f"plain loop, one process      {loop['trials_per_s']:8.0f} trials/s",
        f"sweep, 1 worker (in-process) {one['trials_per_s']:8.0f} trials/s  "
        f"ratio {report['ratio_1_worker']:.2f} (target >= 0.90)",
        f"sweep, 2 local workers       {two['trials_per_s']:8.0f} trials/s  "
        f"ratio {report['ratio_2_workers']:.2f} (target >= 1.70); cluster start and warm-up "
        f"{two['start_s']:.1f} s, whole {two['whole_s']:.1f} s",
        f"sweep overhead per trial     {report['overhead_per_trial_ms']:8.3f} ms",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = Parser(prog="camo bench sweep")  # type=int by camo_core.inputs' grammar
    parser.add_argument("--trials", type=int, default=20000, help="trials in all (default 20000)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    try:
        args = parser.parse_args(argv)
        if not 11 <= args.trials <= 10_000_000:
            raise UsageError(f"--trials must be in 11..10000000 (got {args.trials})")
        engines.worker_environment()  # the loop and the in-process sweep run on one thread too
        report = run(args.trials)
    except CamoError as exc:
        print(f"camo bench sweep: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    print(json.dumps(report) if args.json else format_table(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
