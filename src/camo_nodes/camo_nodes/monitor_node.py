"""The monitor: assembles the robots' statuses into the swarm's picture and its summary.

It publishes `/swarm/pattern` (one mono8 pixel per robot: dark = on, light =
off, grey = not reported yet) and, once every live robot has finished a round,
builds the same RunResult the reference simulator returns, for summary.json
and figure.png. A robot is dead when it has not finished and its neighbours
gave up on it (their step protocol let a deadline pass without it), or when
the launcher saw its process die; a robot that is merely late to report is
waited for.

`monitor_node` (console script) watches a run started elsewhere: it reads the
run's parameters from /<run>/swarm/params, prints progress, and writes each
round's summary.json and figure.png to --out.
"""

from __future__ import annotations

import heapq
import itertools
import os
import sys
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import Image
from visualization_msgs.msg import MarkerArray

from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.result import RunResult
from camo_core.algorithm.sensing import image_digest
from camo_core.cli.options import Parser, add_out_options, out_dir, seconds
from camo_core.exceptions import CamoError
from camo_core.results.output import round_summary, run_title, start_drawings
from camo_core.results.record import Backgrounds, RoundRecord, Rounds
from camo_core.results.snapshots import Snapshots
from camo_core.results.summary import write_summary
from camo_core.shutdown import StopFlag
from camo_core.swarm.robot_io import CONSENSUS, DISCOVERY, PHASE_NAMES
from camo_core.swarm.run_setup import RunSetup
from camo_core.swarm.status_rows import RowsError, StatusRows
from camo_core.swarm.validation import rows_problems
from camo_msgs.msg import Host, Notices, StatusArray
from camo_nodes import scene
from camo_nodes.polled import PolledTopics
from camo_nodes.rcl_take import PREFIX
from camo_nodes.topics import keyed
from camo_nodes.topics.images import (
    ImageEncodingError,
    frame_number,
    image_from_msg,
    image_to_msg,
    pixels_sha256,
)
from camo_nodes.topics.names import RunTopics, check_run_id
from camo_nodes.topics.qos import LATCHED_READER
from camo_nodes.topics.runs import wait_for_run, wait_for_setup
from camo_nodes.topics.startup import add_network_options, network_env, start_ros
from camo_nodes.trust import BackgroundCheck, Hosts, Rejections, merged

EARLY_NOTICES = 10_000  # notices kept until their robots' host is heard, at most
# Messages that waited for their host's word taken again per turn of the monitor's timer (20 ms)
# at most: twice the status arrays a poll takes, so that what waits shrinks while more comes.
REPLAY_PER_TURN = 32


