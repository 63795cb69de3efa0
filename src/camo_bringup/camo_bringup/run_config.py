"""`./camo run`'s command line, checked into one RunConfig before anything starts.

Every bad option is found here and reported in one line (exit code 2), so a
run never starts processes it would have to stop again.
"""

from __future__ import annotations

import argparse
import os
import socket
import stat
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from camo_core.algorithm.backgrounds import BACKGROUNDS, background
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.sensing import Calibration, image_digest, sense_image
from camo_core.cli.options import (
    Combination,
    Parser,
    add_options,
    add_run_options,
    image_from,
    options_of,
    out_dir,
    params_from,
    parse_ranges,
)
from camo_core.exceptions import UsageError
from camo_core.inputs.files import checked_path, shown
from camo_core.inputs.images import load_image
from camo_core.inputs.numeric import integer, items
from camo_core.results.folders import new_folder_problem
from camo_core.swarm.keys import ENCRYPT_ENV, KEY_FILE_ENV, new_key_file, read_key_file
from camo_core.swarm.run_setup import MAX_WAIT, ProtocolParams, RunSetup, contiguous
from camo_nodes.topics.names import RunTopics, check_run_id, new_run_id
from camo_nodes.topics.parameters import ros_arguments
from camo_nodes.topics.startup import add_network_options, network_env, use_camo_dds_settings
from camo_projector.projector_node import STREAM_COMBINATIONS, ProjectorParams, open_source

# The projector's stream options `./camo run` takes (camo_projector: what it projects).
STREAM_OPTIONS = (
    "background_topic",
    "video",
    "fps",
    "loop",
    "images",
    "period",
    "camera",
    "max_fps",
)
MAX_ROUNDS = 1_000_000

# Robots a worker hosts at most by default: creating a process's nodes grows with their square
# (docs/swarm.md, "Set-up"), so a large swarm is spread over more processes than cores.
ROBOTS_PER_PROCESS = 8192


def build_parser() -> Parser:
    parser = Parser(prog="camo run", description="run the camouflage as a swarm of ROS 2 nodes")
    parser.add_params_file_option("camo_run")
    add_run_options(parser)
    add = parser.add_argument
    add(
        "--procs",
        type=int,
        default=None,
        help="worker processes hosting the robot nodes (default: the number of cores, or more "
        f"so that none hosts more than {ROBOTS_PER_PROCESS} robots)",
    )
    add_network_options(parser)
    add(
        "--run-id",
        default=None,
        help="name of the run: its topics live under /<run id>/ (default: a new unique one)",
    )
    add(
        "--remote-cells",
        action="append",
        default=[],
        metavar="FIRST-LAST",
        help="robots this run does not start: `./camo worker --cells FIRST-LAST` hosts them, "
        "on this machine or another (repeatable)",
    )
    add_options(parser, ProtocolParams)
    add(
        "--own-process",
        action="append",
        default=[],
        metavar="ROW,COL",
        help="run this robot alone in a process of its own (repeatable)",
    )
    add(
        "--then",
        action="append",
        default=[],
        metavar="BACKGROUND",
        help="after the camouflage finishes, project this built-in name or image file and "
        "camouflage again (repeatable); each round writes round_<k>/",
    )
    add(
        "--rounds",
        type=int,
        default=None,
        metavar="N",
        help="with --continuous: end the run after this many finished rounds (exit code 0)",
    )
    add(
        "--duration",
        type=float,
        default=None,
        metavar="S",
        help="with --continuous: end the run after this many seconds (exit code 0)",
    )
    add_options(parser, ProjectorParams, only=STREAM_OPTIONS)
    add(
        "--bridge",
        action="append",
        default=[],
        metavar="ROW,COL=PORT",
        help="this cell is a real Droplet on this serial port (repeatable); see docs/hardware.md",
    )
    add(
        "--calibration",
        default=None,
        metavar="YAML",
        help="gain and offset applied to every bridged Droplet's grey reading",
    )
    add(
        "--record",
        metavar="BAG",
        default=None,
        help="record every topic of the run into this MCAP bag folder (as rosbag2 does)",
    )
    add(
        "--foxglove",
        metavar="PORT",
        type=int,
        nargs="?",
        const=8765,
        default=None,
        help="serve the run live to Foxglove on ws://127.0.0.1:PORT (default 8765), as "
        "./camo view does",
    )
    add(
        "--no-key",
        action="store_true",
        help="run without a key: its processes believe any writer in the domain (to measure "
        "what keys cost, or with nodes of your own that write on the run's topics)",
    )
    add(
        "--encrypt",
        action="store_true",
        help="also encrypt the robots' messages and the backgrounds (AES-GCM with the run's "
        "key): the traffic cannot be read without the key file",
    )
    add(
        "--no-projector",
        action="store_true",
        help="start no projector: the background comes from elsewhere, e.g. "
        "./camo replay BAG --topics /RUN/camo/background --run-id RUN",
    )
    parser.combine(*RUN_COMBINATIONS)
    return parser


