"""`./camo run`: the distributed swarm, launched from one command.

Three steps: the command line becomes a checked RunConfig (`run_config.py`);
the run's processes start (`processes.py`: the recorder with --record, the
projector, a bridge per real Droplet, the workers hosting the robot nodes);
then the rounds run here, in the launcher's session (`session.py`: the
monitor, the run's parameters; `recording.py`: what the recorders hold):
progress, background switches with --then, and each round's summary.json,
figure.png and timing.json once every live robot has finished. Ctrl-C stops every process and still
writes what the swarm had reported, bag included.
"""

from __future__ import annotations

import faulthandler
import json
import os
import socket
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import rclpy
from rclpy.signals import SignalHandlerOptions

from camo_bringup.failures import Interrupted, RunFailed
from camo_bringup.processes import ProcessGroup
from camo_bringup.round_report import continuous_round, report_round, write_partial
from camo_bringup.run_config import RunConfig, build_parser, config_from
from camo_bringup.session import Session
from camo_core.cli.params_file import write_params_file
from camo_core.exceptions import EXIT_USAGE, CamoError
from camo_core.shm import remove_stale
from camo_core.shutdown import StopFlag
from camo_core.swarm.keys import ENCRYPT_ENV, KEY_FILE_ENV, fingerprint
from camo_core.swarm.robot_io import CONSENSUS
from camo_core.swarm.run_setup import contiguous
from camo_nodes.monitor_node import MonitorNode
from camo_nodes.topics import keyed

TEARDOWN_LIMIT = 60.0  # s; stopping, writing and the result take 25 s at most
EXIT_RECORDING = 3  # the run finished, its recording failed (a full disk): the bag is cut short
HINT_AFTER = 20.0  # s with no robot past discovery before a run on a named server says so


def discovery_hint(server: str | None, waited: float, past_discovery: bool) -> str | None:
    """What a run on a discovery server the user named (ROS_DISCOVERY_SERVER,
    --discovery-server) says once none of its robots has heard a neighbour in HINT_AFTER s: a
    server that does not run leaves every process searching, and the run waiting, without a
    word of why."""
    if server is None or past_discovery or waited < HINT_AFTER:
        return None
    return (
        f"no robot has heard a neighbour in {waited:.0f} s: is a discovery server running at "
        f"{server}? (`./camo discovery-server --port PORT` on that machine; docs/swarm.md)"
    )


def run_round(session: Session, index: int, group: ProcessGroup) -> float:
    """Spin until every live robot has finished round `index`; when they had all voted."""
    monitor = session.monitor
    last_print = 0.0
    all_voted = None
    config = session.config
    named = config.env.get("ROS_DISCOVERY_SERVER") if config.deferred is None else None
    started, hinted = time.monotonic(), False
    while not monitor.complete(index):
        # Everything that arrives in 0.1 s, then the (numpy) checks below: they cost more than
        # a status, and a burst of statuses must not wait behind them.
        session.spin_for(0.1)
        if all_voted is None and monitor.all_voted(index):
            all_voted = time.monotonic()
        if named and not hinted:
            waited = time.monotonic() - started
            hint = discovery_hint(named, waited, monitor.past_discovery(index))
            if hint:
                print(f"camo run: {hint}", file=sys.stderr)
                hinted = True
        if time.monotonic() - last_print > 1.0:
            print(f"camo run: {monitor.progress_line(index)}", file=sys.stderr)
            last_print = time.monotonic()
            group.sample_memory()
        problem = group.failed()
        if problem:
            raise RunFailed(problem)
        session.check_hosts(group.cells)
        for robot in group.lost_cells():
            monitor.lost[robot] = True
    print(f"camo run: {monitor.progress_line(index)}", file=sys.stderr)
    session.check_hosts(group.cells, final=True)
    session.recorders.views_matched()
    monitor.publish_views()  # the round's final scene, however short the round was
    return all_voted or time.monotonic()


def round_ran(config: RunConfig, monitor: MonitorNode, index: int, summary: dict) -> dict:
    """What the result says of round `index`, as written in its summary: who finished, who
    died (as [first, last] ranges), what was refused."""
    record = monitor.record(index)
    cols = config.params.cols
    dead = [i * cols + j for i, j in summary.get("dead", [])]
    return {
        "finished": [list(r) for r in contiguous(np.flatnonzero(record.finished).tolist())],
        "dead": [list(r) for r in contiguous(dead)],
        "rejected_messages": summary["rejected_messages"],
    }


