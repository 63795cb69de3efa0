"""The recorders of a run, as the launcher follows them: what each bag holds, so that the robots
neither stop nor start a new round before every recorder has their messages, and the run's
result (its last word) is in every bag before the launcher exits."""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

from rclpy.duration import Duration
from rclpy.node import Node
from std_msgs.msg import String

from camo_bringup.failures import RunFailed
from camo_bringup.run_config import RunConfig
from camo_nodes.monitor_node import MonitorNode
from camo_nodes.topics import keyed
from camo_nodes.topics.names import RunTopics
from camo_nodes.topics.qos import LATCHED, LATCHED_READER

if TYPE_CHECKING:
    from camo_bringup.processes import ProcessGroup


class RunSide(Protocol):
    """What the recorders need of the launcher's side of a run (session.Session): its node,
    topics, configuration and monitor, when it started, and spinning its executor."""

    node: Node
    topics: RunTopics
    config: RunConfig
    monitor: MonitorNode
    started: float

    def spin_for(self, seconds: float) -> None: ...


RECORDER_SETTLE = 1.0  # s after the parameters appear that a waiting recorder has joined
# s a round's end waits for a writer on the run's recorded topic that has never reported as a
# recorder does (a recorder reports as it records): a stranger writing there does not hold
# the run for `hold`'s minute.
UNHEARD_GRACE = 5.0


def recorder_report(text: str) -> dict | None:
    """A recorder's /<run>/swarm/recorded report, or None if it is not one."""
    try:
        report = json.loads(text)
        valid = (
            isinstance(report["recorder"], str)
            and isinstance(report["result"], bool)
            and all(isinstance(n, int) for n in report["complete"])
        )
    except (ValueError, KeyError, TypeError):
        return None
    return report if valid else None


def holds(report: dict, round_index: int, finished: int, continuous: bool = False) -> bool:
    """Whether a recorder's bag holds a round of `finished` robots (a continuous run's round by
    its frame number, the others' by their index)."""
    if continuous:
        rounds = report.get("rounds", {})
        return isinstance(rounds, dict) and rounds.get(str(round_index), -1) >= finished
    complete = report.get("complete", [])
    return len(complete) > round_index and complete[round_index] >= finished