SOURCES = ("--image", "--video", "--images", "--background-topic", "--camera")
CONTINUOUS_ONLY = "a continuous swarm starts its own rounds, on projected frames only"
# Which options of `camo run` need, exclude or mean nothing without which others.
RUN_COMBINATIONS = (
    Combination("--rounds", needs=("--continuous",), why="it ends a --continuous run"),
    Combination("--duration", needs=("--continuous",), why="it ends a --continuous run"),
    Combination("--continuous", excludes=("--then", "--bridge"), why=CONTINUOUS_ONLY),
    *(
        Combination(flag, needs=("--continuous",), why="how a --continuous swarm watches")
        for flag in ("--sense-period", "--change-window", "--change-threshold")
    ),
    Combination("--no-key", excludes=("--key-file", "--encrypt")),
    *(
        Combination(source, excludes=SOURCES[k + 1 :], why="one background source")
        for k, source in enumerate(SOURCES)
    ),
    Combination("--then", excludes=SOURCES[1:], why="--then switches still backgrounds"),
    *STREAM_COMBINATIONS,
    Combination("--pattern", excludes=SOURCES[1:], why="one background source"),
    # (--pattern stays: what the run's own projector would have shown, in its parameters)
    Combination("--no-projector", excludes=(*SOURCES[1:], "--then"), why="no projector shows it"),
)


@dataclass
class RunConfig:
    params: CamoParams
    procs: int
    protocol: ProtocolParams
    image: np.ndarray  # the first background
    labels: list[str]  # every round's background: a built-in name or a file
    folder: Path
    env: dict[str, str]
    projector: list[str] | None  # the projector's ROS parameters, None with --no-projector
    topics: RunTopics = field(default_factory=lambda: RunTopics(new_run_id()))
    remote: list[tuple[int, int]] = field(default_factory=list)  # robots left to remote workers
    named: bool = False  # the run id was given (--run-id): refuse it if a run of it is live
    alone: list[int] = field(default_factory=list)  # robots in processes of their own
    bridges: dict[int, str] = field(default_factory=dict)  # robot -> serial port
    calibration: Path | None = None
    record: Path | None = None
    foxglove: int | None = None  # the live view's port
    digests: list[str] = field(default_factory=list)  # of the backgrounds our projector shows
    # --continuous: finished rounds and seconds after which the run ends (None: no end).
    until_rounds: int | None = None
    until_seconds: float | None = None
    # A large swarm on this machine: its processes find each other through a discovery server
    # of the run's own, started once every worker has created its robot nodes (HOST:PORT).
    deferred: str | None = None

    @property
    def rounds(self) -> int:
        return len(self.labels)

    @property
    def continuous(self) -> bool:
        return self.protocol.continuous

    def setup(self) -> RunSetup:
        """What /<run>/swarm/params says of the run: all a worker on another machine needs."""
        return RunSetup(
            run=self.topics.run,
            params=self.params,
            protocol=self.protocol,
            backgrounds=tuple(self.labels),
            remote=tuple(self.remote),
            tiles=tuple(self.tiles()),
            background_digests=tuple(self.digests),
            bridged=tuple(sorted(self.bridges)),
        )

    def tiles(self) -> list[tuple[int, int]]:
        """Every tile the run's own processes host: the workers' blocks, the lone robots."""
        groups = [*worker_groups(self), *([b] for b in self.bridges)]
        return [tile for cells in groups for tile in contiguous(cells)]


def parse_cells(texts: list[str], params: CamoParams, option: str = "--own-process") -> list[int]:
    """ROW,COL options as robot ids; a cell given twice is an error."""
    cells: list[int] = []
    for text in texts:
        try:
            row, col = (integer(x) for x in items(text, option))
        except ValueError:
            raise UsageError(f"{option} takes ROW,COL (got {text!r})") from None
        if not (0 <= row < params.rows and 0 <= col < params.cols):
            raise UsageError(f"{option} {text}: outside the {params.rows}x{params.cols} grid")
        if row * params.cols + col in cells:
            raise UsageError(f"{option} {row},{col}: that cell is given twice")
        cells.append(row * params.cols + col)
    return cells


def check_port(port: str, cell: str) -> None:
    """A bridge's PORT: an existing character device (a serial port, a pty or a symlink to
    one), checked before anything starts."""
    path = checked_path(port, "--bridge port", UsageError)
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        raise UsageError(f"--bridge {cell}={shown(port)}: no such port") from None
    except OSError as exc:
        raise UsageError(f"--bridge {cell}={shown(port)}: {exc.strerror or exc}") from None
    if not stat.S_ISCHR(mode):
        raise UsageError(
            f"--bridge {cell}={shown(port)}: not a serial port (a character device or a pty)"
        )


