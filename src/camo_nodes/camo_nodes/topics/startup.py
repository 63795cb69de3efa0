"""How a process of a run starts: rclpy with camo's DDS settings, its network and domain from
the command line, and one-line errors for what rcl refuses.

DDS reads its settings from the environment (ROS_DOMAIN_ID, ROS_AUTOMATIC_DISCOVERY_RANGE,
ROS_DISCOVERY_SERVER, ROS_SUPER_CLIENT, FASTRTPS_DEFAULT_PROFILES_FILE): this module is the one
place that sets them.
"""

from __future__ import annotations

import argparse
import ipaddress
import os
import re
import socket
import sys
import time
from collections.abc import Mapping
from pathlib import Path

import rclpy
from rclpy.context import Context
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions

from camo_core.cli.options import Combination, Parser
from camo_core.cli.params_file import check_ros_args
from camo_core.exceptions import EXIT_USAGE, UsageError
from camo_core.inputs.files import shown
from camo_core.inputs.numeric import INTEGER
from camo_core.shm import remove_stale
from camo_core.shutdown import stacks_on_faults
from camo_core.swarm.keys import ENCRYPT_ENV, KEY_FILE_ENV, read_key_file

FASTDDS_PROFILE = Path(__file__).parent.parent / "fastdds.xml"


def use_camo_dds_settings(environ=os.environ) -> None:
    """Before rclpy.init in a process of ours (and in the environment of the processes it
    starts): camo's Fast DDS settings (fastdds.xml: quicker discovery, roomier readers), unless
    the user has a profiles file of their own."""
    environ.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE", str(FASTDDS_PROFILE))


def start_ros(
    prog: str, args: list[str] | None = None, node_options: bool = False, **options
) -> None:
    """rclpy.init for a process of ours, with camo's DDS settings. With `node_options`, `args`
    is a node's whole command line, whose domain and network options before --ros-args set
    its environment first. Parameters files are checked before rcl reads them, and what rcl
    refuses is said in one line (rcl's text without its source locations): `prog: error: ...`
    and exit code 2, as for any bad command line."""
    use_camo_dds_settings()
    stacks_on_faults()
    remove_stale()  # a port file a killed process left empty would hang this one (shm.py)
    try:
        if node_options:
            args = node_command_line(prog, args)
        check_ros_args(sys.argv if args is None else args)
        try:
            _init_holding_rcl_log(args, options)
        except _rclpy.RCLError as exc:
            text = re.sub(r", at /\S+:\d+", "", str(exc)).removeprefix(
                "failed to initialize rcl: "
            )
            raise UsageError(f"ROS arguments refused: {' '.join(text.split())}") from None
        except _rclpy.UnknownROSArgsError as exc:  # `--ros-args --help`, say: not an RCLError
            unknown = " ".join(re.findall(r"'([^']*)'", str(exc))) or str(exc)  # "['--help']"
            raise UsageError(f"unknown ROS arguments after --ros-args: {unknown}") from None
    except UsageError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        raise SystemExit(EXIT_USAGE) from None


def _init_holding_rcl_log(args: list[str] | None, options: dict) -> None:
    """rclpy.init, with what rcl logs on stderr meanwhile held back: when it refuses the
    arguments, its "[ERROR] [rcl]: Failed to parse global arguments" would stand above camo's
    one line, which says the same; when it starts, what it wrote is written out as it came."""
    from camo_core.inputs.images import captured_stderr

    def init():
        try:
            rclpy.init(args=args, **options)
        except (_rclpy.RCLError, _rclpy.UnknownROSArgsError) as exc:
            return exc
        return None

    refused, text = captured_stderr(init)
    if refused is not None:
        raise refused
    if text:
        sys.stderr.write(text)


# Nodes with no parameter, rosout or type-description services: no DDS entities of their own
# (hosted robots, and short-lived helper nodes).
LEAN_NODE = {
    "start_parameter_services": False,
    "enable_rosout": False,
    "parameter_overrides": [Parameter("start_type_description_service", value=False)],
}


GROUPED_NODE = {"use_global_arguments": False}

# Lean nodes per DDS participant when a process creates thousands. rmw_fastrtps publishes a
# participant's whole node list each time one of its nodes is created, so creating n nodes in
# one participant costs time that grows with n^2: alone, 8192 lean robot nodes took 4.3 s in one
# participant here, 2.1 s in four of 2048 and 1.8 s in eight of 1024, but every participant
# costs discovery and memory too (docs/swarm.md).
NODES_PER_PARTICIPANT = 2048