class MonitorNode(Node):
    def __init__(
        self, params: CamoParams, topics: RunTopics, setup: RunSetup | None = None, **kwargs
    ) -> None:
        super().__init__("monitor", namespace=topics.swarm_namespace, **kwargs)
        self.params = params
        self.topics = topics
        self.rounds = Rounds(params)
        self.images = Backgrounds()  # the frame of round r is images[r]
        # Continuous camouflage: round -> (robot, changed_at, noticed_at) of its first notice.
        self.notices: dict[int, tuple[int, float, float]] = {}
        self.lost = np.zeros(params.count, bool)  # robots whose process is known to have died
        self.round_of = np.full(params.count, -1, np.int64)  # each robot's latest round
        self.closed: set[int] = set()  # rounds written or superseded: their records let go
        self.heard: set[int] = set()  # rounds robots reported in
        self._shown: tuple[int, RoundRecord | None] = (-1, None)  # the last closed round
        self.continuous = setup is not None and setup.protocol.continuous
        # Notices (columns) before their host's word, and how many: (arrival, columns, gid).
        self._early_notices: list[tuple[int, tuple[np.ndarray, ...], bytes]] = []
        self._early_rows = 0
        self.offline = np.zeros(params.count, bool)
        self.statuses_heard = 0  # a recording of the run must hold at least these
        # Statuses count only from the process hosting their robot; a background only if it is
        # the run's next; both polled with their publisher's GID (trust.py).
        self.rejected = Rejections(self.get_logger())
        self.trusted = Hosts(params.count, self.rejected, setup)
        self.backgrounds = BackgroundCheck(setup)
        # Status rows before their host's word (arrival, rows, gid, stamp), and how many.
        self._unplaced: list[tuple[int, StatusRows, bytes, float]] = []
        self._unplaced_rows = 0
        # What waited for its host's word, taken again a bounded number a turn (`turn`) in the
        # order it came, and statuses that came since: (arrival, how to take it).
        self._replay: list[tuple[int, Callable[[], None]]] = []
        self._arrivals = itertools.count()
        # Robot -> the index of its host's GUID prefix (-1: none yet), for a table's rows at once.
        self._owner = np.full(params.count, -1, np.int64)
        self._prefixes: dict[bytes, int] = {}
        context = kwargs.get("context")
        self.polled = PolledTopics(
            "monitor_listener", topics.swarm_namespace, context, topics.run, self.rejected.refuse
        )
        self.polled.listen(Host, topics.hosts, LATCHED_READER, self._on_host)
        # Every process writes its robots' statuses to one topic: the monitor keeps all
        # (LATCHED_READER keeps every sample), or bursts would push statuses out.
        self.polled.listen(StatusArray, topics.status, LATCHED_READER, self._on_status, 16)
        self.polled.listen(Image, topics.background, LATCHED_READER, self._on_background)
        self.polled.listen(Notices, topics.notices, LATCHED_READER, self._on_notices)
        self.create_timer(0.02, self.turn)
        # For viewers; tagged too, so that a keyed recorder or view tells them from a stranger's.
        self.pattern_pub = keyed.publisher(self, Image, topics.pattern, 10, topics.run)
        self.create_timer(0.2, self._publish_pattern)
        self.bridged = set(setup.bridged if setup is not None else ())
        self.markers_pub = keyed.publisher(self, MarkerArray, topics.markers, 1, topics.run)
        self.diagnostics_pub = keyed.publisher(
            self, DiagnosticArray, topics.diagnostics, 1, topics.run
        )
        self.create_timer(0.5, self.publish_views)

    def turn(self) -> int:
        """A turn of the monitor's timer: REPLAY_PER_TURN of the messages that waited for their
        host's word at most, then a poll; how many messages the poll took."""
        for _ in range(min(REPLAY_PER_TURN, len(self._replay))):
            _, take = heapq.heappop(self._replay)
            take()
        return self.polled.poll()

    def _on_host(self, data: bytes, gid: bytes) -> None:
        tiles = self.trusted.learn(deserialize_message(data, Host), gid)
        if tiles:
            index = self._prefixes.setdefault(gid[:PREFIX], len(self._prefixes))
            for first, last in tiles:
                self._owner[first : last + 1] = index
            # What waited is taken again over the next turns, in the order it came (a robot's
            # later report after its earlier ones): a bounded number a turn.
            for arrival, rows, sender_gid, stamp in self._unplaced:
                take = partial(self._take_rows, rows, sender_gid, stamp, arrival)
                heapq.heappush(self._replay, (arrival, take))
            for arrival, notices, sender_gid in self._early_notices:
                take = partial(self._notice_rows, notices, sender_gid, arrival)
                heapq.heappush(self._replay, (arrival, take))
            self._unplaced, self._unplaced_rows = [], 0
            self._early_notices, self._early_rows = [], 0

    def _on_background(self, data: bytes, gid: bytes) -> None:
        msg = deserialize_message(data, Image)
        stamp = (msg.header.stamp.sec, msg.header.stamp.nanosec)
        if stamp in self.images.stamps:
            return
        try:
            image = image_from_msg(msg)
        except ImageEncodingError:
            self.rejected.refuse("a background that cannot be decoded", gid)
            return
        problem = self.backgrounds.problem(image_digest(image), gid)
        if problem is not None:
            if problem != BackgroundCheck.REPEAT:
                self.rejected.refuse(problem, gid)
            return
        # A continuous run's frames are named by the projector's numbers; elsewhere the k-th
        # background taken is round k.
        number = frame_number(msg.header.frame_id) if self.continuous else None
        self.images.add(stamp, lambda: image, number, pixels_sha256(msg))

    def _on_notices(self, data: bytes, gid: bytes) -> None:
        msg = self.rejected.decoded(data, Notices, gid, "a notice")
        if msg is None:
            return
        columns = (msg.robot, msg.round, msg.changed_at, msg.noticed_at)
        if len({len(c) for c in columns}) != 1:
            self.rejected.refuse("a notice whose columns disagree", gid, msg.name)
            return
        notices = (
            np.asarray(msg.robot, np.int64),
            np.asarray(msg.round, np.int64),
            np.asarray(msg.changed_at, np.float64),
            np.asarray(msg.noticed_at, np.float64),
        )
        self._notice_rows(notices, gid, next(self._arrivals))

    def _notice_rows(self, notices: tuple[np.ndarray, ...], gid: bytes, arrival: int) -> None:
        """A process's notices (robot, round, changed_at, noticed_at columns): the first notice
        of each round is kept, from the process hosting its robot."""
        robot, round_, changed, noticed = notices
        count = self.params.count
        inside = (robot >= 0) & (robot < count)
        owner = np.where(inside, self._owner[np.clip(robot, 0, count - 1)], -1)
        early = inside & (owner < 0)  # its host's word is still to come
        if early.any():
            keep = np.flatnonzero(early)[: max(0, EARLY_NOTICES - self._early_rows)]
            if len(keep):
                self._early_notices.append((arrival, tuple(c[keep] for c in notices), gid))
                self._early_rows += len(keep)
            robot, round_, changed, noticed = (c[~early] for c in notices)
            owner = owner[~early]
        stranger = owner != self._prefixes.get(gid[:PREFIX], -2)
        for sender in robot[stranger].tolist():
            self.rejected.refuse("not from the process hosting its sender", gid, f"robot {sender}")
        robot, round_, changed, noticed = (c[~stranger] for c in (robot, round_, changed, noticed))
        for index in np.unique(round_).tolist():
            self.images.pin(index)  # the round's frame is kept for its figure from now on
            rows = np.flatnonzero(round_ == index)
            k = rows[np.argmin(noticed[rows])]
            first = self.notices.get(index)
            if first is None or noticed[k] < first[2]:
                self.notices[index] = (int(robot[k]), float(changed[k]), float(noticed[k]))

    def _on_status(self, data: bytes, gid: bytes) -> None:
        msg = self.rejected.decoded(data, StatusArray, gid, "a status array")
        if msg is None:
            return
        try:
            rows = StatusRows.from_message(msg)
        except RowsError:
            self.rejected.refuse("a status array whose columns disagree", gid, msg.name)
            return
        self.statuses_heard += len(rows)
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        arrival = next(self._arrivals)
        if self._replay:  # after what came before it and waited for its host's word
            take = partial(self._take_rows, rows, gid, stamp, arrival)
            heapq.heappush(self._replay, (arrival, take))
        else:
            self._take_rows(rows, gid, stamp, arrival)

    def _take_rows(self, rows: StatusRows, gid: bytes, stamp: float, arrival: int = 0) -> None:
        """A process's reports: each row used if it is sound and its robot is the process's.
        `arrival`: the order it came in, kept while it waits for its host's word."""
        ids = rows.sender_id
        inside = (ids >= 0) & (ids < self.params.count)
        owner = np.where(inside, self._owner[np.clip(ids, 0, self.params.count - 1)], -1)
        waiting = inside & (owner < 0)  # robots whose host has not been heard yet
        if waiting.any():
            if self._unplaced_rows < 10 * self.params.count + 1000:
                self._unplaced.append((arrival, rows.select(waiting), gid, stamp))
                self._unplaced_rows += int(waiting.sum())
            else:
                for robot in ids[waiting]:
                    self.rejected.refuse(
                        "status from a robot no process hosts", gid, f"robot {robot}"
                    )
            rows, owner = rows.select(~waiting), owner[~waiting]
        problems = rows_problems(rows, self.params)
        speaker = self._prefixes.get(gid[:PREFIX], -2)
        for row in np.flatnonzero(owner != speaker):
            problems[row] = problems[row] or "not from the process hosting its sender"
        good = np.array([p is None for p in problems], bool)
        for row in np.flatnonzero(~good):
            self.rejected.refuse(problems[row], gid, f"robot {rows.sender_id[row]}")
        rows = rows.select(good)
        # A bridged Droplet whose port went away.
        self.offline[rows.sender_id] = ~rows.alive
        np.maximum.at(self.round_of, rows.sender_id, rows.round.astype(np.int64))
        for index in np.unique(rows.round).tolist():
            if index in self.closed:
                continue
            if index not in self.heard:
                self.heard.add(index)
                self.images.pin(index)  # a round's frame is kept for its figure
            self.rounds[index].add_rows(rows.select(rows.round == index), stamp)

    def take_waiting(self, limit: float = 2.0) -> None:
        """Take what waits in the readers (bounded batches, for `limit` seconds at most): the last
        reports of robots that stopped while nobody spun the monitor."""
        deadline = time.monotonic() + limit
        while time.monotonic() < deadline and (self.turn() or self.polled.more or self._replay):
            pass

    def rejected_messages(self) -> dict:
        """Messages refused in the whole run: by this monitor and by every host."""
        return merged(self.rejected.as_dict(), *self.trusted.refused.values())

    def destroy_node(self) -> None:
        self.polled.close()
        super().destroy_node()

    # ---- views ------------------------------------------------------------------

    def record(self, round_index: int) -> RoundRecord:
        return self.rounds[round_index]

    def dead(self, round_index: int = 0) -> np.ndarray:
        return self.rounds[round_index].dead(self.lost)

    def past_discovery(self, round_index: int = 0) -> bool:
        """Some robot has heard its neighbours (it reported a later phase, or finished)."""
        record = self.rounds[round_index]
        return bool((record.phase > DISCOVERY).any() or record.finished.any())

    def all_voted(self, round_index: int = 0) -> bool:
        """Every live robot has voted and entered consensus."""
        record = self.rounds[round_index]
        return bool(np.all((record.phase >= CONSENSUS) | self.dead(round_index)))

    def complete(self, round_index: int = 0) -> bool:
        return bool(np.all(self.rounds[round_index].finished | self.dead(round_index)))

    def superseded(self, round_index: int) -> bool:
        """An unfinished round that no robot is in any more: every one has finished it, is dead
        or has moved to a later round (continuous camouflage)."""
        record = self.rounds[round_index]
        out = record.finished | self.dead(round_index) | (self.round_of > round_index)
        return bool(out.all()) and not self.complete(round_index)

    def close(self, round_index: int) -> None:
        """A round written or superseded: its record is let go (a 256x256 round's traces are
        tens of MB), and later reports of it are not recorded."""
        self.closed.add(round_index)
        record = self.rounds.pop(round_index, None)
        if record is not None and round_index >= self._shown[0]:
            self._shown = (round_index, record)  # the views show it until a later one begins
        # Its notice is written, and so are those of earlier rounds no robot reported in (a later
        # one superseded them first): their frames, pinned at the notice, are let go too.
        for noticed in [r for r in self.notices if r <= round_index]:
            if noticed == round_index or noticed not in self.heard:
                del self.notices[noticed]
                self.images.unpin(noticed)
        self.images.unpin(round_index)

    def progress_line(self, round_index: int = 0) -> str:
        record = self.rounds[round_index]
        counts = np.bincount(record.phase, minlength=5)
        parts = []
        for k in range(4):
            if counts[k]:
                steps = record.step[record.phase == k]
                where = f" (step {steps.min()}-{steps.max()})" if k >= CONSENSUS else ""
                parts.append(f"{PHASE_NAMES[k]} {counts[k]}{where}")
        busy = ", ".join(parts)
        extra = f"; hardware offline {int(self.offline.sum())}" if self.offline.any() else ""
        if record.deadlines.any():
            extra += f"; step deadlines passed {int(record.deadlines.sum())}"
        return (
            f"round {round_index}: robots done {int(record.finished.sum())}/{self.params.count}"
            f"{', ' + busy if busy else ''}; silent {int(self.dead(round_index).sum())}{extra}"
        )

    def result(self, round_index: int = 0, partial: bool = False) -> RunResult:
        return self.rounds[round_index].result(self.dead(round_index), partial)

    def write(
        self,
        round_index: int,
        folder: Path,
        label: str,
        partial: bool = False,
        extra: dict | None = None,
    ) -> dict:
        """summary.json, figure.png and run.gif of a round (partial: how far a stopped run
        got; `extra`: more fields for its summary)."""
        image = self.images.get(round_index)
        record, dead = self.record(round_index), self.dead(round_index)
        title = run_title(label, record.params, "robot nodes")  # the round's seed
        marks = record.marks(dead, self.bridged)
        snapshots = Snapshots.of_record(record)
        result = self.result(round_index, partial)
        # (the robots' processes are stopping meanwhile: the drawings share their cores)
        drawings = start_drawings(
            result, image, snapshots, record.sensed_shown, dead, folder, title, marks
        )
        try:
            incomplete = self.progress_line(round_index) if partial else None
            extra = {"rejected_messages": self.rejected_messages(), **(extra or {})}
            summary = round_summary(result, incomplete, extra)
            write_summary(summary, folder)
        except BaseException:
            drawings.stop()  # a round written again must not meet this one's drawings
            raise
        drawings.wait("figure.png and run.gif")
        return summary

    def _view(self) -> tuple[int, RoundRecord]:
        """The round the views show: the latest one recorded (or closed)."""
        latest = max(self.rounds, default=-1)
        if latest > self._shown[0] or self._shown[1] is None:
            return max(latest, 0), self.rounds[max(latest, 0)]
        return self._shown  # type: ignore[return-value]

    def _publish_pattern(self) -> None:
        latest = self._view()[1]
        shape = (self.params.rows, self.params.cols)
        pixels = np.where(latest.state < 0, 128, np.where(latest.state == 1, 0, 255))
        msg = image_to_msg(pixels.astype(np.uint8).reshape(shape), frame_id="swarm")
        msg.header.stamp = self.get_clock().now().to_msg()
        self.pattern_pub.publish(msg)

    def publish_views(self) -> None:
        """The 3D scene and the diagnostics of the latest round, to those who listen (thousands
        of cubes and statuses are not built for nobody)."""
        _, record = self._view()
        stamp = self.get_clock().now().to_msg()
        dead = record.dead(self.lost)
        if self.markers_pub.get_subscription_count():
            self.markers_pub.publish(scene.markers(record, dead, self.bridged, stamp))
        if self.diagnostics_pub.get_subscription_count():
            self.diagnostics_pub.publish(
                scene.diagnostics(record, dead, self.bridged, self.offline, stamp)
            )


