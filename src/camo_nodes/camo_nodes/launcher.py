"""`./camo run`: the distributed swarm, launched from one command.

Three steps: the command line becomes a checked RunConfig (`launch_config.py`);
the run's processes start (`processes.py`: the recorder with --record, the
projector, a bridge per real Droplet, the workers hosting the robot nodes);
then a session here runs the monitor, shows progress, switches backgrounds
with --then and writes each round's summary.json, figure.png and timing.json
once every live robot has finished. Ctrl-C stops every process and still
writes what the swarm had reported, bag included.
"""

from __future__ import annotations

import faulthandler
import json
import os
import socket
import sys
import time
from pathlib import Path

import numpy as np
import rclpy
from rclpy.duration import Duration
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import String

from camo_core.cli.options import contiguous
from camo_core.cli.params_file import write_params_file
from camo_core.exceptions import EXIT_USAGE, CamoError
from camo_core.shutdown import StopFlag
from camo_nodes.launch_config import RunConfig, build_parser, config_from
from camo_nodes.monitor_node import MonitorNode
from camo_nodes.processes import ProcessGroup
from camo_nodes.round_report import report_round, write_partial
from camo_nodes.topics import LATCHED, LATCHED_READER


class RunFailed(CamoError):
    """A process of the run failed, or a wait gave up: exit code 1 (2 when the process said its
    input was bad)."""

    def __init__(self, message: str, code: int = 1) -> None:
        super().__init__(message)
        self.code = code


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


def holds(report: dict, round_index: int, finished: int) -> bool:
    """Whether a recorder's bag holds a round of `finished` robots."""
    complete = report.get("complete", [])
    return len(complete) > round_index and complete[round_index] >= finished


RECORDER_SETTLE = 1.0  # s after the parameters appear that a waiting recorder has joined


class Interrupted(Exception):
    """Ctrl-C or SIGTERM reached the launcher."""