def parse_bridges(texts: list[str], params: CamoParams) -> dict[int, str]:
    """--bridge ROW,COL=PORT options as {robot id: port}."""
    bridges: dict[int, str] = {}
    for text in texts:
        cell, _, port = text.partition("=")
        if not port:
            raise UsageError(f"--bridge takes ROW,COL=PORT (got {text!r})")
        robot = parse_cells([cell], params, "--bridge")[0]
        if robot in bridges:
            raise UsageError(f"--bridge {cell}: that cell is bridged twice")
        check_port(port, cell)
        bridges[robot] = port
    return bridges


def config_from(args: argparse.Namespace, environ: dict[str, str] | None = None) -> RunConfig:
    params = params_from(args)
    procs = default_procs(params.count) if args.procs is None else args.procs
    if not 1 <= procs <= 256:
        raise UsageError(f"--procs must be an integer in 1..256 (got {args.procs})")
    protocol = ProtocolParams(**options_of(args, ProtocolParams)).for_swarm(params.count)
    alone = parse_cells(args.own_process, params)
    bridges = parse_bridges(args.bridge, params)
    remote = parse_ranges(args.remote_cells, params.count, "--remote-cells")
    remote_cells = {c for a, b in remote for c in range(a, b + 1)}
    if set(alone) & set(bridges) or (set(alone) | set(bridges)) & remote_cells:
        raise UsageError("a cell can be only one of --own-process, --bridge and --remote-cells")
    calibration = None
    if args.calibration:
        Calibration.from_yaml(args.calibration)  # a bad file (or path) fails here, in one line
        calibration = Path(args.calibration).resolve()
    if args.foxglove is not None and not 0 <= args.foxglove <= 65535:
        raise UsageError(f"--foxglove PORT must be in 0..65535 (got {args.foxglove})")
    record = Path(args.record) if args.record else None
    if record is not None:
        problem = new_folder_problem(record, "the bag")
        if problem or record.suffix == ".mcap":
            raise UsageError(problem or f"--record {record}: give a bag folder, not a .mcap file")
        out = Path(args.out).resolve() if args.out else None
        if out is not None and (out == record.resolve() or record.resolve() in out.parents):
            # The results would be in the bag's folder before the recorder makes it: refused
            # then, after the whole run.
            raise UsageError(f"--record {record} holds --out {args.out}: give them apart")
    inherited = os.environ if environ is None else environ
    if args.no_key and inherited.get(ENCRYPT_ENV, "").strip() == "1":
        raise UsageError(f"{ENCRYPT_ENV}=1 and --no-key do not go together: it takes a key")
    stream = {n: v for n, v in options_of(args, ProjectorParams).items() if n in STREAM_OPTIONS}
    ProjectorParams(**stream)  # each in its range, before anything starts
    until_rounds, until_seconds = continuous_ends(args)
    sources = stream_sources(args, stream, (params.rows, params.cols))
    image, label = image_from(args)
    sense_image(image, params.rows, params.cols, params.profile)  # a too-small image fails here
    images = [image]
    for then in args.then:
        images.append(background(then) if then in BACKGROUNDS else load_image(then))
        sense_image(images[-1], params.rows, params.cols, params.profile)
    env = processes_env(args, inherited)
    deferred = deferred_discovery(env, params.count, bool(remote))
    topics = RunTopics(check_run_id(args.run_id) if args.run_id is not None else new_run_id())
    if args.no_projector:
        projector = None
        # The background is whatever another projector publishes: say so, not the default's name.
        label = f"the background on {topics.background}"
    elif sources:
        stream = {n: str(Path(v).resolve()) if n == "video" else v for n, v in stream.items()}
        # Without --continuous the swarm camouflages once: on the stream's first frame.
        projector = ros_arguments(ProjectorParams(**stream, snapshot=not protocol.continuous))
        label = f"{sources[0].removeprefix('background_')} {stream[sources[0]]}"  # topic /x
    elif args.image is not None:
        projector = ros_arguments(ProjectorParams(image=str(Path(args.image).resolve())))
    else:
        projector = ros_arguments(ProjectorParams(pattern=args.pattern or args.default_pattern))
    folder = out_dir(args)
    env.pop(KEY_FILE_ENV, None)
    env.pop(ENCRYPT_ENV, None)
    if not args.no_key:
        # --key-file's, else the environment's (as for every other camo process), else new.
        given = args.key_file or inherited.get(KEY_FILE_ENV, "").strip() or None
        env[KEY_FILE_ENV] = str(run_key(given, folder))
    if args.encrypt or inherited.get(ENCRYPT_ENV, "").strip() == "1":
        env[ENCRYPT_ENV] = "1"
    return RunConfig(
        params=params,
        procs=procs,
        protocol=protocol,
        image=image,
        labels=[label, *args.then],
        folder=folder,
        env=env,
        projector=projector,
        alone=alone,
        bridges=bridges,
        calibration=calibration,
        record=record,
        foxglove=args.foxglove,
        topics=topics,
        remote=remote,
        named=args.run_id is not None,
        # A continuous run's or a stream's frames are not known in advance: its processes take
        # the frames of the first projector they hear (trust.py).
        digests=[]
        if projector is None or sources or protocol.continuous
        else [image_digest(i) for i in images],
        deferred=deferred,
        until_rounds=until_rounds,
        until_seconds=until_seconds,
    )