def start_processes(config: RunConfig, group: ProcessGroup, session: Session) -> None:
    """The recorder (it starts with the swarm: the robots' topics keep their history for it),
    the live view, then the swarm: projector, bridges and workers."""
    if config.record:
        recorder = group.start_recorder(str(config.record), config.topics.run)
        session.recorders.own = f"{socket.gethostname()}:{recorder.pid}"  # as it names itself
        session.recorders.own_running = group.recording
        print(f"camo run: recording every topic to {config.record}/", file=sys.stderr)
    if config.foxglove is not None:
        group.start_view(config.topics.run, config.foxglove)  # it says where it serves
    key = keyed.process_key()
    said = f"key {fingerprint(key)} in {key.path}" if key else "no key: any writer is believed"
    print(
        f"camo run: {config.topics.run}: topics under /{config.topics.run}/; {said}",
        file=sys.stderr,
    )
    with tempfile.TemporaryDirectory(prefix="camo-ready-") as ready:
        group.start_swarm(config, Path(ready) if config.deferred else None)
        (config.folder / "processes.json").write_text(
            json.dumps({str(pid): cells for pid, cells in group.cells.items()})
        )
        if config.deferred:
            discover_once_created(config, group, session, Path(ready))


def _count(path: Path) -> int:
    """A worker's count of robot nodes created so far (0 while it is being written)."""
    try:
        return int(path.read_text())
    except (OSError, ValueError):
        return 0


def discover_once_created(config: RunConfig, group: ProcessGroup, session: Session, ready: Path):
    """Wait until every worker has created its robot nodes, then start the run's discovery
    server (run_config.deferred_discovery says why)."""
    workers, last_print = len(group.workers), 0.0
    while (done := sum(1 for f in ready.iterdir() if not f.suffix)) < workers:
        problem = group.failed() or (group.lost_cells() and "a worker died creating its robots")
        if problem:
            raise RunFailed(problem)
        session.check_hosts(group.cells)
        if time.monotonic() - last_print > 2.0:
            created = sum(_count(f) for f in ready.glob("*.count"))
            print(
                f"camo run: creating robot nodes: {created}/{config.params.count} "
                f"({done}/{workers} workers done)",
                file=sys.stderr,
            )
            last_print = time.monotonic()
        session.spin(0.2)  # Ctrl-C is heard here too
    group.start_discovery_server(config.deferred)
    print(
        f"camo run: {config.params.count} robot nodes created; the run's processes find each "
        f"other through its discovery server at {config.deferred} (ros2 CLI: "
        f"ROS_DISCOVERY_SERVER={config.deferred} ROS_SUPER_CLIENT=TRUE)",
        file=sys.stderr,
    )


def run_rounds(
    config: RunConfig, session: Session, group: ProcessGroup, launched: tuple, ran: list[dict]
) -> None:
    """Every round, one after another, each written once its live robots have finished (what
    the result will say of it appended to `ran`). `launched`: (monotonic, wall) times."""
    for index, label in enumerate(config.labels):
        if index > 0:
            if session.recorders.present():
                session.recorders.hold(index - 1, group)
            session.switch_background(label)
        voted = run_round(session, index, group)
        times = {"launched": launched[0], "voted": voted, "done": time.monotonic()}
        times["launched_wall"] = launched[1]
        group.sample_memory()
        times["peak_mib"] = group.peak_mib()
        if index == config.rounds - 1:
            if session.recorders.present():
                session.recorders.hold(index, group)
            # The robots tear down while this process writes the results.
            group.interrupt(keep=lambda proc: proc in (group.recorder, group.server))
        summary = report_round(config, session.monitor, index, times)
        session.action.written(index, index, summary)
        ran.append(round_ran(config, session.monitor, index, summary))


class ContinuousRounds:
    """The rounds of a continuous run, written as their live robots finish them (round_0/,
    round_1/, ...: what the result will say of each appended to `ran`); when the run stops,
    the finished ones not written yet, then the round under way as far as the swarm had
    reported it."""

    def __init__(self, config: RunConfig, session: Session, ran: list[dict]) -> None:
        self.config, self.session, self.ran = config, session, ran
        self.written: list[int] = []  # the frames of the rounds written, in order
        self.finished: dict[int, int] = {}  # round -> robots that finished it

    def collect(self, check=lambda: None, most: int | None = None) -> None:
        """Every round its live robots have finished is written (`check()` first; `most`
        rounds in all at most); one no robot is in any more is superseded: said, not written."""
        monitor = self.session.monitor
        for round_ in sorted(monitor.heard - monitor.closed):
            if most is not None and len(self.written) >= most:
                return
            if monitor.complete(round_):
                check()
                self._write(round_)
            elif monitor.superseded(round_):
                print(f"camo run: the round of frame {round_} was superseded", file=sys.stderr)
                monitor.close(round_)

    def _write(self, round_: int, partial: bool = False) -> None:
        monitor = self.session.monitor
        index = len(self.written)
        summary = continuous_round(self.config, monitor, index, round_, partial)
        if not partial:  # a goal is met by a finished round only
            self.session.action.written(index, round_, summary)
        self.ran.append({"round": round_, **round_ran(self.config, monitor, round_, summary)})
        self.written.append(round_)
        self.finished[round_] = int(monitor.record(round_).finished.sum())
        monitor.close(round_)

    def wrap_up(self) -> None:
        """The run stops (Ctrl-C, --duration, a failure), its robots' last reports taken: every
        finished round not written yet, then the latest round robots were in, as it stood."""
        self.collect()
        monitor = self.session.monitor
        *earlier, latest = sorted(monitor.heard - monitor.closed) or [None]
        for round_ in earlier:
            print(
                f"camo run: the round of frame {round_} was not finished (a later one had begun)",
                file=sys.stderr,
            )
        if latest is None:
            return
        if not np.any(monitor.record(latest).phase >= CONSENSUS):
            print(
                f"camo run: nothing to write of the round under way (frame {latest}): no robot "
                "had voted",
                file=sys.stderr,
            )
            return
        self._write(latest, partial=True)