class Participants:
    """The contexts (a DDS participant each) a process creates many lean nodes in: the first
    `per` in `first` (the process's own), then `per` more in each further one, with the first's
    domain. Nodes spread so take `GROUPED_NODE` too: the command line's
    remappings and parameters, which only the first context has, would otherwise apply to
    some of them and not others. `shutdown()` ends the further ones once their nodes are
    destroyed."""

    def __init__(self, first: Context, per: int = NODES_PER_PARTICIPANT) -> None:
        self.per = per
        self.created = 0
        self.contexts = [first]

    def next(self) -> Context:
        """The context for the next node."""
        if self.created and self.created % self.per == 0:
            context = Context()
            domain = self.contexts[0].get_domain_id()
            # No command-line arguments (nodes given `GROUPED_NODE` take none in any context),
            # and the process's signal handlers stay the first context's.
            rclpy.init(
                args=[],
                context=context,
                domain_id=domain,
                signal_handler_options=SignalHandlerOptions.NO,
            )
            self.contexts.append(context)
        self.created += 1
        return self.contexts[-1]

    def shutdown(self) -> None:
        for context in self.contexts[1:]:
            context.try_shutdown()


def wants_help(argv: list[str] | None) -> bool:
    """-h or --help before any --ros-args: a ROS node's own arguments end there."""
    args = sys.argv[1:] if argv is None else list(argv)
    if "--ros-args" in args:
        args = args[: args.index("--ros-args")]
    return "-h" in args or "--help" in args


def node_help(prog: str, description: str, parameters: list[str]) -> str:
    """The --help text of a node configured by ROS parameters (ros2 run's conventions);
    `parameters`: a line each (topics.parameters.parameters_help)."""
    lines = [
        f"usage: {prog} [--domain-id D] [--network localhost|subnet] [--discovery-server "
        "HOST:PORT] [--ros-args [-p NAME:=VALUE ...] [--params-file FILE] ...]",
        "",
    ]
    lines.append(description)
    if parameters:
        lines += ["", "parameters (default):"]
        lines += [f"  {line}" for line in parameters]
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
DISCOVERY_RANGES = ("LOCALHOST", "SUBNET", "OFF", "SYSTEM_DEFAULT")  # rcl's, for the variable
MAX_DOMAIN_ID = 232  # rcl's limit with Fast DDS's default ports


MAX_PEER_CHARS = 255  # of one static peer, as rmw's RMW_DISCOVERY_OPTIONS_STATIC_PEERS_MAX_LENGTH
HOST_LABEL = re.compile(r"(?!-)[A-Za-z0-9-]{1,63}(?<!-)", re.ASCII)


def check_static_peers(value: str) -> None:
    """ROS_STATIC_PEERS as rcl reads it: `;`-separated host names (RFC 1123) or IP addresses.
    Empty entries (`a;;b`, a trailing `;`) are ignored, as rcl's split ignores them; anything
    else is a UsageError here, not an RCLError traceback when the first node is created."""
    for peer in value.split(";"):
        peer = peer.strip()
        if not peer:
            continue
        try:
            ipaddress.ip_address(peer)
            continue
        except ValueError:
            pass
        labels = peer.removesuffix(".").split(".")
        if len(peer) > MAX_PEER_CHARS or not all(HOST_LABEL.fullmatch(x) for x in labels):
            raise UsageError(
                f"ROS_STATIC_PEERS: {shown(peer)!r} is not a host name or an IP address "
                "(want NAME-OR-IP;NAME-OR-IP...): fix or unset it"
            )


def _is_host(host: str) -> bool:
    """An IP address or a host name (RFC 1123)."""
    try:
        ipaddress.ip_address(host)
        return True
    except ValueError:
        labels = host.removesuffix(".").split(".")
        return len(host) <= MAX_PEER_CHARS and all(HOST_LABEL.fullmatch(x) for x in labels)


def check_discovery_servers(value: str) -> None:
    """ROS_DISCOVERY_SERVER as Fast DDS reads it: `;`-separated HOST or HOST:PORT ([IPv6]:PORT),
    an empty entry keeping a server's place. Anything else leaves every process searching for
    servers that are not there: a run that waits for good, so a UsageError here."""
    if value.strip() and not value.replace(";", "").strip():
        raise UsageError(
            f"ROS_DISCOVERY_SERVER {shown(value)!r} names no server (want HOST:PORT;...): "
            "fix or unset it, or give --discovery-server"
        )
    for entry in value.split(";"):
        entry = entry.strip()
        if not entry:
            continue
        host, port = entry, ""
        bracketed = re.fullmatch(r"\[([^\]]+)\](?::(.*))?", entry)
        if bracketed:
            host, port = bracketed[1], bracketed[2] or ""
        elif entry.count(":") == 1:
            host, port = entry.split(":")
        good_port = not port or (INTEGER.fullmatch(port) and 0 < int(port) < 65536)
        if not (_is_host(host) and good_port):
            raise UsageError(
                f"ROS_DISCOVERY_SERVER: {shown(entry)!r} is not HOST or HOST:PORT (want "
                "HOST:PORT;HOST:PORT...): fix or unset it, or give --discovery-server"
            )


