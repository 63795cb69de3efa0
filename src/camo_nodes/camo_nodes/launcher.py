"""`./camo run`: the distributed swarm, launched from one command.

Starts the projector (unless --no-projector), a bridge process per real
Droplet (--bridge) and K worker processes (robot nodes spread over them, many
per executor), runs the monitor (and with --record the recorder) here, shows
progress, and writes summary.json and figure.png when every live robot has
finished. Ctrl-C stops every process it started and still writes what it has,
bag included.
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
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import String

from camo_core import cli
from camo_core.backgrounds import BACKGROUNDS
from camo_core.params import ParameterError
from camo_core.sensing import ImageError, load_image
from camo_projector.qos import BACKGROUND_TOPIC, LATCHED, LOAD_TOPIC

from .bag import BagError
from .droplet_link import Calibration
from .monitor_node import MonitorNode, write_round
from .recorder_node import RecorderNode
from .robot_node import MESSAGE_TYPES
from .shutdown import StopFlag
from .swarm_worker import events_executor
from .topics import PARAMS_TOPIC, PATTERN_TOPIC, STATUS_TOPIC, robot_topic


def build_parser() -> cli.Parser:
    parser = cli.Parser(
        prog="camo run", description="run the camouflage as a swarm of ROS 2 nodes"
    )
    cli.add_run_options(parser)
    parser.add_argument(
        "--procs",
        type=int,
        default=os.cpu_count() or 1,
        help="worker processes hosting the robot nodes (default: number of cores)",
    )
    parser.add_argument(
        "--domain-id", type=int, default=None, help="ROS_DOMAIN_ID (default: inherited, else 0)"
    )
    parser.add_argument(
        "--step-timeout",
        type=float,
        default=30.0,
        help="seconds a robot waits for a silent neighbour before moving on (default 30)",
    )
    parser.add_argument(
        "--discovery-timeout",
        type=float,
        default=None,
        help="seconds a robot waits for its neighbours' hellos (default 300 + 0.15 per robot: "
        "node start-up of big swarms is slow; a robot that never starts costs this once)",
    )
    parser.add_argument(
        "--own-process",
        action="append",
        default=[],
        metavar="ROW,COL",
        help="run this robot alone in a process of its own (repeatable)",
    )
    parser.add_argument(
        "--then",
        action="append",
        default=[],
        metavar="BACKGROUND",
        help="after the camouflage finishes, project this built-in name or image file and "
        "camouflage again (repeatable); each round writes round_<k>/",
    )
    parser.add_argument(
        "--bridge",
        action="append",
        default=[],
        metavar="ROW,COL=PORT",
        help="this cell is a real Droplet on this serial port (repeatable); see docs/hardware.md",
    )
    parser.add_argument(
        "--calibration",
        default=None,
        metavar="YAML",
        help="gain and offset applied to every bridged Droplet's grey reading",
    )
    parser.add_argument(
        "--record",
        metavar="BAG",
        default=None,
        help="record every topic of the run into this MCAP bag folder (as rosbag2 does)",
    )
    parser.add_argument(
        "--no-projector",
        action="store_true",
        help="start no projector: the background comes from elsewhere, e.g. "
        "./camo replay BAG --topics /camo/background",
    )
    return parser


def parse_cells(texts: list[str], params) -> list[int]:
    cells = []
    for text in texts:
        try:
            row, col = (int(x) for x in text.split(","))
        except ValueError:
            raise cli.UsageError(f"--own-process takes ROW,COL (got {text!r})") from None
        if not (0 <= row < params.rows and 0 <= col < params.cols):
            raise cli.UsageError(
                f"--own-process {text}: outside the {params.rows}x{params.cols} grid"
            )
        cells.append(row * params.cols + col)
    return cells


def parse_bridges(texts: list[str], params) -> dict[int, str]:
    """--bridge ROW,COL=PORT options as {robot id: port}."""
    bridges = {}
    for text in texts:
        cell, _, port = text.partition("=")
        if not port:
            raise cli.UsageError(f"--bridge takes ROW,COL=PORT (got {text!r})")
        robot = parse_cells([cell], params)[0]
        if robot in bridges:
            raise cli.UsageError(f"--bridge {cell}: that cell is bridged twice")
        bridges[robot] = port
    return bridges


def robot_parameters(params, args: argparse.Namespace, robot: int) -> list[str]:
    """A standalone robot's (or bridge's) ROS parameters, as -p options."""
    row, col = divmod(robot, params.cols)
    values = {
        "rows": params.rows,
        "cols": params.cols,
        "row": row,
        "col": col,
        "profile": params.profile,
        "seed": params.seed,
        "rho_meas": float(params.rho_meas),
        "rho_comm": float(params.rho_comm),
        "threshold": float(params.threshold),
        "consensus_steps": params.consensus_steps,
        "formation_steps": params.formation_steps,
        "step_timeout": float(args.step_timeout),
        "discovery_timeout": float(args.discovery_timeout),
    }
    return [
        x
        for name, value in values.items()
        for x in ("-p", f"{name}:={value!r}" if isinstance(value, float) else f"{name}:={value}")
    ]


def split_cells(count: int, procs: int) -> list[list[int]]:
    """Robot ids in contiguous blocks, one per process, so neighbours mostly share a process."""
    procs = max(1, min(procs, count))
    bounds = [round(k * count / procs) for k in range(procs + 1)]
    return [list(range(bounds[k], bounds[k + 1])) for k in range(procs)]


class Swarm:
    """The processes of one run: projector and workers."""

    def __init__(
        self,
        args: argparse.Namespace,
        params,
        env: dict,
        alone: list[int],
        bridges: dict[int, str],
    ) -> None:
        self.procs: list[subprocess.Popen] = []
        self.cells: dict[int, list[int]] = {}  # pid -> robot ids
        python = sys.executable
        if not args.no_projector:
            self._start_projector(args, env)
        for robot, port in bridges.items():
            command = [
                python,
                "-m",
                "camo_nodes.droplet_bridge",
                "--ros-args",
                "--log-level",
                "warn",
                *robot_parameters(params, args, robot),
                "-p",
                f"port:={port}",
            ]
            if args.calibration:
                command += ["-p", f"calibration:={Path(args.calibration).resolve()}"]
            self.cells[self._start(command, env).pid] = [robot]
        shared = [i for i in range(params.count) if i not in alone and i not in bridges]
        groups = [[i] for i in alone] + (split_cells(len(shared), args.procs) if shared else [])
        for group in groups[len(alone) :]:
            group[:] = [shared[k] for k in group]
        for cells in groups:
            proc = self._start(
                [
                    python,
                    "-m",
                    "camo_nodes.swarm_worker",
                    "--params",
                    json.dumps(params.as_dict()),
                    "--cells",
                    ",".join(map(str, cells)),
                    "--step-timeout",
                    str(args.step_timeout),
                    "--discovery-timeout",
                    str(args.discovery_timeout),
                    "--ros-args",
                    "--log-level",
                    "warn",
                ],
                env,
            )
            self.cells[proc.pid] = cells

    def _start_projector(self, args: argparse.Namespace, env: dict) -> None:
        projector = [
            sys.executable,
            "-m",
            "camo_projector.projector_node",
            "--ros-args",
            "--log-level",
            "warn",
        ]
        if args.image:
            projector += ["-p", f"image:={Path(args.image).resolve()}"]
        else:
            projector += ["-p", f"pattern:={args.pattern or args.default_pattern}"]
        self._start(projector, env)

    def _start(self, command: list[str], env: dict) -> subprocess.Popen:
        # Own process group: the terminal's Ctrl-C reaches us, and we stop them in order.
        proc = subprocess.Popen(command, env=env, start_new_session=True)
        self.procs.append(proc)
        return proc

    def failed(self) -> str | None:
        """The projector or a worker exited with an error (a robot killed by a signal is a fault, not this)."""
        for proc in self.procs:
            if proc.poll() is not None and proc.returncode > 0:
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


def write_outputs(
    monitor: MonitorNode, round_index: int, folder: Path, label: str, image, partial: bool = False
) -> dict:
    return write_round(
        monitor.result(round_index, partial),
        image,
        folder,
        label,
        monitor.progress_line(round_index) if partial else None,
    )


def recorded_topics(params, switching: bool) -> set[str]:
    """The topics a recording of a whole run must hold."""
    topics = {robot_topic(i, kind) for i in range(params.count) for kind in MESSAGE_TYPES}
    topics |= {STATUS_TOPIC, PATTERN_TOPIC, PARAMS_TOPIC, BACKGROUND_TOPIC}
    return topics | {LOAD_TOPIC} if switching else topics


def expected_messages(params, monitor: MonitorNode, rounds: int) -> dict[str, int]:
    """What a recording must hold once `rounds` rounds are over: every status the monitor heard, and
    from each robot, for each round it finished, its hello, its colour, its votes and its states."""
    per_round = {
        "hello": 1,
        "color": 1,
        "vote": params.consensus_steps,
        "state": params.formation_steps,
    }
    finished = sum(monitor.record(k).finished.astype(int) for k in range(rounds))
    expected = {
        robot_topic(i, kind): n * int(finished[i])
        for i in range(params.count)
        for kind, n in per_round.items()
    }
    expected[STATUS_TOPIC] = monitor.statuses_heard
    return expected


def lacking(recorder: RecorderNode, expected: dict[str, int]) -> dict[str, int]:
    """Messages still missing from the recording, by topic."""
    return {
        topic: n - got for topic, n in expected.items() if (got := recorder.recorded(topic)) < n
    }


def drain(
    executor,
    recorder: RecorderNode,
    topics: set[str],
    expected,
    stop,
    quiet: float = 1.0,
    limit: float = 60.0,
) -> None:
    """Before the robots stop or start a new round: let the recorder subscribe to every topic and take
    in what is still coming. Matching a publisher is not enough: a publisher in another process hands
    over its history only once it has discovered the recorder, so wait for the messages themselves."""
    deadline = time.monotonic() + limit
    while time.monotonic() < deadline and not stop:
        executor.spin_once(timeout_sec=0.1)
        if recorder.settled(topics, quiet, ignoring=frozenset({PATTERN_TOPIC})) and not lacking(
            recorder, expected()
        ):
            return
    if stop:
        return
    missing = sorted(topics - recorder.recording_now())
    if missing:
        print(
            f"camo run: the recording lacks {len(missing)} topics, e.g. {missing[:3]}",
            file=sys.stderr,
        )
    short = lacking(recorder, expected())
    if short:
        print(
            f"camo run: the recording lacks {sum(short.values())} messages on {len(short)} topics, "
            f"e.g. {sorted(short)[:3]}",
            file=sys.stderr,
        )


def wait_for_listener(executor, publisher, what: str, stop, limit: float = 60.0) -> None:
    """A message on a volatile topic reaches only subscribers matched when it is sent."""
    deadline = time.monotonic() + limit
    while publisher.get_subscription_count() == 0 and not stop:
        if time.monotonic() > deadline:
            raise RuntimeError(f"no {what} listens on {publisher.topic_name} after {limit:g} s")
        executor.spin_once(timeout_sec=0.1)


def run(args: argparse.Namespace) -> int:
    params = cli.params_from(args)
    if args.procs < 1 or args.procs > 256:
        raise cli.UsageError(f"--procs must be an integer in 1..256 (got {args.procs})")
    if args.discovery_timeout is None:
        args.discovery_timeout = (
            300.0 + 0.15 * params.count
        )  # 64x64 needed about 505 s to start here
    for name in ("step_timeout", "discovery_timeout"):
        if getattr(args, name) <= 0:
            raise cli.UsageError(
                f"--{name.replace('_', '-')} must be positive (got {getattr(args, name)})"
            )
    alone = parse_cells(args.own_process, params)
    bridges = parse_bridges(args.bridge, params)
    if set(alone) & set(bridges):
        raise cli.UsageError("a cell cannot be both --own-process and --bridge")
    if args.calibration:
        Calibration.from_yaml(args.calibration)  # a bad file fails here, in one line
    image, label = cli.image_from(args)
    cli.sense_image(
        image, params.rows, params.cols, params.profile
    )  # a too-small image fails here
    labels = [label]
    for then in args.then:
        if then not in BACKGROUNDS:
            cli.sense_image(load_image(then), params.rows, params.cols, params.profile)
        labels.append(then)
    folder = cli.out_dir(args)
    env = dict(os.environ)
    if args.domain_id is not None:
        if not 0 <= args.domain_id <= 232:
            raise cli.UsageError(f"--domain-id must be in 0..232 (got {args.domain_id})")
        env["ROS_DOMAIN_ID"] = str(args.domain_id)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.update(env)

    launched = time.monotonic()
    stop = StopFlag()
    rclpy.init(
        args=["--ros-args", "--log-level", "warn"], signal_handler_options=SignalHandlerOptions.NO
    )
    recorder = None
    if args.record:
        try:
            recorder = RecorderNode(args.record)  # first, so that it hears the run from its start
        except BagError as exc:
            rclpy.try_shutdown()
            raise cli.UsageError(str(exc)) from None
        print(f"camo run: recording every topic to {recorder.bag.file}", file=sys.stderr)
    monitor = MonitorNode(
        params,
        silence_timeout=max(3 * args.step_timeout, 5.0),
        startup_timeout=args.discovery_timeout + 60.0,
    )
    loader = monitor.create_publisher(String, LOAD_TOPIC, 10)
    monitor.create_publisher(String, PARAMS_TOPIC, LATCHED).publish(
        String(data=json.dumps({"params": params.as_dict(), "backgrounds": labels}))
    )
    executor = events_executor()
    executor.add_node(monitor)
    if recorder is not None:
        executor.add_node(recorder)
    swarm = Swarm(args, params, env, alone, bridges)
    (folder / "processes.json").write_text(
        json.dumps({str(pid): cells for pid, cells in swarm.cells.items()})
    )
    code = 0
    round_index = 0
    written: list[dict] = []
    try:
        for round_index, round_label in enumerate(labels):
            if round_index > 0:
                if recorder is not None:
                    # A robot's topics keep one round of history for late subscribers: the recorder
                    # must have taken this round in before the next one pushes it out.
                    drain(
                        executor,
                        recorder,
                        recorded_topics(params, True),
                        lambda: expected_messages(params, monitor, round_index),
                        stop,
                    )
                wait_for_listener(executor, loader, "projector", stop)
                loader.publish(String(data=round_label))
            last_print = 0.0
            all_voted = None  # when every robot had voted: the steps start
            while not monitor.complete(round_index):
                if stop:
                    raise KeyboardInterrupt
                # Handle a burst of statuses before the (numpy) checks below, so the monitor keeps up.
                executor.spin_once(timeout_sec=0.1)
                for _ in range(200):
                    executor.spin_once(timeout_sec=0.0)
                if all_voted is None and monitor.all_voted(round_index):
                    all_voted = time.monotonic()
                now = time.monotonic()
                if now - last_print > 1.0:
                    print(f"camo run: {monitor.progress_line(round_index)}", file=sys.stderr)
                    last_print = now
                problem = swarm.failed()
                if problem:
                    raise RuntimeError(problem)
            print(f"camo run: {monitor.progress_line(round_index)}", file=sys.stderr)
            round_folder = folder if len(labels) == 1 else folder / f"round_{round_index}"
            round_folder.mkdir(exist_ok=True)
            shown = monitor.images[round_index] if len(monitor.images) > round_index else image
            summary = write_outputs(monitor, round_index, round_folder, round_label, shown)
            written.append(summary)
            done = time.monotonic()
            steps = params.consensus_steps + params.formation_steps
            voted = all_voted or done
            missed = int(monitor.record(round_index).deadlines.sum())
            (round_folder / "timing.json").write_text(
                json.dumps(
                    {
                        "startup_s": voted - launched,
                        "steps": steps,
                        "steps_s": done - voted,
                        "steps_per_s": steps / max(done - voted, 1e-9),
                        "launch_to_done_s": done - launched,
                        "deadlines": missed,
                    }
                )
                + "\n"
            )
            counts = ", ".join(f"{k} {v}" for k, v in summary["votes"].items())
            dead_cells = summary.get("dead", [])
            dead = (
                f"; {len(dead_cells)} dead robots {dead_cells[:8]}{' ...' if len(dead_cells) > 8 else ''}"
                if dead_cells
                else ""
            )
            if missed:
                dead += (
                    f"; {missed} step deadlines passed (robots moved on without silent neighbours: the "
                    f"result can differ from ./camo sim)"
                )
            print(
                f"pattern: {summary['pattern']} ({counts}){dead}; wrote {round_folder}/summary.json and figure.png"
            )
        if recorder is not None:
            drain(
                executor,
                recorder,
                recorded_topics(params, len(labels) > 1),
                lambda: expected_messages(params, monitor, len(labels)),
                stop,
            )
    except (KeyboardInterrupt, ExternalShutdownException):
        print("camo run: interrupted; stopping the swarm and writing what it has", file=sys.stderr)
        code = 130
    except RuntimeError as exc:
        print(f"camo run: error: {exc}", file=sys.stderr)
        code = 1
    finally:
        swarm.stop()
        if len(written) < len(labels):
            partial = folder if len(labels) == 1 else folder / f"round_{round_index}"
            partial.mkdir(exist_ok=True)
            try:
                write_outputs(
                    monitor,
                    round_index,
                    partial,
                    labels[round_index] + " (incomplete)",
                    image,
                    partial=True,
                )
                print(
                    f"camo run: wrote what the swarm had reported to {partial}/", file=sys.stderr
                )
            except Exception as exc:  # noqa: BLE001 - a run stopped early may lack what a figure needs
                print(f"camo run: nothing to write yet ({exc})", file=sys.stderr)
        if recorder is not None:
            recorder.close()
            print(
                f"camo run: recorded {recorder.bag.message_count} messages on {len(recorder.bag.topics)} topics "
                f"to {recorder.bag.folder}/",
                file=sys.stderr,
            )
        # Executor first, then node, then context: the EventsExecutor must let go of the
        # node's handles before they are destroyed, or interpreter exit can crash.
        executor.shutdown()
        for node in (monitor, recorder):
            if node is not None:
                executor.remove_node(node)
                node.destroy_node()
        del executor
        rclpy.try_shutdown()
    return code


def main(argv: list[str] | None = None) -> int:
    try:
        return run(build_parser().parse_args(argv))
    except (cli.UsageError, ParameterError, ImageError, ValueError) as exc:
        print(f"camo: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
