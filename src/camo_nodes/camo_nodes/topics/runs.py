"""Finding a run from a process that joins it (a worker, a monitor, a recorder, a node alone):
which runs are on the graph, the run's setup as its launcher published it, its result, and
whether it has ended."""

from __future__ import annotations

import json
import time

import rclpy
from std_msgs.msg import String

from camo_core.exceptions import CamoError
from camo_core.swarm.run_setup import RunSetup, SetupError

from . import keyed
from .names import RunTopics, check_run_id, runs_on_graph
from .qos import LATCHED_READER


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


def setup_from(text: str, run: str) -> RunSetup | None:
    """Run `run`'s setup message, or None if it is not one (a stranger's, say)."""
    try:
        return RunSetup.from_json(text, run)
    except SetupError:
        return None


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


def _ignored(reason: str, gid: bytes) -> None:
    """Parameters not tagged with the run's key: as if never written."""


def wait_for_setup(node, spin, topics: RunTopics, timeout: float, stop=None) -> RunSetup:
    """The run's /swarm/params (latched) as the launcher published it."""
    got: list[RunSetup] = []

    def take(msg: String) -> None:
        setup = setup_from(msg.data, topics.run)
        if setup is not None:
            got.append(setup)

    subscription = keyed.subscription(
        node, String, topics.params, take, LATCHED_READER, topics.run, _ignored
    )
    deadline = time.monotonic() + timeout
    try:
        while not got and not stop:
            if time.monotonic() > deadline:
                raise NoRun(f"no parameters on {topics.params} after {timeout:g} s")
            spin()
        if node.count_publishers(topics.params) > 1:
            raise NoRun(
                f"{node.count_publishers(topics.params)} processes publish the parameters of "
                f"{topics.run}: cannot tell which is its launcher"
            )
    finally:
        node.destroy_subscription(subscription)
    if stop:
        raise KeyboardInterrupt
    return got[0]