# Variables read as a yes or a no, and what they take.
SWITCHES = {
    "ROS_SUPER_CLIENT": ("TRUE", "FALSE", "true", "false", "1", "0"),
    "ROS_LOCALHOST_ONLY": ("0", "1"),
    ENCRYPT_ENV: ("0", "1"),
}


def check_environment(env: dict[str, str]) -> None:
    """What DDS and camo read from the environment on a process's behalf, besides the domain,
    the discovery range, static peers and the RMW: a value they would misread or pass over
    without a word is one line here, before rcl starts."""
    check_discovery_servers(env.get("ROS_DISCOVERY_SERVER", ""))
    for name, values in SWITCHES.items():
        value = env.get(name, "").strip()
        if value and value not in values:
            raise UsageError(
                f"{name} must be one of {', '.join(values)} (got {shown(value)!r}): "
                "fix or unset it"
            )
    for name in ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE"):
        profiles = env.get(name, "").strip()
        if profiles:
            _check_profiles_file(Path(profiles), name)
    for name in ("ROS_LOG_DIR", "ROS_HOME"):  # rcl makes its log folder there, or fails
        if env.get(name, "").strip():
            _check_writable_folder(Path(env[name]), name)
    if env.get(KEY_FILE_ENV):
        read_key_file(env[KEY_FILE_ENV])  # missing, malformed or readable by others: one line


def _check_writable_folder(path: Path, name: str) -> None:
    """A folder rcl writes into (its logs): one there, or one it can make, that it may write."""
    where = f"{name} {shown(path)}"
    there = path if path.exists() else next((p for p in path.parents if p.exists()), None)
    if there is None or not there.is_dir():
        raise UsageError(f"{where} is not a folder (nor under one): fix or unset it")
    if not os.access(there, os.W_OK | os.X_OK):
        raise UsageError(f"{where}: {shown(there)} may not be written: fix or unset it")


def _check_profiles_file(path: Path, name: str = "FASTRTPS_DEFAULT_PROFILES_FILE") -> None:
    """FASTRTPS_DEFAULT_PROFILES_FILE (or FASTDDS_...): Fast DDS passes over a file it cannot
    load, leaving the user's settings unapplied without a word: it must be there and be XML."""
    import xml.etree.ElementTree as ElementTree

    where = f"{name} {shown(path)}"
    if not path.is_file():
        raise UsageError(f"{where} is not a file: fix or unset it")
    try:
        if path.stat().st_size > 16 * 1024 * 1024:
            raise UsageError(f"{where} is over 16 MiB: not a Fast DDS profiles file")
        ElementTree.parse(path)
    except ElementTree.ParseError as exc:
        raise UsageError(f"{where} is not XML ({exc}): fix or unset it") from None
    except OSError as exc:
        raise UsageError(f"cannot read {where}: {exc.strerror}") from None


def installed_rmws(ament_prefix_path: str) -> set[str]:
    """The RMW implementations installed: those the ament index of a prefix names
    (resource type rmw_typesupport, as rmw_implementation finds them) whose library is there."""
    found = set()
    for prefix in filter(None, ament_prefix_path.split(os.pathsep)):
        index = Path(prefix, "share", "ament_index", "resource_index", "rmw_typesupport")
        if not index.is_dir():
            continue
        for entry in index.iterdir():
            if (
                entry.name != "rmw_implementation"
                and Path(prefix, "lib", f"lib{entry.name}.so").exists()
            ):
                found.add(entry.name)
    return found


def check_rmw(value: str, ament_prefix_path: str) -> None:
    """RMW_IMPLEMENTATION empty (the default, Fast DDS) or one that is installed; else a
    UsageError, not rcl's exit 102 (which rcl does as soon as rclpy is imported: the camo script
    checks the same rule before Python starts; this is for an environment given to a child).
    Blanks are no name: rcl takes " " for one, and so do we."""
    if not value:
        return
    known = installed_rmws(ament_prefix_path)
    if value not in known:
        have = ", ".join(sorted(known)) or "none found on AMENT_PREFIX_PATH"
        raise UsageError(
            f"RMW_IMPLEMENTATION={shown(value)!r} is not installed (installed: {have}): "
            "unset it or name one of those"
        )


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
    if isinstance(parser, Parser):  # a server is found by its address, not by a range
        parser.combine(Combination("--discovery-server", excludes=("--network",)))
    parser.add_argument(
        "--key-file",
        metavar="FILE",
        default=None,
        help="the run's key file (run.key beside its results, 0600): only messages tagged with "
        f"it are believed, and this process's are tagged (default: ${KEY_FILE_ENV} if set)",
    )