class Recorders:
    """Every recorder of the run (ours, or one started by hand) reports what its bag holds on
    /<run>/swarm/recorded; the run's result goes out on /<run>/swarm/result."""

    def __init__(self, session: RunSide) -> None:
        self.session = session
        node, topics = session.node, session.topics
        self.reports: dict[str, dict] = {}
        self.own: str | None = None  # our recorder's report's "recorder", once started
        # Whether our recorder still runs: one that could not write its bag (a full disk) has
        # said so and exited, and the run goes on without waiting for it.
        self.own_running: Callable[[], bool] = lambda: True
        # Since when the graph has shown more writers on the recorded topic than have reported
        # as recorders (None: it does not now): they are waited for UNHEARD_GRACE from then.
        self._unheard_since: float | None = None
        self._unheard_said = False
        keyed.subscription(
            node,
            String,
            topics.recorded,
            self._on_recorded,
            LATCHED_READER,
            topics.run,
            session.monitor.rejected.refuse,
        )
        # Created now, written at the end: recorders subscribe to it while the run goes on.
        self.result_pub = keyed.publisher(node, String, topics.result, LATCHED, topics.run)

    def _on_recorded(self, msg: String) -> None:
        report = recorder_report(msg.data)
        if report is not None:
            self.reports[report["recorder"]] = report

    def own_heard(self) -> bool:
        """Whether our own recorder has reported (one started by hand may be seen first)."""
        return self.own is None or self.own in self.reports or not self.own_running()

    def live_reports(self) -> list[dict]:
        """The reports of the recorders that still record (not our own once it has failed)."""
        gone = None if self.own_running() else self.own
        return [r for name, r in self.reports.items() if name != gone]

    def count(self) -> int:
        """The recorders the graph shows, and at least our own: on a loaded machine discovery
        can show it later than a short round ends, and the robots must not stop before it has
        their messages."""
        publishers = self.session.node.count_publishers(self.session.topics.recorded)
        if not self.session.config.record:
            return publishers
        if not self.own_running():  # the graph may list it a while after it exited
            return max(len(self.live_reports()), publishers - 1)
        return max(1, publishers)

    def waited_for(self) -> int:
        """The recorders a wait waits for: those the graph shows, but of the writers that have
        never reported as recorders, only for UNHEARD_GRACE after they were first seen (a
        recorder reports four times a second as it records; a stranger writing on the topic
        never does), then said once and not waited for again."""
        graph, heard = self.count(), len(self.live_reports())
        if graph <= heard:
            self._unheard_since = None  # every writer there has reported
            return graph
        now = time.monotonic()
        if self._unheard_since is None:
            self._unheard_since = now
        if now - self._unheard_since < UNHEARD_GRACE:
            return graph
        if not self._unheard_said:
            print(
                f"camo run: {graph - heard} writers on {self.session.topics.recorded} never "
                "reported as recorders; not waited for",
                file=sys.stderr,
            )
            self._unheard_said = True
        return heard

    def present(self) -> bool:
        """Whether a recorder records the run. A recorder waiting for a run finds it within
        about a discovery announcement period (fastdds.xml) of its parameters' appearing: a
        run shorter than that gives it the time."""
        if self.session.config.record and self.own_running():
            return True
        settle = RECORDER_SETTLE - (time.monotonic() - self.session.started)
        if settle > 0:
            self.session.spin_for(settle)
        return self.count() > 0

    def hold(
        self,
        round_index: int,
        group: ProcessGroup,
        limit: float = 60.0,
        finished: int | None = None,
    ) -> None:
        """Before the robots stop or start a new round: a robot's topics keep one round of
        history for late subscribers, so every recorder must have taken this round in first
        (`finished`: the robots that finished it, if the monitor's record is let go)."""
        session = self.session
        if finished is None:
            finished = int(session.monitor.record(round_index).finished.sum())

        deadline = time.monotonic() + limit

        def short() -> list[dict]:
            """The reports of recorders that do not hold the round yet."""
            reports = self.live_reports()
            if len(reports) < self.waited_for() or not self.own_heard():
                return [{}]  # a recorder not heard from yet
            continuous = session.config.continuous
            return [r for r in reports if not holds(r, round_index, finished, continuous)]

        while lacking := short():
            problem = group.failed()
            if problem:
                raise RunFailed(problem)
            if time.monotonic() > deadline:
                kinds = [
                    r["lacking"][round_index]
                    for r in lacking
                    if len(r.get("lacking", [])) > round_index
                ]
                print(
                    f"camo run: {len(lacking)} recordings lack round {round_index} of some "
                    f"robots after {limit:g} s (messages missing, by kind: "
                    f"{kinds or 'statuses only'})",
                    file=sys.stderr,
                )
                return
            session.spin()

    def views_matched(self, limit: float = 5.0) -> None:
        """Before the round's final scene and diagnostics: every recorder subscribes to them
        (it finds topics as they appear; a short round can end first), or `limit` passes."""
        recorders = self.waited_for()
        monitor = self.session.monitor
        views = (monitor.markers_pub, monitor.diagnostics_pub)
        deadline = time.monotonic() + limit
        while recorders and time.monotonic() < deadline:
            if all(v.get_subscription_count() >= recorders for v in views):
                return
            self.session.spin()
            recorders = self.waited_for()

    def publish_result(self, result: dict, limit: float = 10.0) -> None:
        """The run's last word, latched, and waited for: every recorder must hold it (a bag
        without it is incomplete), and every other reader (a monitor elsewhere) ack it."""
        self.result_pub.publish(String(data=json.dumps(result)))
        deadline = time.monotonic() + limit
        while time.monotonic() < deadline:
            reports = self.live_reports()
            present = self.waited_for()
            heard = len(reports) >= present and self.own_heard()
            if not present or (heard and all(r["result"] for r in reports)):
                break  # every recorder has it (one that stopped by itself had it)
            self.session.executor.spin_once(timeout_sec=0.1)  # even after Ctrl-C: it is quick
        self.result_pub.wait_for_all_acked(Duration(seconds=max(0.1, deadline - time.monotonic())))
