"""`./camo bench ros`: the swarm against a bare rclpy exchange of the same shape, in one run.

The bare exchange moves the same messages and does nothing else: the same
processes, each hosting a contiguous block of robot ids; per block the same
tile topics (edge and core); each process subscribes to the edge topics of the
blocks that hold its robots' neighbours and hands the rest over in memory.
Each step every robot publishes a `camo_msgs/Vote` as a DDS message of its own
(the exchange the swarm's targets are set against), and a process moves on
once every remote vote of that step that its robots need has arrived. No robot
nodes, no protocol, no statuses, no monitor. The swarm packs its messages
(`transport.py`); so the long-run rate is also measured against a *packed*
bare exchange, whose processes publish each step one `camo_msgs/Votes` per
tile topic, packed as the swarm packs them, as the swarm's do at best.

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
import contextlib
import json
import os
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

import cv2
import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.signals import SignalHandlerOptions

from camo_bringup.run_config import default_procs, split_cells
from camo_core.algorithm.backgrounds import SIZE, forest
from camo_core.algorithm.grid import neighbor_ids
from camo_core.algorithm.params import CamoParams
from camo_core.cli.options import Parser
from camo_core.exceptions import EXIT_USAGE, CamoError
from camo_core.inputs.numeric import integer
from camo_core.swarm.robot_io import Message
from camo_msgs.msg import Vote, Votes
from camo_nodes.topics.names import RunTopics, tile_name
from camo_nodes.topics.qos import history_qos
from camo_nodes.topics.robot_messages import Columns
from camo_nodes.topics.startup import LEAN_NODE, bench_domain, start_ros
from camo_nodes.transport import edge_of, listener_qos

BARE_RUN = "bench_bare"
PACKED_RUN = "bench_packed"
# s a bare process waits for its peers, set-up to last step, before it gives up; its parent
# waits that and as long again for set-up and exit, then has its stacks written and kills it.
BARE_BUDGET = 300


def bare_worker(
    side: int, steps: int, block: int, procs: int, packed: int = 0, budget: int = BARE_BUDGET
) -> dict:
    """One process of the bare exchange (block `block` of `procs`; `packed`: one Votes per
    topic and step; `budget`: seconds it waits for its peers); its timings."""
    started = time.monotonic()
    params = CamoParams(rows=side, cols=side, consensus_steps=steps)
    blocks = split_cells(list(range(side * side)), procs)
    mine = blocks[block]
    hosted = set(mine)
    first, last = mine[0], mine[-1]
    edge = edge_of(params, hosted, mine)
    needed = {
        n
        for r in mine
        for n in neighbor_ids(*divmod(r, side), side, side)[:8]
        if n is not None and n not in hosted
    }
    topics = RunTopics(PACKED_RUN if packed else BARE_RUN)
    wire = Votes if packed else Vote
    start_ros("camo bench ros", [], signal_handler_options=SignalHandlerOptions.NO)  # same footing
    node = rclpy.create_node(f"bare_{block}", **LEAN_NODE)
    qos = history_qos(len(mine) * (steps + 4))
    name = tile_name(first, last)
    writers = {
        part: node.create_publisher(wire, topics.tile(name, part, "vote"), qos)
        for part in ("edge", "core")
    }
    got: dict[int, int] = {}  # step -> remote votes of it received

    def on_vote(msg: Vote) -> None:
        if msg.sender_id in needed:
            got[msg.step] = got.get(msg.step, 0) + 1

    def on_votes(msg: Votes) -> None:
        for sender, step in zip(msg.sender_id.tolist(), msg.step.tolist(), strict=True):
            if sender in needed:
                got[step] = got.get(step, 0) + 1

    peers = [b for b in blocks if b is not mine and any(n in b for n in needed)]
    for peer in peers:
        topic = topics.tile(tile_name(peer[0], peer[-1]), "edge", "vote")
        node.create_subscription(wire, topic, on_votes if packed else on_vote, listener_qos())
    executor = EventsExecutor()
    executor.add_node(node)
    deadline = time.monotonic() + budget
    while time.monotonic() < deadline and (
        writers["edge"].get_subscription_count() < len(peers)
        or sum(s.get_publisher_count() for s in node.subscriptions) < len(peers)
    ):
        executor.spin_once(timeout_sec=0.05)
    matched = time.monotonic()
    vote = Vote(p=[0.2, 0.3, 0.5], degree=8)
    parts = {"edge": [r for r in mine if r in edge], "core": [r for r in mine if r not in edge]}
    columns = {part: Columns("vote") for part in parts}
    local = {}
    for step in range(steps):
        vote.step = step
        for part, robots in parts.items():
            for robot in robots:
                local[robot] = step  # the in-memory hand-over to this process's robots
                if packed:
                    columns[part].add(Message("vote", robot, 0, step, ((0.2, 0.3, 0.5), 8)))
                else:
                    vote.sender_id = robot
                    writers[part].publish(vote)
            if packed and robots:
                writers[part].publish(columns[part].take())
        while got.get(step, 0) < len(needed) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
    done = time.monotonic()
    linger = time.monotonic() + 2  # serve our history to slower peers a little longer
    while time.monotonic() < linger:
        executor.spin_once(timeout_sec=0.05)
    # Executor first, then the node (as the swarm's hosts do): the EventsExecutor must let go
    # of the node's handles before they are destroyed.
    executor.shutdown()
    executor.remove_node(node)
    node.destroy_node()
    rclpy.shutdown()
    return {"started": started, "matched": matched, "done": done, "complete": done < deadline}


def worker_reports(workers: list[subprocess.Popen], what: str, limit: float) -> list[dict]:
    """The last line of each worker's output, as JSON, once all have ended. A worker that
    fails ends them all at once (its peers would wait for it for their whole budget); one that
    has not ended within `limit` s has its threads' stacks written to stderr (SIGUSR1,
    camo_core.shutdown) and is killed, with the others: either is one line, and no process is
    left behind. (Each says one short line: its pipe never fills while it is polled.)"""
    end = time.monotonic() + limit
    try:
        while None in [w.poll() for w in workers]:  # each polled: its returncode is set
            failed = [k for k, w in enumerate(workers) if w.returncode not in (None, 0)]
            if failed:
                code = workers[failed[0]].returncode
                raise RuntimeError(f"{what}: process {failed[0]} failed (exit code {code})")
            if time.monotonic() > end:
                hung = next(k for k, w in enumerate(workers) if w.returncode is None)
                raise RuntimeError(
                    f"{what}: process {hung} did not end in {limit:g} s (its threads' stacks "
                    "are on stderr)"
                )
            time.sleep(0.05)
        reports = []
        for k, worker in enumerate(workers):
            lines = (worker.communicate()[0] or "").strip().splitlines()
            if worker.returncode != 0 or not lines:
                raise RuntimeError(f"{what}: process {k} failed (exit code {worker.returncode})")
            reports.append(json.loads(lines[-1]))
    except RuntimeError:
        _end_all(workers)
        raise
    return reports


def _end_all(workers: list[subprocess.Popen]) -> None:
    alive = [w for w in workers if w.poll() is None]
    for how in (signal.SIGUSR1, signal.SIGKILL):
        for worker in alive:
            with contextlib.suppress(ProcessLookupError):
                worker.send_signal(how)
        if how == signal.SIGUSR1 and alive:
            time.sleep(1.0)  # the stacks are written
    for worker in workers:
        worker.communicate()


def bare_exchange(
    side: int, steps: int, procs: int, domain: int, packed: bool = False, budget: int = BARE_BUDGET
) -> dict:
    """The bare exchange in `procs` processes: set-up, steps per second, launch to exit
    (`budget`: the seconds each waits for its peers; twice that, and they are ended)."""
    env = {
        **os.environ,
        "ROS_DOMAIN_ID": str(domain),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
    }
    launched = time.monotonic()
    command = [sys.executable, "-m", "camo_bringup.bench", "--bare-worker", str(side), str(steps)]
    workers = [
        subprocess.Popen(
            [*command, str(k), str(procs), str(int(packed)), str(budget)],
            env=env,
            stdout=subprocess.PIPE,
            text=True,
        )
        for k in range(min(procs, side * side))
    ]
    what = f"the bare exchange at {side}x{side}"
    reports = worker_reports(workers, what, 2 * budget)
    exited = time.monotonic()
    if not all(r["complete"] for r in reports):
        raise RuntimeError(f"{what} did not finish")
    start = max(r["matched"] for r in reports)
    end = max(r["done"] for r in reports)
    return {
        "setup_s": start - launched,
        "steps_per_s": steps / max(end - start, 1e-9),
        "wall_s": exited - launched,
    }


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
    parser.add_argument("--bare-worker", nargs=6, type=int, help=argparse.SUPPRESS)
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
    if args.bare_worker:
        print(json.dumps(bare_worker(*args.bare_worker)))
        return 0
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
