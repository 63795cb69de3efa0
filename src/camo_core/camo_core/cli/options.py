"""Command-line options shared by every command that runs a camouflage (sim, errors, run, ...)."""

from __future__ import annotations

import argparse
import copy
import itertools
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from camo_core.algorithm.backgrounds import BACKGROUNDS, background
from camo_core.algorithm.layout import file_positions
from camo_core.algorithm.params import (
    AUTO,
    ORIENTATIONS,
    PROFILES,
    CamoParams,
    auto_consensus_steps,
)
from camo_core.algorithm.sensing import load_image, with_contrast
from camo_core.exceptions import UsageError


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors, and no abbreviations: `--row` is not `--rows`. With
    `add_params_file_option()`, options can come from a ROS 2 parameters file too."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> None:  # one line, not usage + message
        raise UsageError(message)

    def add_params_file_option(self, node: str) -> None:
        """--params-file FILE: a ROS 2 parameters file whose `/**` and `<node>` keys set options
        (`rho_comm: 0.1` is --rho-comm 0.1); options on the command line override it."""
        self.add_argument(
            "--params-file",
            metavar="FILE",
            type=Path,
            default=None,
            help=f"ROS 2 parameters YAML (keys /** and {node}); the command line overrides it",
        )
        self.set_defaults(params_node=node)

    def parse_with_ros_args(self, argv: list[str] | None = None):
        """(options, ROS arguments) of a node's command line: everything before `--ros-args` is
        ours and must parse (a misspelt option is an error, not a ROS argument); from
        `--ros-args` on it is rclpy's."""
        argv = list(sys.argv[1:] if argv is None else argv)
        at = argv.index("--ros-args") if "--ros-args" in argv else len(argv)
        return self.parse_args(argv[:at]), argv[at:]

    def parse_known_args(self, args=None, namespace=None):
        if not any(a.dest == "params_file" for a in self._actions):  # (a subcommand's, say)
            return super().parse_known_args(args, namespace)
        first, _ = super().parse_known_args(args, copy.copy(namespace))
        path = getattr(first, "params_file", None)
        if path is None:
            return super().parse_known_args(args, namespace)
        from camo_core.cli.params_file import (
            options_from_file,  # the YAML reader, only when a file is given
        )

        # The file's values as defaults, so that what the command line gives wins.
        self.set_defaults(**options_from_file(self, path, first.params_node))
        return super().parse_known_args(args, namespace)


def add_run_options(
    parser: argparse.ArgumentParser, default_pattern: str | None = "forest"
) -> None:
    """The options shared by every command that runs one camouflage (sim, errors, run)."""
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--image", help="background image file (any format OpenCV reads)")
    source.add_argument(
        "--pattern",
        choices=BACKGROUNDS,
        default=None,
        help=f"built-in background (default: {default_pattern})",
    )
    parser.add_argument("--rows", type=int, default=8, help="robot rows (default 8)")
    parser.add_argument("--cols", type=int, default=8, help="robot columns (default 8)")
    parser.add_argument(
        "--profile", choices=PROFILES, default="paper", help="paper or droplet rules"
    )
    parser.add_argument(
        "--seed", type=int, default=0, help="seed of every random draw (default 0)"
    )
    parser.add_argument(
        "--rho-meas", type=float, default=0.0, help="measurement error probability"
    )
    parser.add_argument("--rho-comm", type=float, default=0.0, help="message loss probability")
    parser.add_argument(
        "--threshold",
        type=threshold_or_auto,
        default=50.0,
        metavar="T|auto",
        help="descriptor threshold T (default 50); auto: each robot's from the swarm's mean "
        "texture energy",
    )
    parser.add_argument(
        "--orientation",
        choices=ORIENTATIONS,
        default="axes",
        help="axes: the paper's horizontal and vertical stripes; any: stripes at any multiple "
        "of 15 degrees",
    )
    parser.add_argument(
        "--levels",
        type=int,
        default=0,
        metavar="K",
        help="show K greys (2 to 8) the swarm chooses from its averaged histogram, instead of "
        "black and white (default: the paper's two)",
    )
    parser.add_argument(
        "--layout",
        default=None,
        metavar="hex|jitter:A|FILE",
        help="robots at hexagonal positions, at grid positions jittered by up to A spacings, "
        "or at a CSV file's x,y positions (spacings; a file's robots make one row); needs "
        "--orientation any (default: the grid)",
    )
    parser.add_argument(
        "--consensus-steps",
        type=steps_or_auto,
        default=None,
        metavar="N|auto",
        help="default: 35 paper, 10 droplet; auto: the profile's, scaled with the square of "
        "the grid's diameter over 8x8's",
    )
    parser.add_argument(
        "--formation-steps", type=int, default=None, help="default: 10 paper, 20 droplet"
    )
    add_out_options(parser)
    parser.set_defaults(default_pattern=default_pattern)