def stream_sources(
    args: argparse.Namespace, stream: dict, grid: tuple[int, int] | None = None
) -> list[str]:
    """The stream the run projects (one at most, with neither --image nor --then), its file or
    device opened as the projector will open it: a missing video or camera is one line before
    anything starts, not a projector that fails in a running swarm."""
    sources = [n for n in ("background_topic", "video", "images") if stream.get(n)]
    sources += ["camera"] if stream.get("camera", -1) >= 0 else []  # one: RUN_COMBINATIONS
    opened = open_source(stream, grid) if sources else None  # a topic's name checked, too
    if opened is not None:
        opened.close()
    return sources


def continuous_ends(args: argparse.Namespace):
    """--rounds and --duration, each in its range (only with --continuous: RUN_COMBINATIONS)."""
    if args.rounds is not None and not 1 <= args.rounds <= MAX_ROUNDS:
        raise UsageError(f"--rounds must be an integer in 1..{MAX_ROUNDS} (got {args.rounds})")
    if args.duration is not None and not 0 < args.duration <= MAX_WAIT:
        raise UsageError(f"--duration must be a number in (0, {MAX_WAIT:g}] (got {args.duration})")
    return args.rounds, args.duration


def default_procs(robots: int) -> int:
    return max(os.cpu_count() or 1, -(-robots // ROBOTS_PER_PROCESS))


# From this many robots on, a run on this machine defers discovery (docs/swarm.md, "Set-up").
DEFER_FROM = 4097


def processes_env(args: argparse.Namespace, inherited: dict[str, str]) -> dict[str, str]:
    """The environment of the run's processes: the network's (--domain-id, --network, ...),
    camo's Fast DDS settings, and OpenBLAS without its pool of spinning threads (./camo's
    `activate` says why) however this launcher was started (`ros2 run`, say)."""
    env = network_env(args, inherited)
    use_camo_dds_settings(env)
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    return env


def deferred_discovery(env: dict[str, str], robots: int, remote: bool) -> str | None:
    """For a large swarm on this machine alone: a private discovery server's address, set in
    `env` for every process of the run, or None (simple discovery).

    Creating a node says the process's whole node list anew to every participant that listens:
    thousands of robot nodes created while the others listen cost each listener as much as
    their creator, and the cost grows with the square of the nodes. Clients of a server that
    does not run yet hear nobody; once the server starts, each hears the others' final lists
    once."""
    local = env.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "").upper() == "LOCALHOST"
    if robots < DEFER_FROM or remote or "ROS_DISCOVERY_SERVER" in env or not local:
        return None
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    env["ROS_DISCOVERY_SERVER"] = f"127.0.0.1:{port}"
    env["ROS_SUPER_CLIENT"] = "TRUE"  # a recorder, a view and the launcher list the graph
    return env["ROS_DISCOVERY_SERVER"]


def split_cells(cells: list[int], procs: int) -> list[list[int]]:
    """Robot ids in contiguous blocks, one per process, so neighbours mostly share a process."""
    procs = max(1, min(procs, len(cells)))
    bounds = [round(k * len(cells) / procs) for k in range(procs + 1)]
    return [cells[bounds[k] : bounds[k + 1]] for k in range(procs)]


def worker_groups(config: RunConfig) -> list[list[int]]:
    """The robots of each worker process: one each for --own-process, the rest in blocks (none
    for the bridges' and the remote workers' cells)."""
    params = config.params
    taken = set(config.alone) | set(config.bridges)
    taken |= {c for first, last in config.remote for c in range(first, last + 1)}
    shared = [i for i in range(params.count) if i not in taken]
    return [[i] for i in config.alone] + (split_cells(shared, config.procs) if shared else [])


def run_key(given: str | None, folder: Path) -> Path:
    """The run's key file: the one given (checked), else a new random key in the run's folder."""
    if given:
        read_key_file(given)  # missing, malformed or readable by others: one line, now
        return Path(given).resolve()
    return new_key_file(folder / "run.key").path