class Session:
    """The launcher's own nodes (the monitor, and a node that publishes the run's parameters
    and switches backgrounds) in one executor, with the waits a run needs."""

    def __init__(self, config: RunConfig, stop: StopFlag, context=None) -> None:
        self.config = config
        self.stop = stop
        topics = config.topics
        self.topics = topics
        self.node = Node("launcher", namespace=topics.swarm_namespace, context=context)
        self.executor = EventsExecutor(context=context)
        self.executor.add_node(self.node)
        if config.named:
            self.refuse_a_live_run()
        self.monitor = MonitorNode(config.params, topics, config.setup(), context=context)
        self.executor.add_node(self.monitor)
        self.loader = self.node.create_publisher(String, topics.load, 10)
        self.started = time.monotonic()
        self.node.create_publisher(String, topics.params, LATCHED).publish(
            String(data=json.dumps(config.setup()))
        )
        # Every recorder of the run (ours, or one started by hand) reports what its bag holds.
        self.recorders: dict[str, dict] = {}
        self.own_recorder: str | None = None  # our recorder's report's "recorder", once started
        self.node.create_subscription(String, topics.recorded, self._on_recorded, LATCHED_READER)
        # Created now, written at the end: recorders subscribe to it while the run goes on.
        self.result_pub = self.node.create_publisher(String, topics.result, LATCHED)
        self.rounds_ran: list[dict] = []  # per round written: who finished, who died, refusals

    def refuse_a_live_run(self, settle: float = 1.0) -> None:
        """Two launchers of one run id would share its topics: the second refuses to start."""
        deadline = time.monotonic() + settle  # discovery needs a moment to show a live run
        while time.monotonic() < deadline:
            if self.node.count_publishers(self.topics.params):
                raise RunFailed(
                    f"a run named {self.topics.run} is already running in this domain; "
                    f"choose another --run-id (or leave it out for a new one)",
                    2,
                )
            self.spin(0.05)

    def _on_recorded(self, msg: String) -> None:
        report = recorder_report(msg.data)
        if report is not None:
            self.recorders[report["recorder"]] = report

    def spin(self, seconds: float = 0.1) -> None:
        if self.stop:
            raise Interrupted
        self.executor.spin_once(timeout_sec=seconds)

    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            self.spin(left)

    def wait(self, done, what: str, limit: float) -> None:
        deadline = time.monotonic() + limit
        while not done():
            if time.monotonic() > deadline:
                raise RunFailed(f"{what} after {limit:g} s")
            self.spin()

    # ---- the recorder ---------------------------------------------------------------

    def recording_holds(self, round_index: int, group: ProcessGroup, limit: float = 60.0) -> None:
        """Before the robots stop or start a new round: a robot's topics keep one round of
        history for late subscribers, so every recorder must have taken this round in first."""
        finished = int(self.monitor.record(round_index).finished.sum())

        def short() -> list[dict]:
            """The reports of recorders that do not hold the round yet."""
            reports = list(self.recorders.values())
            if len(reports) < self.recorder_count() or not self.own_recorder_heard():
                return [{}]  # a recorder not heard from yet
            return [r for r in reports if not holds(r, round_index, finished)]

        deadline = time.monotonic() + limit
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
            self.spin()

    def views_matched(self, limit: float = 5.0) -> None:
        """Before the round's final scene and diagnostics: every recorder subscribes to them
        (it finds topics as they appear; a short round can end first), or `limit` passes."""
        recorders = self.recorder_count()
        views = (self.monitor.markers_pub, self.monitor.diagnostics_pub)
        deadline = time.monotonic() + limit
        while recorders and time.monotonic() < deadline:
            if all(v.get_subscription_count() >= recorders for v in views):
                return
            self.spin()

    def own_recorder_heard(self) -> bool:
        """Whether our own recorder has reported (one started by hand may be seen first)."""
        return self.own_recorder is None or self.own_recorder in self.recorders

    def recorder_count(self) -> int:
        """The recorders the graph shows, and at least our own: on a loaded machine discovery
        can show it later than a short round ends, and the robots must not stop before it has
        their messages."""
        own = 1 if self.config.record else 0
        return max(own, self.node.count_publishers(self.topics.recorded))

    def recorders_present(self) -> bool:
        """Whether a recorder records the run. A recorder waiting for a run finds it within
        about a discovery announcement period (fastdds.xml) of its parameters' appearing: a
        run shorter than that gives it the time."""
        if self.config.record:
            return True
        settle = RECORDER_SETTLE - (time.monotonic() - self.started)
        if settle > 0:
            self.spin_for(settle)
        return self.recorder_count() > 0

    def publish_result(self, ended: str, limit: float = 10.0) -> None:
        """The run's last word, latched, and waited for: every recorder must hold it (a bag
        without it is incomplete), and every other reader (a monitor elsewhere) ack it."""
        result = {"run": self.topics.run, "ended": ended, "rounds": self.rounds_ran}
        self.result_pub.publish(String(data=json.dumps(result)))
        deadline = time.monotonic() + limit
        while time.monotonic() < deadline:
            reports = list(self.recorders.values())
            present = self.recorder_count()
            heard = len(reports) >= present and self.own_recorder_heard()
            if not present or (heard and all(r["result"] for r in reports)):
                break  # every recorder has it (one that stopped by itself had it)
            self.executor.spin_once(timeout_sec=0.1)  # even after Ctrl-C: it is quick
        self.result_pub.wait_for_all_acked(Duration(seconds=max(0.1, deadline - time.monotonic())))

    def ran(self, index: int, summary: dict) -> None:
        """What the result will say of round `index`, as written in its summary."""
        record = self.monitor.record(index)
        cols = self.config.params.cols
        dead = [i * cols + j for i, j in summary.get("dead", [])]
        self.rounds_ran.append(
            {
                "finished": [
                    list(r) for r in contiguous(np.flatnonzero(record.finished).tolist())
                ],
                "dead": [list(r) for r in contiguous(dead)],
                "rejected_messages": summary["rejected_messages"],
            }
        )

    # ---- rounds -----------------------------------------------------------------

    def switch_background(self, label: str, limit: float = 60.0) -> None:
        """/camo/projector/load is volatile: it reaches only a projector matched when sent."""
        self.wait(
            lambda: self.loader.get_subscription_count() > 0,
            f"no projector listens on {self.topics.load}",
            limit,
        )
        self.loader.publish(String(data=label))

    def run_round(self, index: int, group: ProcessGroup) -> float:
        """Spin until every live robot has finished round `index`; when they had all voted."""
        monitor = self.monitor
        last_print = 0.0
        all_voted = None
        while not monitor.complete(index):
            # Everything that arrives in 0.1 s, then the (numpy) checks below: they cost more than
            # a status, and a burst of statuses must not wait behind them.
            self.spin_for(0.1)
            if all_voted is None and monitor.all_voted(index):
                all_voted = time.monotonic()
            if time.monotonic() - last_print > 1.0:
                print(f"camo run: {monitor.progress_line(index)}", file=sys.stderr)
                last_print = time.monotonic()
            problem = group.failed()
            if problem:
                raise RunFailed(problem)
            for robot in group.lost_cells():
                monitor.lost[robot] = True
        print(f"camo run: {monitor.progress_line(index)}", file=sys.stderr)
        self.views_matched()
        monitor.publish_views()  # the round's final scene, however short the round was
        return all_voted or time.monotonic()

    def close(self) -> None:
        # Executor first, then nodes, then context: the EventsExecutor must let go of the
        # nodes' handles before they are destroyed, or interpreter exit can crash.
        self.executor.shutdown()
        for node in (self.monitor, self.node):
            self.executor.remove_node(node)
            node.destroy_node()


