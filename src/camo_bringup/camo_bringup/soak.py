"""`./camo bench soak --runs N`: N small runs one after another in one domain, and what they leave.

After each run it looks for what a run must not leave behind: camo processes
still running, Fast DDS shared-memory files of dead processes, entries of /dev/shm
(Fast DDS's, Python multiprocessing's) that pile up from one run to the next (each run's
processes remove what earlier ones left, `camo_core.shm`: after the last run the count is
the first run's), and a
result that differs from the first run's (same parameters, same seed: a
leftover in the domain would show here). Over the runs it compares the last
tenth with the first: the peak memory of a run's processes, the machine's available
memory, and launch-to-exit time. Exit code 1 if anything leaked.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

from camo_core.cli.options import Parser
from camo_core.exceptions import EXIT_USAGE, CamoError
from camo_core.shm import ORPHAN_PREFIXES, SHM, stale_files
from camo_core.shutdown import interrupt_on_signals
from camo_nodes.topics.startup import bench_domain

MODULES = ("camo_nodes.", "camo_projector.", "camo_bag.", "camo_droplet.")
RESULT_KEYS = ("pattern", "votes", "mean_p", "final")


def camo_processes(exclude: set[int], domain: int | None = None) -> dict[int, str]:
    """Running camo processes (python -m camo_...), but those in `exclude`, and with `domain`
    only those in that ROS domain (camo's other runs on this machine are not the soak's):
    pid -> command."""
    found = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit() or int(entry) in exclude:
            continue
        try:
            argv = Path(f"/proc/{entry}/cmdline").read_bytes().split(b"\0")
            status = Path(f"/proc/{entry}/status").read_text()
            environ = Path(f"/proc/{entry}/environ").read_bytes().split(b"\0")
        except OSError:
            continue
        if domain is not None and f"ROS_DOMAIN_ID={domain}".encode() not in environ:
            continue
        words = [a.decode(errors="replace") for a in argv if a]
        if "State:\tZ" in status:
            continue
        if any(os.path.basename(w).startswith(MODULES) for w in words[1:3]):  # -m camo_...
            found[int(entry)] = " ".join(words[:4])
    return found


def available_mib() -> float:
    for line in Path("/proc/meminfo").read_text().splitlines():
        if line.startswith("MemAvailable:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def one_run(index: int, args: argparse.Namespace, domain: int) -> dict:
    """One `./camo run`: its exit code, launch-to-exit time, and the peak RSS of its largest
    process (wait4 reports the most of the launcher and the processes it waited for)."""
    out = args.out / f"run_{index:03d}"
    out.mkdir(parents=True, exist_ok=True)
    command = [sys.executable, "-m", "camo_bringup.launcher", "--rows", str(args.side)]
    command += ["--cols", str(args.side), "--procs", str(args.procs), "--seed", "1"]
    command += ["--consensus-steps", str(args.steps), "--domain-id", str(domain)]
    command += ["--out", str(out / "result")]
    started = time.monotonic()
    with open(out / "stderr.txt", "w") as errors:
        env = {**os.environ, "ROS_DOMAIN_ID": str(domain)}  # marks the run's processes
        proc = subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL, stderr=errors)
        _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    summary = out / "result" / "summary.json"
    result = None
    if summary.exists():
        data = json.loads(summary.read_text())
        result = {key: data.get(key) for key in RESULT_KEYS}
    said = (out / "stderr.txt").read_text()
    return {
        "exit": proc.returncode,
        "killed_at_stop": said.count("did not stop within"),
        "wall_s": time.monotonic() - started,
        "peak_mib": usage.ru_maxrss / 1024,
        "result": result,
    }


def shm_entries() -> int:
    """/dev/shm's entries of the kinds camo's processes make (Fast DDS's, multiprocessing's)."""
    try:
        return sum(1 for name in os.listdir(SHM) if name.startswith(ORPHAN_PREFIXES))
    except OSError:
        return 0


def tenth(values: list[float], last: bool) -> float:
    k = max(1, len(values) // 10)
    return statistics.median(values[-k:] if last else values[:k])


def soak(args: argparse.Namespace) -> dict:
    before = {os.getpid()}
    stale_before = {p.name for p in stale_files()}
    entries_before = shm_entries()
    entries: list[int] = []  # after each run: what it left (the next camo process removes it)
    domain = args.domain
    available = [available_mib()]
    runs, leaked, stale_new, differing = [], {}, set(), []
    for index in range(args.runs):
        run = one_run(index, args, domain)
        time.sleep(args.settle)
        for pid, command in camo_processes(exclude=before, domain=domain).items():
            leaked[pid] = command
            try:
                os.kill(pid, signal.SIGKILL)  # so that the next run does not meet it
            except OSError:
                pass
        stale_new |= {p.name for p in stale_files()} - stale_before
        entries.append(shm_entries())
        if runs and run["result"] != runs[0]["result"]:
            differing.append(index)
        runs.append(run)
        available.append(available_mib())
        print(
            f"soak {index + 1}/{args.runs}: exit {run['exit']}, {run['wall_s']:.1f} s, "
            f"peak {run['peak_mib']:.0f} MiB; leaked processes {len(leaked)}, "
            f"stale shm files {len(stale_new)}, /dev/shm entries {entries[-1]}",
            file=sys.stderr,
        )
    walls = [r["wall_s"] for r in runs]
    peaks = [r["peak_mib"] for r in runs]
    return {
        "runs": args.runs,
        "robots": f"{args.side}x{args.side}",
        "procs": args.procs,
        "failed_runs": [k for k, r in enumerate(runs) if r["exit"] != 0],
        "results_differing_from_the_first": differing,
        "leaked_processes": sorted(leaked.values()),
        "killed_at_stop": sum(r["killed_at_stop"] for r in runs),
        "stale_shm_files": sorted(stale_new),
        "shm_entries_before": entries_before,
        "shm_entries_per_run": entries,
        # What the runs leave piles up if the last tenth's count is above the first tenth's (a
        # run leaves a few files of its own, removed by the next: the count varies by a few).
        "shm_entries_gained": tenth(entries, True) - tenth(entries, False),
        "peak_mib_first_last": [tenth(peaks, False), tenth(peaks, True)],
        "peak_ratio": tenth(peaks, True) / tenth(peaks, False),
        "wall_s_first_last": [tenth(walls, False), tenth(walls, True)],
        "wall_ratio": tenth(walls, True) / tenth(walls, False),
        "available_mib_change": available[-1] - available[0],
    }


def format_report(report: dict) -> str:
    first, last = report["peak_mib_first_last"]
    wall_first, wall_last = report["wall_s_first_last"]
    return "\n".join(
        [
            f"{report['runs']} runs of {report['robots']} robots in {report['procs']} processes",
            f"  failed runs:                    {len(report['failed_runs'])}",
            f"  results unlike the first run's: {len(report['results_differing_from_the_first'])}",
            f"  leaked processes:               {len(report['leaked_processes'])}",
            f"  processes killed at the end:    {report['killed_at_stop']}",
            f"  stale shared-memory files:      {len(report['stale_shm_files'])}",
            f"  /dev/shm entries before / after the first / after the last run: "
            f"{report['shm_entries_before']} / {report['shm_entries_per_run'][0]} / "
            f"{report['shm_entries_per_run'][-1]}",
            f"  /dev/shm entries gained, first to last tenth of the runs: "
            f"{report['shm_entries_gained']:g}",
            f"  peak memory of a process, first/last tenth: {first:.0f} / {last:.0f} MiB "
            f"(ratio {report['peak_ratio']:.2f})",
            f"  launch to exit, first/last tenth:           {wall_first:.1f} / {wall_last:.1f} s "
            f"(ratio {report['wall_ratio']:.2f})",
            f"  machine's available memory change:      {report['available_mib_change']:+.0f} MiB",
        ]
    )


def main(argv: list[str] | None = None) -> int:
    parser = Parser(prog="camo bench soak", description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=50, help="consecutive runs (default 50)")
    parser.add_argument("--side", type=int, default=4, help="grid side of each run (default 4)")
    parser.add_argument("--procs", type=int, default=2, help="worker processes (default 2)")
    parser.add_argument("--steps", type=int, default=200, help="consensus steps (default 200)")
    parser.add_argument(
        "--settle", type=float, default=0.5, help="seconds between a run and its check"
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument(
        "--out", type=Path, default=Path("results") / time.strftime("soak-%Y%m%d-%H%M%S")
    )
    try:
        args = parser.parse_args(argv)
        if not (1 <= args.runs <= 10_000 and 1 <= args.side <= 64 and 1 <= args.procs <= 64):
            parser.error("--runs must be in 1..10000, --side in 1..64 and --procs in 1..64")
        if not (10 <= args.steps <= 100_000 and 0 <= args.settle <= 60):
            parser.error("--steps must be in 10..100000 and --settle in 0..60")
        args.domain = bench_domain(150, 30)
    except CamoError as exc:
        print(f"camo bench soak: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    interrupt_on_signals()
    try:
        report = soak(args)
    except KeyboardInterrupt:
        print("camo bench soak: interrupted", file=sys.stderr)
        return 130
    (args.out / "soak.json").write_text(json.dumps(report, indent=1))
    print(json.dumps(report) if args.json else format_report(report))
    clean = not (
        report["leaked_processes"]
        or report["stale_shm_files"]
        or report["shm_entries_gained"] > 0
        or report["failed_runs"]
        or report["results_differing_from_the_first"]
        or report["killed_at_stop"]
    )
    return 0 if clean else 1


if __name__ == "__main__":
    sys.exit(main())
