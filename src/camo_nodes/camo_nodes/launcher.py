"""`./camo run`: the distributed swarm, launched from one command.

Starts the projector and K worker processes (robot nodes spread over them,
many per executor), runs the monitor here, shows progress, and writes
summary.json and figure.png when every live robot has finished. Ctrl-C stops
every process it started and still writes what it has.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import rclpy
from rclpy.executors import ExternalShutdownException

from camo_core import cli, figures
from camo_core.params import ParameterError
from camo_core.sensing import ImageError

from .monitor_node import MonitorNode
from .swarm_worker import events_executor


def build_parser() -> cli.Parser:
    parser = cli.Parser(prog="camo run", description="run the camouflage as a swarm of ROS 2 nodes")
    cli.add_run_options(parser)
    parser.add_argument("--procs", type=int, default=os.cpu_count() or 1,
                        help="worker processes hosting the robot nodes (default: number of cores)")
    parser.add_argument("--domain-id", type=int, default=None, help="ROS_DOMAIN_ID (default: inherited, else 0)")
    parser.add_argument("--step-timeout", type=float, default=10.0,
                        help="seconds a robot waits for a silent neighbour before moving on (default 10)")
    return parser


def split_cells(count: int, procs: int) -> list[list[int]]:
    """Robot ids in contiguous blocks, one per process, so neighbours mostly share a process."""
    procs = max(1, min(procs, count))
    bounds = [round(k * count / procs) for k in range(procs + 1)]
    return [list(range(bounds[k], bounds[k + 1])) for k in range(procs)]


class Swarm:
    """The processes of one run: projector and workers."""

    def __init__(self, args: argparse.Namespace, params, env: dict) -> None:
        self.procs: list[subprocess.Popen] = []
        python = sys.executable
        projector = [python, "-m", "camo_projector.projector_node", "--ros-args", "--log-level", "warn"]
        if args.image:
            projector += ["-p", f"image:={Path(args.image).resolve()}"]
        else:
            projector += ["-p", f"pattern:={args.pattern or args.default_pattern}"]
        self._start(projector, env)
        for cells in split_cells(params.count, args.procs):
            self._start([python, "-m", "camo_nodes.swarm_worker", "--params", json.dumps(params.as_dict()),
                         "--cells", ",".join(map(str, cells)), "--step-timeout", str(args.step_timeout),
                         "--ros-args", "--log-level", "error"], env)

    def _start(self, command: list[str], env: dict) -> None:
        # Own process group: the terminal's Ctrl-C reaches us, and we stop them in order.
        self.procs.append(subprocess.Popen(command, env=env, start_new_session=True))

    def failed(self) -> str | None:
        for proc in self.procs:
            if proc.poll() not in (None, 0):
                return f"a swarm process exited with code {proc.returncode}: {' '.join(proc.args[:3])}"
        return None

    def stop(self, grace: float = 5.0) -> None:
        for proc in self.procs:
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
        deadline = time.monotonic() + grace
        for proc in self.procs:
            try:
                proc.wait(max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def write_outputs(monitor: MonitorNode, folder: Path, label: str, image) -> None:
    result = monitor.result()
    cli.write_summary(result.summary(), folder)
    params = monitor.params
    figures.run_figure(result, image, folder / "figure.png",
                       title=f"{label}: {params.rows}x{params.cols} robot nodes, {params.profile} profile, "
                             f"seed {params.seed}, rho_meas {params.rho_meas:g}, rho_comm {params.rho_comm:g}")


def run(args: argparse.Namespace) -> int:
    params = cli.params_from(args)
    if args.procs < 1 or args.procs > 256:
        raise cli.UsageError(f"--procs must be an integer in 1..256 (got {args.procs})")
    if args.step_timeout <= 0:
        raise cli.UsageError(f"--step-timeout must be positive (got {args.step_timeout})")
    image, label = cli.image_from(args)
    cli.sense_image(image, params.rows, params.cols, params.profile)      # a too-small image fails here
    folder = cli.out_dir(args)
    env = dict(os.environ)
    if args.domain_id is not None:
        if not 0 <= args.domain_id <= 232:
            raise cli.UsageError(f"--domain-id must be in 0..232 (got {args.domain_id})")
        env["ROS_DOMAIN_ID"] = str(args.domain_id)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.update(env)

    rclpy.init(args=["--ros-args", "--log-level", "warn"])
    swarm = Swarm(args, params, env)
    monitor = MonitorNode(params, silence_timeout=max(3 * args.step_timeout, 30.0))
    executor = events_executor()
    executor.add_node(monitor)
    code = 0
    last_print = 0.0
    try:
        while not monitor.complete:
            executor.spin_once(timeout_sec=0.1)
            now = time.monotonic()
            if now - last_print > 1.0:
                print(f"camo run: {monitor.progress_line()}", file=sys.stderr)
                last_print = now
            problem = swarm.failed()
            if problem:
                raise RuntimeError(problem)
        print(f"camo run: {monitor.progress_line()}", file=sys.stderr)
    except (KeyboardInterrupt, ExternalShutdownException):
        print("camo run: interrupted; stopping the swarm and writing what it has", file=sys.stderr)
        code = 130
    except RuntimeError as exc:
        print(f"camo run: error: {exc}", file=sys.stderr)
        code = 1
    finally:
        swarm.stop()
        try:
            write_outputs(monitor, folder, label, monitor.image if monitor.image is not None else image)
        except Exception as exc:  # noqa: BLE001 - a partial run may lack what a figure needs
            (folder / "statuses_incomplete.txt").write_text(f"{monitor.progress_line()}\n{exc}\n")
        monitor.destroy_node()
        rclpy.try_shutdown()
    if code == 0:
        result = json.loads((folder / "summary.json").read_text())
        print(f"pattern: {result['pattern']} ({', '.join(f'{k} {v}' for k, v in result['votes'].items())}); "
              f"wrote {folder}/summary.json and figure.png")
    return code


def main(argv: list[str] | None = None) -> int:
    try:
        return run(build_parser().parse_args(argv))
    except (cli.UsageError, ParameterError, ImageError, ValueError) as exc:
        print(f"camo: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
