"""The swarm's topics in one place: run identities, names, QoS profiles and the wire form of
images.

Robots, workers, the monitor, the projector, recorders and viewers all take
their topic names and QoS from here, so that they always match.
"""

from __future__ import annotations

import json
import os
import re
import secrets
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import rclpy
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image

from camo_core.algorithm.params import CamoParams, ParameterError
from camo_core.cli.options import node_command_line
from camo_core.cli.params_file import check_ros_args
from camo_core.exceptions import EXIT_USAGE, CamoError, UsageError
from camo_nodes.shm import remove_stale

FASTDDS_PROFILE = Path(__file__).with_name("fastdds.xml")


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
    remove_stale()  # a port file a killed process left empty would hang this one (shm.py)
    try:
        if node_options:
            args = node_command_line(prog, args)
        check_ros_args(sys.argv if args is None else args)
        try:
            rclpy.init(args=args, **options)
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


RUN_ID = re.compile(r"^[a-z][a-z0-9_]{0,39}$")
PARAMS_SUFFIX = "/swarm/params"


class RunIdError(CamoError):
    """A run id that cannot name ROS topics."""


def check_run_id(run_id: str) -> str:
    if not RUN_ID.match(run_id):
        raise RunIdError(
            f"a run id is a lowercase letter then up to 39 lowercase letters, digits or _ "
            f"(got {run_id!r})"
        )
    return run_id


def new_run_id() -> str:
    """Unique per run, so that two runs in one domain never share a topic."""
    return f"run_{secrets.token_hex(3)}"


@dataclass(frozen=True)
class RunTopics:
    """Every topic of one run lives under /<run id>/: runs in one domain never meet.

    /<run>/swarm/ holds what the run says of itself (parameters, statuses, the
    pattern, the recording's ledger); /<run>/camo/ what the robots and the
    projector exchange: the background, and per tile of robots (the robots one
    process hosts) four topics of its edge robots (those with a neighbour in
    another process) and four of the rest."""

    run: str

    def __post_init__(self) -> None:
        check_run_id(self.run)

    @property
    def swarm_namespace(self) -> str:
        return f"/{self.run}/swarm"

    @property
    def robot_namespace(self) -> str:
        return f"/{self.run}/camo"

    @property
    def params(self) -> str:
        """std_msgs/String, latched: the run's parameters and backgrounds as JSON."""
        return f"/{self.run}{PARAMS_SUFFIX}"

    @property
    def status(self) -> str:
        return f"/{self.run}/swarm/status"

    @property
    def pattern(self) -> str:
        return f"/{self.run}/swarm/pattern"

    @property
    def markers(self) -> str:
        return f"/{self.run}/swarm/markers"

    @property
    def diagnostics(self) -> str:
        return f"/{self.run}/diagnostics"

    @property
    def recorded(self) -> str:
        """std_msgs/String, latched: what a recorder holds of the run, per round (JSON)."""
        return f"/{self.run}/swarm/recorded"

    @property
    def result(self) -> str:
        """std_msgs/String, latched: the launcher's last word on the run (JSON, `result_from`)."""
        return f"/{self.run}/swarm/result"

    @property
    def background(self) -> str:
        return f"/{self.run}/camo/background"

    @property
    def load(self) -> str:
        """std_msgs/String: a built-in background name or an image path for the projector."""
        return f"/{self.run}/camo/projector/load"

    @property
    def hosts(self) -> str:
        """camo_msgs/Host, latched: which robots each process hosts."""
        return f"/{self.run}/camo/hosts"

    def tile(self, tile: str, part: str, kind: str) -> str:
        """A tile's robot messages: part is "edge" or "core", kind hello, color, energy (with
        --threshold auto), vote or state."""
        return f"/{self.run}/camo/{tile}/{part}/{kind}"


def tile_name(first: int, last: int) -> str:
    return f"tile_{first}_{last}"