def run(config: RunConfig) -> int:
    launched, launched_wall = time.monotonic(), time.time()
    os.environ.update(config.env)
    stop = StopFlag()
    rclpy.init(
        args=["--ros-args", "--log-level", "warn"], signal_handler_options=SignalHandlerOptions.NO
    )
    group = ProcessGroup(config.env)
    try:
        session = Session(config, stop)
    except RunFailed as exc:
        print(f"camo run: error: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return exc.code
    written = 0
    code = 0
    try:
        if config.record:
            # It starts with the swarm: the robots' topics keep their history for it.
            recorder = group.start_recorder(str(config.record), config.topics.run)
            session.own_recorder = f"{socket.gethostname()}:{recorder.pid}"  # as it names itself
            print(f"camo run: recording every topic to {config.record}/", file=sys.stderr)
        if config.foxglove is not None:
            group.start_view(config.topics.run, config.foxglove)  # it says where it serves
        print(
            f"camo run: {config.topics.run}: topics under /{config.topics.run}/", file=sys.stderr
        )
        group.start_swarm(config)
        (config.folder / "processes.json").write_text(
            json.dumps({str(pid): cells for pid, cells in group.cells.items()})
        )
        for index, label in enumerate(config.labels):
            if index > 0:
                if session.recorders_present():
                    session.recording_holds(index - 1, group)
                session.switch_background(label)
            voted = session.run_round(index, group)
            times = {"launched": launched, "voted": voted, "done": time.monotonic()}
            times["launched_wall"] = launched_wall
            if index == config.rounds - 1:
                if session.recorders_present():
                    session.recording_holds(index, group)
                # The robots tear down while this process writes the results.
                group.interrupt(keep=lambda proc: proc is group.recorder)
            session.ran(index, report_round(config, session.monitor, index, times))
            written += 1
        ended = "finished"
    except Interrupted:
        print("camo run: interrupted; stopping the swarm and writing what it has", file=sys.stderr)
        code, ended = 130, "interrupted"
    except RunFailed as exc:
        print(f"camo run: error: {exc}", file=sys.stderr)
        code, ended = exc.code, "failed"
    finally:
        stuck = watchdog(config.folder)
        group.stop(keep=lambda proc: proc is group.recorder)
        if written < config.rounds and group.cells:
            summary = write_partial(config, session.monitor, written)
            if summary is not None:
                session.ran(written, summary)
        session.publish_result(ended)
        group.stop()  # the recorder last: it closes the bag on SIGINT
        for module in group.killed:
            print(f"camo run: warning: {module} did not stop within 5 s; killed", file=sys.stderr)
        session.close()
        rclpy.try_shutdown()
        faulthandler.cancel_dump_traceback_later()
        stuck.close()
        Path(stuck.name).unlink()  # it ended in time: nothing to say
    return code


TEARDOWN_LIMIT = 60.0  # s; stopping, writing and the result take 25 s at most


def watchdog(folder: Path):
    """Bound the end of a run. Fast DDS can block a writer for good on the shared-memory port of
    a process killed at the wrong moment (seen: publishing the result after the recorder was
    SIGKILLed), holding the interpreter: only a thread outside Python can end the process then.
    What the run wrote stays; the threads' stacks go to stuck.txt; exit code 1."""
    stuck = open(folder / "stuck.txt", "w")  # kept open: the watchdog thread writes to it
    faulthandler.dump_traceback_later(TEARDOWN_LIMIT, exit=True, file=stuck)
    return stuck


def main(argv: list[str] | None = None) -> int:
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        config = config_from(args)
        write_params_file(parser, args, config.folder)  # the run, repeatable with --params-file
    except CamoError as exc:
        print(f"camo: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    return run(config)


if __name__ == "__main__":
    sys.exit(main())
