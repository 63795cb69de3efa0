"""`./camo bench ros`: the swarm against a bare rclpy exchange of the same shape, in one run.

The bare exchange (bare_exchange.py) moves the same messages in the same
processes and does nothing else; a packed one publishes them as the swarm packs
them.

Figures: set-up (launch until every robot has voted; bare: until the
processes are matched), steps per second (every robot voting to every robot
done; bare: its steps), and launch to exit. Beside each swarm figure, the same
run with lossy links (`--loss`, default 10% of messages lost) and its ratio to
the loss-free one. Large swarms (128x128 and 256x256 by default) run once each,
with the launcher's default processes, loss-free and with loss and sensor noise
(`--loss`, `--noise`), and add the largest resident set of a worker and of the
whole run. Keys (`--keyed-side`, 64 by default): the step rate of a run without a key,
keyed (the default) and encrypted, alternating, and the ratios to the run without a key.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import cv2

from camo_bringup.bare_exchange import bare_exchange
from camo_bringup.run_config import default_procs
from camo_core.algorithm.backgrounds import SIZE, forest
from camo_core.cli.options import Parser
from camo_core.exceptions import EXIT_USAGE, CamoError
from camo_core.inputs.numeric import integer
from camo_nodes.topics.startup import bench_domain


def swarm_run(
    side: int, procs: int | None, domain: int, out: Path, steps: int | None = None, extra=()
) -> dict:
    """`./camo run` once (paper profile; `steps` consensus + formation steps if given; `extra`
    options; `procs` None: the launcher's default): its timing.json, and launch to exit."""
    length = [] if steps is None else ["--consensus-steps", str(steps - 10)]
    length += list(extra)
    length += [] if procs is None else ["--procs", str(procs)]
    launched = time.monotonic()
    proc = subprocess.run(
        [sys.executable, "-m", "camo_bringup.launcher", "--rows", str(side), "--cols", str(side)]
        + ["--domain-id", str(domain), "--out", str(out), *length],
        capture_output=True,
        text=True,
        timeout=1800,
    )
    wall = time.monotonic() - launched
    if proc.returncode != 0:
        raise RuntimeError(f"camo run {side}x{side} failed: {proc.stderr.strip()[-300:]}")
    timing = json.loads((out / "timing.json").read_text())
    return {
        "setup_s": timing["startup_s"],
        "steps_per_s": timing["steps_per_s"],
        "wall_s": wall,
        "peak_mib": timing.get("peak_mib", {}),
        "deadlines": timing["deadlines"],
    }


def lossy(loss: float, noise: float = 0.0) -> list[str]:
    """The options of a run with lossy links (and sensor noise)."""
    return ["--rho-comm", str(loss)] + (["--rho-meas", str(noise)] if noise else [])


def large_run(side: int, domain: int, out: Path, extra: list[str]) -> dict:
    """One whole run of a large swarm with the launcher's defaults (processes of at most
    ROBOTS_PER_PROCESS robots), on the forest scaled to the grid when the grid outgrows it,
    with `extra` options (loss, noise)."""
    out.mkdir(parents=True, exist_ok=True)
    image = out / f"forest_{side}.png"
    size = max(SIZE, side)
    cv2.imwrite(str(image), cv2.resize(forest(), (size, size), interpolation=cv2.INTER_NEAREST))
    procs = default_procs(side * side)
    row = swarm_run(side, None, domain, out / "run", extra=["--image", str(image), *extra])
    same = equals_sim(out / "run", image, side, extra)
    peaks = ", ".join(f"{k} {v:.0f}" for k, v in row["peak_mib"].get("processes", {}).items())
    print(
        f"{side}x{side} {' '.join(extra) or 'loss-free'}: set-up {row['setup_s']:.1f} s, "
        f"{row['steps_per_s']:.2f} steps/s, launch to exit {row['wall_s']:.1f} s, {procs} "
        f"workers, equal to ./camo sim: {same}; peak MiB per process: {peaks}",
        file=sys.stderr,
    )
    links = " ".join(extra[1::2]) if extra else "0"
    return {"robots": f"{side}x{side}", "procs": procs, "equals_sim": same, "links": links, **row}


def equals_sim(run: Path, image: Path, side: int, extra: list[str] = ()) -> bool:
    """The run's summary says what `./camo sim` on its image (and `extra` options) does, key
    by key (but the time)."""
    sim = run.parent / "sim"
    done = subprocess.run(
        [sys.executable, "-m", "camo_core.cli", "sim", "--image", str(image), *extra]
        + ["--rows", str(side), "--cols", str(side), "--out", str(sim), "--force"],
        capture_output=True,
        text=True,
        timeout=1800,
    )
    if done.returncode != 0:
        raise RuntimeError(f"camo sim {side}x{side} failed: {done.stderr.strip()[-300:]}")
    ran = json.loads((run / "summary.json").read_text())
    expected = json.loads((sim / "summary.json").read_text())
    return all(ran.get(k) == v for k, v in expected.items() if k != "elapsed_s")


def format_large(rows: list[dict]) -> str:
    lines = [
        f"{'robots':>8} {'loss noise':>10} {'workers':>7} {'set-up s':>9} {'steps/s':>8} "
        f"{'launch to exit s':>17} {'peak MiB: a worker / all':>25} {'deadlines':>9} "
        f"{'equals sim':>10}"
    ]
    for r in rows:
        peak = r["peak_mib"]
        memory = f"{peak.get('worker_max', 0):>8.0f} / {peak.get('all', 0):<6.0f}"
        lines.append(
            f"{r['robots']:>8} {r['links']:>10} {r['procs']:>7} {r['setup_s']:>9.1f} "
            f"{r['steps_per_s']:>8.2f} "
            f"{r['wall_s']:>17.1f} {memory:>25} {r['deadlines']:>9} "
            f"{'yes' if r.get('equals_sim') else 'NO':>10}"
        )
    return "\n".join(lines)


def default_steps(side: int) -> int:
    """Steps per rate measurement: runs of about 10 s here, since short runs' rates are noisy."""
    return max(300, 100_000 // side**2)


def compare(
    side: int,
    procs: int,
    domain: int,
    out: Path,
    steps: int | None,
    repeat: int,
    packed: bool = False,
    loss: float = 0.0,
) -> dict:
    """Medians of alternating swarm and bare runs (this shared machine's speed drifts); with
    `packed`, of the packed bare exchange too; with `loss`, of the swarm with lossy links."""
    swarm, bare, packs, losing = [], [], [], []
    bare_steps = steps or 45
    for k in range(repeat):
        swarm.append(swarm_run(side, procs, domain, out / f"{side}_{k}", steps))
        if loss:
            losing.append(
                swarm_run(side, procs, domain, out / f"{side}_{k}_loss", steps, lossy(loss))
            )
        bare.append(bare_exchange(side, bare_steps, procs, domain))
        if packed:
            packs.append(bare_exchange(side, bare_steps, procs, domain, packed=True))
        also = f", packed {packs[-1]['steps_per_s']:.1f}" if packed else ""
        also += f", swarm with loss {losing[-1]['steps_per_s']:.1f}" if loss else ""
        print(
            f"{side}x{side}: swarm {swarm[-1]['steps_per_s']:.1f} steps/s, "
            f"bare {bare[-1]['steps_per_s']:.1f}{also}; launch to exit "
            f"{swarm[-1]['wall_s']:.1f} s, bare {bare[-1]['wall_s']:.1f} s",
            file=sys.stderr,
        )
    row = {"robots": f"{side}x{side}", "procs": procs, "steps": steps or 45, "repeat": repeat}
    for key in ("setup_s", "steps_per_s", "wall_s"):
        row[f"swarm_{key}"] = statistics.median(r[key] for r in swarm)
        row[f"bare_{key}"] = statistics.median(r[key] for r in bare)
        if loss:
            row[f"lossy_{key}"] = statistics.median(r[key] for r in losing)
    row["rate_ratio"] = row["swarm_steps_per_s"] / row["bare_steps_per_s"]
    if loss:
        row["loss"] = loss
        row["loss_ratio"] = row["lossy_steps_per_s"] / row["swarm_steps_per_s"]
    if packed:
        row["packed_steps_per_s"] = statistics.median(r["steps_per_s"] for r in packs)
        row["packed_ratio"] = row["swarm_steps_per_s"] / row["packed_steps_per_s"]
    return row


KEYS = {"no key": ["--no-key"], "keyed": [], "encrypted": ["--encrypt"]}
KEY_TARGETS = {"keyed": 0.95, "encrypted": 0.85}  # step rate against the run without a key


def key_cost(side: int, procs: int, domain: int, out: Path, steps: int, repeat: int) -> dict:
    """Step rates of alternating runs without a key, keyed (the default) and encrypted: the
    medians and their ratios to the run without a key."""
    rates: dict[str, list[float]] = {what: [] for what in KEYS}
    for k in range(repeat):
        for what, options in KEYS.items():
            folder = out / f"{what.replace(' ', '_')}_{k}"
            rates[what].append(
                swarm_run(side, procs, domain, folder, steps, options)["steps_per_s"]
            )
        said = ", ".join(f"{what} {r[-1]:.1f}" for what, r in rates.items())
        print(f"{side}x{side}: steps/s {said}", file=sys.stderr)
    row = {"robots": f"{side}x{side}", "steps": steps}
    row |= {
        f"{what.replace(' ', '_')}_steps_per_s": statistics.median(r) for what, r in rates.items()
    }
    for what in KEY_TARGETS:
        row[f"{what}_ratio"] = row[f"{what}_steps_per_s"] / row["no_key_steps_per_s"]
    return row


def format_keys(row: dict) -> str:
    names = [what.replace(" ", "_") for what in KEYS]
    rates = " / ".join(f"{row[name + '_steps_per_s']:.1f}" for name in names)
    ratios = ", ".join(
        f"{what} {row[f'{what}_ratio']:.2f} (target >= {target})"
        for what, target in KEY_TARGETS.items()
    )
    return (
        f"keys {row['robots']}, {row['steps']} steps: steps/s without a key / keyed / "
        f"encrypted {rates}; ratios {ratios}"
    )


def added_cost(side: int, procs: int, domain: int, out: Path, repeat: int, extra) -> dict:
    """Launch to exit of alternating runs without and with `extra(folder)` options (recording,
    a live view): the medians and their ratio."""
    plain, added = [], []
    for k in range(repeat):
        plain.append(swarm_run(side, procs, domain, out / f"plain_{k}")["wall_s"])
        folder = out / f"added_{k}"
        added.append(swarm_run(side, procs, domain, folder, extra=extra(folder))["wall_s"])
        print(f"{side}x{side}: {plain[-1]:.1f} s, with {added[-1]:.1f} s", file=sys.stderr)
    row = {"robots": f"{side}x{side}", "plain_s": statistics.median(plain)}
    row["added_s"] = statistics.median(added)
    row["ratio"] = row["added_s"] / row["plain_s"]
    return row


def format_table(rows: list[dict]) -> str:
    head = (
        f"{'robots':>8} {'steps':>6} {'set-up s':>17} {'steps/s':>21} {'ratio':>6} "
        f"{'launch to exit s':>18}"
    )
    lines = [f"{'':>15} {'swarm / bare':>17} {'swarm / bare':>21} {'':>6} {'swarm / bare':>18}"]
    lines.insert(0, head)
    for r in rows:
        setup = f"{r['swarm_setup_s']:>8.1f} / {r['bare_setup_s']:<6.1f}"
        rate = f"{r['swarm_steps_per_s']:>9.1f} / {r['bare_steps_per_s']:<9.1f}"
        wall = f"{r['swarm_wall_s']:>8.1f} / {r['bare_wall_s']:<7.1f}"
        lines.append(
            f"{r['robots']:>8} {r['steps']:>6} {setup} {rate} {r['rate_ratio']:>6.2f} {wall}"
        )
    return "\n".join(lines)


def format_loss(rows: list[dict]) -> str:
    """The swarm with lossy links beside the loss-free swarm of the same rows."""
    lines = [
        f"{'robots':>8} {'steps':>6} {'loss':>5} {'steps/s':>21} {'ratio':>6} "
        f"{'launch to exit s':>18}",
        f"{'':>21} {'lossy / loss-free':>21} {'':>6} {'lossy / loss-free':>18}",
    ]
    for r in rows:
        if "loss" not in r:
            continue
        rate = f"{r['lossy_steps_per_s']:>9.1f} / {r['swarm_steps_per_s']:<9.1f}"
        wall = f"{r['lossy_wall_s']:>8.1f} / {r['swarm_wall_s']:<7.1f}"
        lines.append(
            f"{r['robots']:>8} {r['steps']:>6} {r['loss']:>5.2f} {rate} "
            f"{r['loss_ratio']:>6.2f} {wall}"
        )
    return "\n".join(lines)


def grid_sides(text: str) -> list[int]:
    """--sides 16,32,64 (empty or 0: none)."""
    try:
        sides = [integer(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"grid sides are integers, comma-separated: {text!r}"
        ) from None
    if not all(0 <= side <= 256 for side in sides):
        raise argparse.ArgumentTypeError(f"a grid side is in 1..256 (0: none): {text!r}")
    return [side for side in sides if side]


def print_report(args, rates, whole, large, keys, added) -> None:
    """The figures as tables, for people."""
    print(f"medians of {args.repeat} alternating runs, {args.procs} processes")
    if rates:
        print("long runs (step rate):")
        print(format_table(rates))
    for r in rates:
        print(
            f"{r['robots']} against the packed bare exchange: "
            f"{r['packed_steps_per_s']:.1f} steps/s, ratio {r['packed_ratio']:.2f}"
        )
    if whole:
        print("whole runs (35 + 10 steps):")
        print(format_table(whole))
    if args.loss and rates + whole:
        print(f"with {args.loss:.0%} of messages lost (the same runs' loss-free figures):")
        print(format_loss(rates + whole))
    if large:
        print("large swarms (one run each, the launcher's default processes):")
        print(format_large(large))
    if keys is not None:
        print(format_keys(keys))
    targets = {"recording": 1.5, "live view": 1.1}
    for what, r in added.items():
        print(
            f"{what} {r['robots']}: launch to exit {r['plain_s']:.1f} s, with it "
            f"{r['added_s']:.1f} s, ratio {r['ratio']:.2f} (target <= {targets[what]})"
        )


def measure(args: argparse.Namespace, domain: int) -> tuple:
    """Every figure `camo bench ros` prints: rates, whole runs, large runs, keys, extras."""
    rates = [
        compare(
            side,
            args.procs,
            domain,
            args.out / "rate",
            args.steps or default_steps(side),
            args.repeat,
            packed=True,
            loss=args.loss,
        )
        for side in args.rate_sides
    ]
    whole = [
        compare(side, args.procs, domain, args.out / "whole", None, args.repeat, loss=args.loss)
        for side in args.sides
    ]
    links = [[]] + ([lossy(args.loss, args.noise)] if args.loss else [])
    large = [
        large_run(side, domain, args.out / "large" / f"{side}_{k}", extra)
        for side in args.large_sides
        for k, extra in enumerate(links)
    ]
    keys = None
    if args.keyed_side:
        side = args.keyed_side
        steps = args.steps or default_steps(side)
        keys = key_cost(side, args.procs, domain, args.out / "keys", steps, args.repeat)
    # What recording, and a live view with no client connected, add to a run.
    extras = {
        "recording": (args.record_side, "record", lambda out: ["--record", str(out / "bag")]),
        "live view": (args.view_side, "view", lambda out: ["--foxglove", "0"]),
    }
    added = {
        what: added_cost(side, args.procs, domain, args.out / folder, args.repeat, extra)
        for what, (side, folder, extra) in extras.items()
        if side
    }
    return rates, whole, large, keys, added


def main(argv: list[str] | None = None) -> int:
    parser = Parser(prog="camo bench ros", description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument(
        "--rate-sides",
        type=grid_sides,
        default="8",
        help="grid sides of the long-run rate comparison (default 8; 0: none)",
    )
    parser.add_argument(
        "--sides",
        type=grid_sides,
        default="16,32,64",
        help="grid sides of the whole-run comparison (default 16,32,64; 0: none)",
    )
    parser.add_argument(
        "--large-sides",
        type=grid_sides,
        default="128,256",
        help="grid sides of single large runs: set-up, rate, memory (default 128,256; 0: none)",
    )
    parser.add_argument(
        "--record-side", type=int, default=16, help="side of the recording comparison (0: none)"
    )
    parser.add_argument(
        "--view-side", type=int, default=8, help="side of the live-view comparison (0: none)"
    )
    parser.add_argument(
        "--keyed-side",
        type=int,
        default=64,
        help="side of the comparison of runs without a key, keyed and encrypted (0: none)",
    )
    parser.add_argument("--procs", type=int, default=os.cpu_count() or 1)
    parser.add_argument(
        "--loss",
        type=float,
        default=0.1,
        help="message loss of the lossy runs beside each swarm figure (default 0.1; 0: none)",
    )
    parser.add_argument(
        "--noise",
        type=float,
        default=0.05,
        help="sensor noise of the lossy large-swarm runs (default 0.05)",
    )
    parser.add_argument(
        "--steps",
        type=int,
        default=None,
        help="steps per rate run (default 100000 / robots, at least 300)",
    )
    parser.add_argument(
        "--repeat", type=int, default=3, help="runs per figure (median; default 3)"
    )
    parser.add_argument(
        "--out", type=Path, default=Path("results") / time.strftime("bench-ros-%Y%m%d-%H%M%S")
    )
    try:
        args = parser.parse_args(argv)
        if not ((args.steps is None or 20 <= args.steps <= 100_000) and 1 <= args.repeat <= 100):
            parser.error("--steps must be in 20..100000 and --repeat in 1..100")
        sides = (args.record_side, args.view_side, args.keyed_side)
        if not (1 <= args.procs <= 64 and all(0 <= side <= 256 for side in sides)):
            parser.error(
                "--procs must be in 1..64, --record-side, --view-side and --keyed-side in 0..256"
            )
        if not (0 <= args.loss < 1 and 0 <= args.noise <= 1):
            parser.error("--loss must be in [0, 1) and --noise in [0, 1]")
        domain = bench_domain(180, 40)
    except CamoError as exc:
        print(f"camo bench ros: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    try:
        rates, whole, large, keys, added = measure(args, domain)
    except RuntimeError as exc:  # a run that failed or hung: what and why, in one line
        print(f"camo bench ros: error: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps({"rates": rates, "whole": whole, "large": large, "keys": keys, **added}))
    else:
        print_report(args, rates, whole, large, keys, added)
    return 0


if __name__ == "__main__":
    sys.exit(main())