def add_out_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--out", type=Path, default=None, help="output folder (default results/<timestamp>/)"
    )
    parser.add_argument(
        "--force", action="store_true", help="write into --out even if it holds something"
    )


def steps_or_auto(value) -> int | str:
    """--consensus-steps: a whole number, or auto (from the command line or a parameters
    file)."""
    if value == AUTO or (isinstance(value, int) and not isinstance(value, bool)):
        return value
    if isinstance(value, str) and value.strip().lstrip("+-").isdigit():
        return int(value)
    raise argparse.ArgumentTypeError(f"a whole number of steps or auto (got {value!r})")


def threshold_or_auto(value) -> float | str:
    """--threshold: a number, or auto (from the command line or a parameters file)."""
    if value == AUTO:
        return value
    try:
        return float(value)
    except (TypeError, ValueError):
        raise argparse.ArgumentTypeError(f"a number or auto (got {value!r})") from None


def layout_options(spec: str | None, rows: int, cols: int) -> dict:
    """--layout (or a node's layout parameter) as CamoParams takes it, with the grid's size: a
    file's positions read, its robots one row."""
    if not spec:
        return {"rows": rows, "cols": cols}
    if spec == "hex" or spec.startswith("jitter:"):
        return {"rows": rows, "cols": cols, "layout": spec}
    positions = file_positions(spec)
    return {"rows": 1, "cols": len(positions), "layout": "file", "positions": positions}


def params_from(args: argparse.Namespace) -> CamoParams:
    where = layout_options(getattr(args, "layout", None), args.rows, args.cols)
    steps = args.consensus_steps
    if steps == AUTO:
        rows, cols = where["rows"], where["cols"]
        if where.get("positions"):  # a file's robots: their extent, not one long row
            extent = np.ptp(np.array(where["positions"]), axis=0)
            rows = cols = math.ceil(float(extent.max())) + 1
        steps = auto_consensus_steps(args.profile, rows, cols)
    auto = args.threshold == AUTO
    return CamoParams(
        profile=args.profile,
        **where,
        threshold=CamoParams.threshold if auto else args.threshold,
        threshold_auto=auto,
        orientation=args.orientation,
        levels=args.levels,
        consensus_steps=steps,
        formation_steps=args.formation_steps,
        seed=args.seed,
        rho_meas=args.rho_meas,
        rho_comm=args.rho_comm,
        w2_stripes=getattr(args, "w2_stripes", None),  # options of ./camo sim alone
        w2_mottled=getattr(args, "w2_mottled", None),
    )


def image_from(args: argparse.Namespace) -> tuple[np.ndarray, str]:
    """The background and its label; with a --contrast (sim's, errors'), at that contrast."""
    if args.image:
        image, label = load_image(args.image), str(args.image)
    else:
        name = args.pattern or args.default_pattern
        image, label = background(name), f"built-in {name}"
    contrast = getattr(args, "contrast", None)
    if contrast is not None:
        image, label = with_contrast(image, contrast), f"{label} at contrast {contrast:g}"
    return image, label


def add_contrast_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--contrast",
        type=float,
        default=None,
        help="scale the background's contrast by this factor in (0, 1] first: each value "
        "pulled toward the image's mean (default: as it is)",
    )


def new_folder_problem(path: Path, what: str = "folder") -> str | None:
    """Why `path` cannot be a new output folder (it exists and holds something), or None."""
    if path.exists() and (not path.is_dir() or any(path.iterdir())):
        return f"{what} {path} already exists and is not empty; choose another name"
    return None


def out_dir(args: argparse.Namespace) -> Path:
    """The output folder, created: --out if given (refused if it holds something, unless
    --force), else a new results/<time>/ (results/<time>-2/ if that is taken)."""
    folder = args.out
    if folder is None:
        stamp = time.strftime("%Y%m%d-%H%M%S")
        folder = Path("results") / stamp
        for k in itertools.count(2):
            if not folder.exists():
                break
            folder = Path("results") / f"{stamp}-{k}"
    elif not getattr(args, "force", False):
        problem = new_folder_problem(folder, "output folder")
        if problem:
            raise UsageError(f"{problem} (or --force to write into it)")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"cannot create output folder {folder}: {exc.strerror}") from None
    return folder