def runs_on_graph(topic_names: list[str]) -> list[str]:
    """The run ids whose parameters topic is on the graph (from get_topic_names_and_types)."""
    return sorted(
        name[1 : -len(PARAMS_SUFFIX)]
        for name in topic_names
        if name.endswith(PARAMS_SUFFIX) and name.count("/") == 3
    )


class NoRun(CamoError):
    """No run (or not the one asked for) appeared in time."""


def wait_for_run(node, spin, run_id: str | None, timeout: float, stop=None) -> str:
    """The run to join: `run_id` once its parameters are published, or without one the only run
    whose parameters are. `spin()` lets the node take in discovery."""
    deadline = time.monotonic() + timeout
    while not stop:
        names = [name for name, _ in node.get_topic_names_and_types()]
        live = [r for r in runs_on_graph(names) if node.count_publishers(RunTopics(r).params)]
        if run_id is not None and run_id in live:
            return run_id
        if run_id is None and len(live) == 1:
            return live[0]
        if run_id is None and len(live) > 1:
            raise NoRun(
                f"several runs in this domain ({', '.join(live)}): choose one with --run-id"
            )
        if time.monotonic() > deadline:
            wanted = f"run {run_id}" if run_id else "run"
            raise NoRun(f"no {wanted} found in {timeout:g} s (check the domain id and network)")
        spin()
    raise KeyboardInterrupt


# Parameters every rclpy node has, which no node of ours declares.
ROS_OWN_PARAMETERS = {"use_sim_time", "start_type_description_service"}


def _kind(value) -> str:
    return {bool: "a bool", int: "an integer", float: "a number", str: "text"}.get(
        type(value), type(value).__name__
    )


def node_parameters(node, defaults: dict) -> dict:
    """A node's ROS parameters (-p, --params-file), each declared with its default. An integer
    where a number is expected is taken as that number; any other value of the wrong kind, or a
    parameter given to this node that it does not have, is a ParameterError in one line (rclpy
    would raise a traceback, or ignore it)."""
    values = {}
    for name, default in defaults.items():
        descriptor = ParameterDescriptor(dynamic_typing=True)
        value = node.declare_parameter(name, default, descriptor).value
        if isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if type(value) is not type(default):
            raise ParameterError(f"{name} must be {_kind(default)} (got {value!r})")
        values[name] = value
    # rclpy keeps the overrides meant for this node here (no public accessor in Jazzy).
    given = set(getattr(node, "_parameter_overrides", {}))
    unknown = sorted(given - set(defaults) - ROS_OWN_PARAMETERS)
    if unknown:
        raise ParameterError(
            f"{node.get_name()} has no parameter {unknown[0]} (it has: {', '.join(defaults)})"
        )
    return values


def run_from_parameter(node, stop=None, timeout: float = 60.0) -> RunTopics:
    """The run a standalone node joins: its `run_id` parameter (declared here if it is not), or
    without one the only run in its domain."""
    if not node.has_parameter("run_id"):
        node.declare_parameter("run_id", "")
    wanted = node.get_parameter("run_id").value
    if wanted:
        return RunTopics(check_run_id(wanted))

    def spin() -> None:
        rclpy.spin_once(node, timeout_sec=0.1)

    return RunTopics(wait_for_run(node, spin, None, timeout, stop))


def run_ended(node, topics: RunTopics, period: float = 0.5):
    """A check, cheap to call often: has the run's launcher (the writer of its parameters when
    first seen) gone, after it was there? A stranger writing there later does not keep a run
    alive. A run started without a launcher never ends this way."""
    state: dict = {"launcher": None, "checked": 0.0}

    def ended() -> bool:
        now = time.monotonic()
        if now - state["checked"] < period:
            return False
        state["checked"] = now
        writers = {bytes(p.endpoint_gid) for p in node.get_publishers_info_by_topic(topics.params)}
        if state["launcher"] is None:
            state["launcher"] = writers or None
            return False
        return not state["launcher"] & writers

    return ended


