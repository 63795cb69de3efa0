"""`./camo bench ros`: the swarm's speed against a bare rclpy exchange of the same shape.

The bare exchange has the same topology (each node subscribes to its neighbours'
per-robot Vote topics, slots 0-7), message type and size, QoS, executor and
split over processes as `./camo run`, and does nothing else: publish step t,
wait for every neighbour's step t, publish step t+1. The ratio of the swarm's
step rate to the bare rate is the cost of the algorithm and its bookkeeping.
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

import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from camo_core.grid import neighbor_ids
from camo_msgs.msg import Vote

from .processes import split_cells
from .topics import history_qos, robot_topic


class BareNode(Node):
    """Publishes step t and moves on when every neighbour's step t has arrived."""

    def __init__(self, robot: int, rows: int, cols: int, steps: int, qos) -> None:
        super().__init__(f"bare_{robot}", start_parameter_services=False, enable_rosout=False)
        self.robot, self.steps, self.step = robot, steps, 0
        row, col = divmod(robot, cols)
        self.neighbors = [n for n in neighbor_ids(row, col, rows, cols)[:8] if n is not None]
        self.pub = self.create_publisher(Vote, robot_topic(robot, "vote"), qos)
        self.got: dict[int, set[int]] = {}
        for n in self.neighbors:
            self.create_subscription(Vote, robot_topic(n, "vote"), self._on_vote, qos)
        self.started = self.finished = None
        self._send()

    def _send(self) -> None:
        self.pub.publish(Vote(sender_id=self.robot, step=self.step, p=[0.2, 0.3, 0.5], degree=8))

    def _on_vote(self, msg: Vote) -> None:
        self.got.setdefault(msg.step, set()).add(msg.sender_id)
        while self.step < self.steps and len(self.got.get(self.step, ())) == len(self.neighbors):
            if self.step == 0:
                self.started = time.monotonic()
            self.step += 1
            if self.step < self.steps:
                self._send()
            else:
                self.finished = time.monotonic()


def bare_worker(rows: int, cols: int, steps: int, cells: list[int]) -> dict:
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    executor = EventsExecutor()
    nodes = [BareNode(c, rows, cols, steps, history_qos(steps + 4)) for c in cells]
    for node in nodes:
        executor.add_node(node)
    deadline = time.monotonic() + 600
    while any(n.finished is None for n in nodes) and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.1)
    # Keep serving our messages a little for neighbours in the other processes.
    linger = time.monotonic() + 3
    while time.monotonic() < linger:
        executor.spin_once(timeout_sec=0.1)
    report = {
        "start": min(n.started for n in nodes if n.started),
        "end": max(n.finished or 0 for n in nodes),
        "finished": sum(n.finished is not None for n in nodes),
    }
    rclpy.shutdown()
    return report


def bare_rate(side: int, steps: int, procs: int, domain: int) -> float:
    """Steps per second of the bare exchange (first step-0 completion to last finish)."""
    env = {
        **os.environ,
        "ROS_DOMAIN_ID": str(domain),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
    }
    workers = [
        subprocess.Popen(
            [
                sys.executable,
                "-m",
                "camo_nodes.bench",
                "--bare-worker",
                str(side),
                str(steps),
                ",".join(map(str, cells)),
            ],
            env=env,
            stdout=subprocess.PIPE,
            text=True,
        )
        for cells in split_cells(list(range(side * side)), procs)
    ]
    reports = [json.loads(w.communicate(timeout=900)[0].strip().splitlines()[-1]) for w in workers]
    if sum(r["finished"] for r in reports) != side * side:
        raise RuntimeError(f"bare exchange at {side}x{side} did not finish")
    return (steps - 1) / (max(r["end"] for r in reports) - min(r["start"] for r in reports))


def swarm_run(side: int, procs: int, domain: int, out: Path, steps: int | None = None) -> dict:
    """Run `./camo run` once (paper profile; `steps` consensus + formation steps if given);
    its timing.json has the wall time and the step rate."""
    start = time.monotonic()
    length = (
        [] if steps is None else ["--consensus-steps", str(steps - 10), "--formation-steps", "10"]
    )
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "camo_nodes.launcher",
            "--rows",
            str(side),
            "--cols",
            str(side),
            "--procs",
            str(procs),
            "--domain-id",
            str(domain),
            "--out",
            str(out),
            *length,
        ],
        capture_output=True,
        text=True,
        timeout=1800,
    )
    wall = time.monotonic() - start
    if proc.returncode != 0:
        raise RuntimeError(
            f"camo run {side}x{side} failed: {proc.stderr.strip().splitlines()[-1:]}"
        )
    timing = json.loads((out / "timing.json").read_text())
    return {"robots": f"{side}x{side}", "procs": procs, "wall_s": wall, **timing}