def wants_help(argv: list[str] | None) -> bool:
    """-h or --help before any --ros-args: a ROS node's own arguments end there."""
    args = sys.argv[1:] if argv is None else list(argv)
    if "--ros-args" in args:
        args = args[: args.index("--ros-args")]
    return "-h" in args or "--help" in args


def node_help(prog: str, description: str, parameters: dict[str, object]) -> str:
    """The --help text of a node configured by ROS parameters (ros2 run's conventions)."""
    lines = [
        f"usage: {prog} [--domain-id D] [--network localhost|subnet] [--discovery-server "
        "HOST:PORT] [--ros-args [-p NAME:=VALUE ...] [--params-file FILE] ...]",
        "",
    ]
    lines.append(description)
    if parameters:
        lines += ["", "parameters (default):"]
        lines += [f"  {name} ({value!r})" for name, value in parameters.items()]
    return "\n".join(lines)


def node_command_line(prog: str, args: list[str] | None) -> list[str]:
    """A ROS node's command line (argv, program first): the domain and network options before
    --ros-args set its environment (UsageError if bad); what rclpy takes is returned."""
    argv = list(sys.argv if args is None else args)
    ours, ros = argv, []
    if "--ros-args" in argv:
        at = argv.index("--ros-args")
        ours, ros = argv[:at], argv[at:]
    parser = Parser(prog=prog)
    add_network_options(parser)
    options, unknown = parser.parse_known_args(ours[1:])
    if unknown:
        raise UsageError(
            f"unrecognized arguments: {' '.join(unknown)} (parameters go after --ros-args: "
            "-p NAME:=VALUE or --params-file FILE)"
        )
    os.environ.update(network_env(options, os.environ))
    return [ours[0] if ours else prog, *ros]


# ---- how a process finds the others: DDS discovery ----------------------------------------

NETWORKS = ("localhost", "subnet")


def add_network_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--network",
        choices=NETWORKS,
        default=None,
        help="discovery range: localhost (this machine only, the default) or subnet "
        "(multicast on the LAN: robots on several machines)",
    )
    parser.add_argument(
        "--discovery-server",
        metavar="HOST:PORT",
        default=None,
        help="use this Fast DDS discovery server (./camo discovery-server) instead of multicast",
    )
    parser.add_argument(
        "--domain-id", type=int, default=None, help="ROS_DOMAIN_ID (default: inherited, else 0)"
    )


def network_env(args: argparse.Namespace, environ: dict[str, str]) -> dict[str, str]:
    """The environment a ROS process of ours runs in, from --network, --discovery-server and
    --domain-id (raises UsageError)."""
    env = dict(environ)
    if args.domain_id is not None:
        if not 0 <= args.domain_id <= 232:
            raise UsageError(f"--domain-id must be in 0..232 (got {args.domain_id})")
        env["ROS_DOMAIN_ID"] = str(args.domain_id)
    if args.network is not None:
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = args.network.upper()
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if args.discovery_server is not None:
        host, _, port = args.discovery_server.rpartition(":")
        if not host or not port.isdigit() or not 0 < int(port) < 65536:
            raise UsageError(f"--discovery-server takes HOST:PORT (got {args.discovery_server!r})")
        env["ROS_DISCOVERY_SERVER"] = args.discovery_server
        # A server tells plain clients only of endpoints that match theirs; tools that list the
        # graph (a recorder, a worker looking for its run) must see everything.
        env["ROS_SUPER_CLIENT"] = "TRUE"
    return env


def parse_ranges(texts: list[str], count: int, option: str = "--cells") -> list[tuple[int, int]]:
    """FIRST-LAST options (robot ids, inclusive; a single id is a range of one) as sorted,
    non-overlapping ranges inside 0..count-1."""
    ranges = []
    for text in texts:
        first, dash, last = text.partition("-")
        try:
            a, b = int(first), int(last if dash else first)
        except ValueError:
            raise UsageError(f"{option} takes FIRST-LAST, robot ids (got {text!r})") from None
        if not 0 <= a <= b < count:
            raise UsageError(
                f"{option} {text}: robot ids run from 0 to {count - 1}, first <= last"
            )
        ranges.append((a, b))
    ranges.sort()
    for (_, b), (c, _) in itertools.pairwise(ranges):
        if c <= b:
            raise UsageError(f"{option}: ranges overlap at robot {c}")
    return ranges


def contiguous(cells: list[int]) -> list[tuple[int, int]]:
    """Sorted robot ids as (first, last) runs of consecutive ids."""
    runs: list[tuple[int, int]] = []
    for cell in sorted(cells):
        if runs and cell == runs[-1][1] + 1:
            runs[-1] = (runs[-1][0], cell)
        else:
            runs.append((cell, cell))
    return runs