def setup_from(text: str, run: str) -> dict | None:
    """Run `run`'s parameters message, or None if it is not one (a stranger's, say)."""
    try:
        setup = json.loads(text)
        CamoParams(**setup["params"])
        ranges = [*setup.get("tiles", []), *setup.get("remote", [])]
        valid = (
            setup["run"] == run
            and isinstance(setup["backgrounds"], list)
            and float(setup["step_timeout"]) > 0
            and float(setup["discovery_timeout"]) > 0
            and all(len(r) == 2 and all(isinstance(x, int) for x in r) for r in ranges)
            and all(isinstance(x, int) for x in setup.get("bridged", []))
        )
    except (ValueError, KeyError, TypeError, CamoError):
        return None
    return setup if valid else None


def result_from(text: str, run: str) -> dict | None:
    """Run `run`'s result message, or None if it is not one. It says how the run ended and, per
    round it ran, which robots finished and which died (as [first, last] ranges) and what was
    refused: {"run", "ended", "rounds": [{"finished", "dead", "rejected_messages"}]}."""
    try:
        result = json.loads(text)
        rounds = result["rounds"]
        valid = result["run"] == run and all(
            all(len(r) == 2 and all(isinstance(x, int) for x in r) for r in entry[key])
            for entry in rounds
            for key in ("finished", "dead")
        )
    except (ValueError, KeyError, TypeError):
        return None
    return result if valid else None


# Nodes with no parameter, rosout or type-description services: no DDS entities of their own
# (hosted robots, and short-lived helper nodes).
LEAN_NODE = {
    "start_parameter_services": False,
    "enable_rosout": False,
    "parameter_overrides": [Parameter("start_type_description_service", value=False)],
}

# Latched: a robot that starts late still gets the background that is up.
LATCHED = QoSProfile(
    depth=1,
    history=HistoryPolicy.KEEP_LAST,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)

# A reader of a latched topic that anyone in the domain can write to: it keeps every sample
# until taken, so that a stranger's flood cannot push the rightful writer's sample out.
LATCHED_READER = QoSProfile(
    depth=1,
    history=HistoryPolicy.KEEP_ALL,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)


def history_qos(depth: int) -> QoSProfile:
    """Reliable and transient-local: a neighbour that starts late still gets every step's
    message."""
    return QoSProfile(
        depth=depth,
        history=HistoryPolicy.KEEP_LAST,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )


# ---- images on the wire: numpy <-> sensor_msgs/Image (8-bit grey or BGR) ---------------------


class ImageEncodingError(CamoError):
    """An Image message in an encoding the swarm does not read."""


def image_to_msg(image: np.ndarray, frame_id: str = "arena") -> Image:
    msg = Image()
    msg.header.frame_id = frame_id
    msg.height, msg.width = int(image.shape[0]), int(image.shape[1])
    msg.encoding = "mono8" if image.ndim == 2 else "bgr8"
    msg.is_bigendian = 0
    msg.step = msg.width * (1 if image.ndim == 2 else 3)
    msg.data = np.ascontiguousarray(image, dtype=np.uint8).tobytes()
    return msg


def image_from_msg(msg: Image) -> np.ndarray:
    channels = {"mono8": 1, "bgr8": 3, "rgb8": 3}.get(msg.encoding)
    if channels is None:
        raise ImageEncodingError(
            f"unsupported image encoding {msg.encoding!r} (mono8, bgr8, rgb8)"
        )
    if msg.height * msg.step != len(msg.data) or msg.step < msg.width * channels:
        raise ImageEncodingError(
            f"an image of {msg.width}x{msg.height} with step {msg.step} cannot hold "
            f"{len(msg.data)} bytes"
        )
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(msg.height, msg.step)
    data = data[:, : msg.width * channels]
    if channels == 1:
        return data.copy()
    image = data.reshape(msg.height, msg.width, 3)
    return (image[:, :, ::-1] if msg.encoding == "rgb8" else image).copy()