def run_continuous(config: RunConfig, session: Session, group: ProcessGroup, rounds):
    """--continuous: the rounds the robots start by themselves, each written once every live
    robot has finished it (`rounds`: ContinuousRounds), until --rounds of them or --duration
    seconds (or Ctrl-C). A round that robots left for a later one before all finished it was
    superseded: said, not written."""
    monitor = session.monitor
    started = last_print = time.monotonic()
    while config.until_rounds is None or len(rounds.written) < config.until_rounds:
        if config.until_seconds is not None and time.monotonic() - started >= config.until_seconds:
            print(f"camo run: --duration {config.until_seconds:g} s is up", file=sys.stderr)
            break
        session.spin_for(0.1)
        rounds.collect(lambda: session.check_hosts(group.cells, final=True), config.until_rounds)
        if time.monotonic() - last_print > 1.0:
            latest = max(monitor.heard - monitor.closed, default=None)
            line = monitor.progress_line(latest) if latest is not None else "watching"
            print(f"camo run: {len(rounds.written)} rounds done; {line}", file=sys.stderr)
            last_print = time.monotonic()
            group.sample_memory()
        problem = group.failed()
        if problem:
            raise RunFailed(problem)
        session.check_hosts(group.cells)
        for robot in group.lost_cells():
            monitor.lost[robot] = True
    last = rounds.written[-1] if rounds.written else None
    if last is not None and session.recorders.present():
        session.recorders.hold(last, group, finished=rounds.finished[last])
    group.interrupt(keep=lambda proc: proc in (group.recorder, group.server))


def run(config: RunConfig) -> int:
    launched = (time.monotonic(), time.time())
    os.environ.update(config.env)
    for name in (KEY_FILE_ENV, ENCRYPT_ENV):  # the run's key (none with --no-key)
        if name not in config.env:
            os.environ.pop(name, None)
    keyed.process_key.cache_clear()

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
    code, ended = 0, "failed"
    ran: list[dict] = []  # per round written: who finished, who died, refusals
    rounds = ContinuousRounds(config, session, ran)
    try:
        start_processes(config, group, session)
        if config.continuous:
            run_continuous(config, session, group, rounds)
        else:
            run_rounds(config, session, group, launched, ran)
        ended = "finished"
    except Interrupted:
        print("camo run: interrupted; stopping the swarm and writing what it has", file=sys.stderr)
        code, ended = 130, "interrupted"
    except RunFailed as exc:
        print(f"camo run: error: {exc}", file=sys.stderr)
        code = exc.code
    finally:
        stuck = watchdog(config.folder)
        # The monitor takes the robots' last reports while their workers stop (a worker waits
        # for them to be taken before it exits), then what is left of them.
        group.stop(
            keep=lambda proc: proc in (group.recorder, group.server),
            meanwhile=session.monitor.turn,
        )
        session.monitor.take_waiting()
        if len(ran) < config.rounds and group.cells and not config.continuous:
            summary = write_partial(config, session.monitor, len(ran))
            if summary is not None:
                ran.append(round_ran(config, session.monitor, len(ran), summary))
        elif config.continuous and (ended != "finished" or config.until_rounds is None):
            rounds.wrap_up()  # Ctrl-C, a failure, or --duration's end: nothing finished is lost
        session.recorders.publish_result({"run": config.topics.run, "ended": ended, "rounds": ran})
        group.stop()  # the recorder last: it closes the bag on SIGINT
        remove_stale()  # the shared-memory files of workers that exited without tearing down
        for module in group.killed:
            print(f"camo run: warning: {module} did not stop within 5 s; killed", file=sys.stderr)
        session.close()
        rclpy.try_shutdown()
        faulthandler.cancel_dump_traceback_later()
        stuck.close()
        Path(stuck.name).unlink()  # it ended in time: nothing to say
    if code == 0 and group.recording_failed():
        print(
            f"camo run: the run finished and wrote its results to {config.folder}/; its "
            "recording did not (the recorder said why above)",
            file=sys.stderr,
        )
        code = EXIT_RECORDING
    return code


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