def default_steps(side: int) -> int:
    """Steps per rate measurement: runs of about 10 s here, since short runs' rates are noisy."""
    return max(300, 100_000 // side**2)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="camo bench ros")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument(
        "--sides", default="8,16", help="grid sides for the rate comparison (default 8,16)"
    )
    parser.add_argument(
        "--wall-sides", default="8,32", help="grid sides for whole-run wall times (default 8,32)"
    )
    parser.add_argument("--procs", type=int, default=os.cpu_count() or 1)
    parser.add_argument(
        "--steps",
        type=int,
        default=None,
        help="steps per rate measurement, swarm and bare alike (default 100000 / robots, at "
        "least 300: 1562 at 8x8, 390 at 16x16; 300-step 8x8 runs last under 3 s and "
        "their rates varied by a factor of 4)",
    )
    parser.add_argument(
        "--repeat", type=int, default=3, help="runs per rate; the median is reported (default 3)"
    )
    parser.add_argument(
        "--out", type=Path, default=Path("results") / time.strftime("bench-ros-%Y%m%d-%H%M%S")
    )
    parser.add_argument("--bare-worker", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.bare_worker:
        side, steps, cells = (
            int(args.bare_worker[0]),
            int(args.bare_worker[1]),
            args.bare_worker[2],
        )
        print(json.dumps(bare_worker(side, side, steps, [int(c) for c in cells.split(",")])))
        return 0
    if not ((args.steps is None or 20 <= args.steps <= 100_000) and args.repeat >= 1):
        parser.error("--steps must be in 20..100000 and --repeat at least 1")
    domain = 180 + os.getpid() % 40
    rates, walls = [], []
    for side in (int(s) for s in args.sides.split(",")):
        # Alternate swarm and bare runs and take medians: this shared machine's speed drifts.
        swarm_rates, bare_rates = [], []
        steps = args.steps or default_steps(side)
        for k in range(args.repeat):
            swarm = swarm_run(side, args.procs, domain, args.out / f"swarm_{side}_{k}", steps)
            swarm_rates.append(swarm["steps_per_s"])
            bare_rates.append(bare_rate(side, steps, args.procs, domain))
            print(
                f"{side}x{side}: swarm {swarm_rates[-1]:.2f} steps/s, "
                f"bare exchange {bare_rates[-1]:.2f} steps/s",
                file=sys.stderr,
            )
        swarm_rate, bare = statistics.median(swarm_rates), statistics.median(bare_rates)
        rates.append(
            {
                "robots": f"{side}x{side}",
                "swarm_steps_per_s": swarm_rate,
                "bare_steps_per_s": bare,
                "ratio": swarm_rate / bare,
                "steps": steps,
                "repeat": args.repeat,
            }
        )
    for side in (int(s) for s in args.wall_sides.split(",")):
        walls.append(swarm_run(side, args.procs, domain, args.out / f"wall_{side}"))
        print(f"{side}x{side}: whole run {walls[-1]['wall_s']:.1f} s", file=sys.stderr)
    report = {"rates": rates, "wall": walls}
    if args.json:
        print(json.dumps(report))
    else:
        print(f"rates: median of {args.repeat} runs each")
        print(
            f"{'robots':>8} {'steps':>6} {'swarm steps/s':>14} {'bare steps/s':>13} {'ratio':>6}"
        )
        for r in rates:
            print(
                f"{r['robots']:>8} {r['steps']:>6} {r['swarm_steps_per_s']:>14.2f} "
                f"{r['bare_steps_per_s']:>13.2f} "
                f"{r['ratio']:>6.2f}"
            )
        print()
        print(
            f"{'robots':>8} {'procs':>5} {'launch to exit s':>17} {'nodes up s':>11} "
            f"{'steps/s':>8}"
        )
        for w in walls:
            print(
                f"{w['robots']:>8} {w['procs']:>5} {w['wall_s']:>17.1f} {w['startup_s']:>11.1f} "
                f"{w['steps_per_s']:>8.2f}"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