RESOLVE_WAIT = 20.0  # s a server's name is tried for: a container's may come up a moment late


def server_address(host: str, given: str) -> str:
    """A discovery server's host as Fast DDS is given it: an IP address. A name is resolved
    here, tried again for RESOLVE_WAIT: Fast DDS resolves it once, as the participant starts,
    and a process whose lookup failed (a compose network's name not served yet) said so in a
    log line and searched for no server, for good. A name that never resolves is one line."""
    bare = host.removeprefix("[").removesuffix("]")
    try:
        ipaddress.ip_address(bare)
        return host
    except ValueError:
        pass
    deadline = time.monotonic() + RESOLVE_WAIT
    while True:
        try:
            found = socket.getaddrinfo(host, None, socket.AF_INET, socket.SOCK_DGRAM)
            return str(found[0][4][0])
        except (OSError, UnicodeError) as exc:
            if time.monotonic() >= deadline:
                said = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
                raise UsageError(
                    f"--discovery-server {shown(given)}: {shown(host)!r} has no IPv4 address "
                    f"({said})"
                ) from None
        time.sleep(0.5)


def inherited_domain(environ: Mapping[str, str]) -> int | None:
    """The ROS_DOMAIN_ID the environment sets (None where it does not; UsageError if it is not
    a domain id)."""
    inherited = environ.get("ROS_DOMAIN_ID", "").strip()
    if not inherited:
        return None
    whole = inherited.isascii() and inherited.isdigit() and len(inherited) <= 3
    if not (whole and int(inherited) <= MAX_DOMAIN_ID):
        raise UsageError(
            f"ROS_DOMAIN_ID must be an integer in 0..{MAX_DOMAIN_ID} (got "
            f"{shown(inherited)!r}): unset it or give --domain-id"
        )
    return int(inherited)


def bench_domain(first: int, count: int, environ: Mapping[str, str] = os.environ) -> int:
    """The ROS domain a benchmark runs its swarms in: the environment's ROS_DOMAIN_ID where it
    sets one (a test's, or one chosen for it), else one of `count` domains from `first` that
    its pid picks, away from domain 0's runs (UsageError if ROS_DOMAIN_ID is not a domain)."""
    inherited = inherited_domain(environ)
    return inherited if inherited is not None else first + os.getpid() % count


def network_env(args: argparse.Namespace, environ: dict[str, str]) -> dict[str, str]:
    """The environment a ROS process of ours runs in, from --network, --discovery-server and
    --domain-id (raises UsageError)."""
    env = dict(environ)
    if getattr(args, "key_file", None):
        read_key_file(args.key_file)  # missing, malformed or readable by others: one line
        env[KEY_FILE_ENV] = str(Path(args.key_file).resolve())
    if args.domain_id is None:
        inherited_domain(env)
    if args.network is None:
        inherited = env.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "").strip().upper()
        if inherited and inherited not in DISCOVERY_RANGES:
            raise UsageError(
                f"ROS_AUTOMATIC_DISCOVERY_RANGE must be one of {', '.join(DISCOVERY_RANGES)} "
                f"(got {shown(env['ROS_AUTOMATIC_DISCOVERY_RANGE'])!r}): unset it or give "
                "--network"
            )
        if inherited == "OFF":
            raise UsageError(
                "ROS_AUTOMATIC_DISCOVERY_RANGE=OFF: a run's processes could not find each other; "
                "unset it or give --network"
            )
        if inherited:
            env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = inherited
        else:
            env.pop("ROS_AUTOMATIC_DISCOVERY_RANGE", None)  # "" is the default, as unset
    if args.domain_id is not None:
        if not 0 <= args.domain_id <= 232:
            raise UsageError(f"--domain-id must be in 0..{MAX_DOMAIN_ID} (got {args.domain_id})")
        env["ROS_DOMAIN_ID"] = str(args.domain_id)
    if args.network is not None:
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = args.network.upper()
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    check_static_peers(env.get("ROS_STATIC_PEERS", ""))
    check_rmw(env.get("RMW_IMPLEMENTATION", ""), env.get("AMENT_PREFIX_PATH", ""))
    if args.discovery_server is not None:
        host, _, port = args.discovery_server.rpartition(":")
        if not host or not INTEGER.fullmatch(port) or not 0 < int(port) < 65536:
            raise UsageError(f"--discovery-server takes HOST:PORT (got {args.discovery_server!r})")
        env["ROS_DISCOVERY_SERVER"] = f"{server_address(host, args.discovery_server)}:{port}"
        # A server tells plain clients only of endpoints that match theirs; tools that list the
        # graph (a recorder, a worker looking for its run) must see everything.
        env["ROS_SUPER_CLIENT"] = "TRUE"
    check_environment(env)  # what the options left of the inherited environment
    return env
