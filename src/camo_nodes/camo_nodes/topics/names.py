"""A run's topics: run ids, names under /<run id>/, and the tiles robots publish on."""

from __future__ import annotations

import re
import secrets
from dataclasses import dataclass

from camo_core.exceptions import CamoError

RUN_ID = re.compile(r"[a-z][a-z0-9_]{0,39}")  # the whole id (fullmatch: no newline after)
PARAMS_SUFFIX = "/swarm/params"


class RunIdError(CamoError):
    """A run id that cannot name ROS topics."""


def check_run_id(run_id: str) -> str:
    if not (isinstance(run_id, str) and RUN_ID.fullmatch(run_id)):
        raise RunIdError(
            f"a run id is a lowercase letter then up to 39 lowercase letters, digits or _ "
            f"(got {run_id!r})"
        )
    return run_id


class TopicNameError(CamoError):
    """A topic name the user gave that ROS would refuse."""


def check_topic_name(name: str, what: str) -> str:
    """A topic name the user gave (`what`: where), checked by rclpy's own rules before any node
    would take it: one line, where rclpy raises a message of three with a caret."""
    from rclpy.exceptions import InvalidTopicNameException
    from rclpy.expand_topic_name import expand_topic_name
    from rclpy.validate_full_topic_name import validate_full_topic_name
    from rclpy.validate_topic_name import validate_topic_name

    try:
        validate_topic_name(name)
        # As a node at the root would take it (a relative name under its namespace): the
        # length DDS allows is checked on the full name.
        validate_full_topic_name(expand_topic_name(name, "camo", "/"))
    except (InvalidTopicNameException, ValueError) as exc:  # (an unknown {substitution})
        reason = str(exc).splitlines()[0].removeprefix("Invalid topic name: ").rstrip(":")
        reason = reason.removeprefix(f"topic name {name!r} is invalid: ").split(", at /")[0]
        reason = reason.replace("'255U - 8U'", "247 characters")  # rmw's limit, as C says it
        shown = repr(name) if len(name) <= 80 else repr(name[:80]) + "..."
        raise TopicNameError(f"{what} {shown} is not a ROS topic name: {reason}") from None
    return name


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
    def camouflage(self) -> str:
        """camo_msgs/action/Camouflage: camouflage on an image, and follow it (the launcher's)."""
        return f"/{self.run}/swarm/camouflage"

    @property
    def hosts(self) -> str:
        """camo_msgs/Host, latched: which robots each process hosts."""
        return f"/{self.run}/camo/hosts"

    @property
    def notices(self) -> str:
        """camo_msgs/Notices, latched: robots that noticed a changed scene (--continuous)."""
        return f"/{self.run}/camo/notices"

    @property
    def heartbeat(self) -> str:
        """camo_msgs/Heartbeat: each process hosting robots is alive (docs/swarm.md)."""
        return f"/{self.run}/swarm/heartbeat"

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