def main(argv: list[str] | None = None) -> int:
    parser = Parser(prog="monitor_node", description="watch a running swarm and write its results")
    add_out_options(parser)
    parser.add_argument("--run-id", default=None, help="the run to watch (default: the only one)")
    parser.add_argument("--wait", type=seconds, default=60.0, help="seconds to wait for a run")
    add_network_options(parser)
    try:
        args, ros_args = parser.parse_with_ros_args(argv)
        os.environ.update(network_env(args, os.environ))
        run_id = check_run_id(args.run_id) if args.run_id is not None else None
        folder = out_dir(args)
    except CamoError as exc:
        print(f"monitor_node: error: {exc}", file=sys.stderr)
        return 2
    stop = StopFlag()
    start_ros("monitor_node", ros_args, signal_handler_options=SignalHandlerOptions.NO)
    executor = EventsExecutor()
    nodes: list[Node] = []
    try:
        reader = rclpy.create_node("monitor_join")
        nodes.append(reader)
        executor.add_node(reader)

        def spin() -> None:
            executor.spin_once(timeout_sec=0.1)

        topics = RunTopics(wait_for_run(reader, spin, run_id, args.wait, stop))
        setup = wait_for_setup(reader, spin, topics, args.wait, stop)
        monitor = MonitorNode(setup.params, topics, setup)
        nodes.append(monitor)
        executor.add_node(monitor)
        labels = list(setup.backgrounds) or ["background"]
        for index, label in enumerate(labels):
            last = 0.0
            while not monitor.complete(index) and not stop:
                executor.spin_once(timeout_sec=0.1)
                if time.monotonic() - last > 1.0:
                    print(f"monitor_node: {monitor.progress_line(index)}", file=sys.stderr)
                    last = time.monotonic()
            if stop:
                raise KeyboardInterrupt
            round_folder = folder if len(labels) == 1 else folder / f"round_{index}"
            round_folder.mkdir(exist_ok=True)
            summary = monitor.write(index, round_folder, label)
            print(f"round {index}: pattern {summary['pattern']}; wrote {round_folder}/")
        return 0
    except CamoError as exc:
        print(f"monitor_node: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    finally:
        executor.shutdown()
        for node in nodes:
            executor.remove_node(node)
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
