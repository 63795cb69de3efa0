"""A process hosting robots: the background, the clock and the spin loop they share.

Every process with robots runs one Host: a worker started by the launcher or by
hand on another machine, a robot alone (`robot_node`), a Droplet bridge. It
owns one node of its own, which holds the transport's DDS endpoints
(`transport.py`, with the process's heartbeat), the background subscription and
the one timer that ticks the robots whose deadline is due; its loop spins the
executor and polls the transport. Each turn of the loop does a bounded amount of
work (a batch of robots started, shown a new background or told they noticed a
change, a bounded take, 20 ms of handing messages over), so that its timers and
stop flag keep up whatever the number of robots.
"""

from __future__ import annotations

import gc
import itertools
import os
import socket
import time
from collections import OrderedDict
from functools import partial

import numpy as np
import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import Image

from camo_core.algorithm.change import Watch
from camo_core.algorithm.sensing import Projection, image_digest
from camo_core.inputs.images import ImageError
from camo_core.swarm.liveness import HEARTBEAT_PERIOD
from camo_core.swarm.protocol import TICK
from camo_core.swarm.run_setup import ProtocolParams
from camo_core.swarm.ticks import Ticks
from camo_msgs.msg import Notices
from camo_nodes.topics import keyed
from camo_nodes.topics.images import ImageEncodingError, frame_number, image_from_msg
from camo_nodes.topics.names import RunTopics
from camo_nodes.topics.qos import LATCHED_READER, history_qos
from camo_nodes.topics.startup import LEAN_NODE, Participants
from camo_nodes.transport import Transport
from camo_nodes.trust import BackgroundCheck

# The loop polls the transport's edge readers between turns of the executor (timers, the
# background, hosts' announcements). While messages flow it waits at most POLL_BUSY for the
# executor, so that a message from another process waits no longer than that; after IDLE
# without one, POLL_IDLE. The executor serves only timers (and a lone robot's services), and a
# turn of it costs about 0.1 ms: while messages flow it turns every SPIN_EVERY.
POLL_BUSY = 0.0002
POLL_IDLE = 0.005
IDLE = 0.05
SPIN_EVERY = 0.02  # s between turns of the executor while messages keep coming
# Robots started, shown a new background or told they noticed a change, per turn of the loop;
# robots ticked per tick at most: each costs tens of microseconds, and a turn stays short.
BATCH = 256
TICKS_PER_TURN = 2048
STAMPS_KEPT = 1024  # backgrounds remembered by stamp (a frame heard again is not new)
NOTICES_KEPT = 64  # notices a late monitor still gets


def host_node_name(pid: int | None = None) -> str:
    """The name of the node of a process hosting robots on this machine (this one's by
    default): worker_<machine>_<pid>. What its Host announcements say it is."""
    name = f"worker_{socket.gethostname().split('.')[0]}_{os.getpid() if pid is None else pid}"
    return "".join(c if c.isalnum() else "_" for c in name).lower()


def host_node(topics: RunTopics) -> Node:
    """The process's own node: /<run>/camo/worker_<machine>_<pid>."""
    return Node(host_node_name(), namespace=topics.robot_namespace, **LEAN_NODE)


GC_THRESHOLD = 20_000  # allocations between young-generation collections (Python's: 700)


class Host:
    """Robots are duck-typed: start(), tick(now), background(now), report_now(now), their
    `protocol` (due(), stalled()), and a Node to spin when `spin_robots` (robots with services
    of their own).
    `hardware`: indices of robots with a real sensor or display (ticked every TICK while they
    wait for it, and said offline in the heartbeat when it is). `participants`: the DDS
    participants the robot nodes were created in, ended after them. `protocol`: the run's
    protocol parameters; with `continuous`, the robots watch their readings (`change.Watch`,
    one reading every `sense_period` for all of them) and start rounds themselves."""

    def __init__(
        self,
        node: Node,
        transport: Transport,
        projection: Projection,
        robots: list,
        spin_robots: bool,
        hardware: tuple[int, ...] = (),
        participants: Participants | None = None,
        protocol: ProtocolParams | None = None,
    ) -> None:
        self.node = node
        self.transport = transport
        self.projection = projection
        self.robots = robots
        self.hardware = hardware
        self.participants = participants
        transport.check_hosted()
        self.ticks = Ticks([robot.protocol for robot in robots])
        for index, robot in enumerate(robots):
            robot.stepped = partial(self.ticks.add, index)
            robot.joined = partial(self._joined, index)
        self._stamps: OrderedDict[tuple[int, int], None] = OrderedDict()
        self.spun = [node, *robots] if spin_robots else [node]
        self.backgrounds = BackgroundCheck(transport.setup)
        # Robots still to start, and to be told of a new background: a bounded number a turn.
        self._to_start = 0 if robots else None
        self._to_show: int | None = None
        self.shown = 0  # the number of the frame last projected
        self._substituted = 0
        # Frames are named by the projector's numbers only in a continuous run: elsewhere the
        # k-th background taken is round k (a background the hosts refused counts for nothing).
        self.numbered = protocol is not None and protocol.continuous
        transport.listen(
            Image, transport.topics.background, LATCHED_READER, self._on_background, 1
        )
        node.create_timer(TICK, self._tick)
        node.create_timer(1.0, transport.announce_rejections)
        if hardware:
            node.create_timer(HEARTBEAT_PERIOD, self._hardware_state)
        self.watch: Watch | None = None
        if protocol is not None and protocol.continuous and robots:
            ids = np.array([robot.protocol.id for robot in robots])
            params = robots[0].protocol.base_params
            self.watch = Watch(ids, params, protocol.change_window, protocol.change_threshold)
            self.idle = np.array([robot.protocol.round < 0 for robot in robots])
            self._joins: list[int] = []
            # Robots that noticed a change, still to be told (a batch a turn, `_work`), in the
            # order they noticed: index -> (the frame they read it in, when the change was
            # first seen, when they noticed); `_notice`: those told so far that started a
            # round, for the monitor once all are told.
            self._noticing: dict[int, tuple[int, float, float]] = {}
            self._notice = Notices(name=node.get_name())
            self.notices = keyed.publisher(
                node,
                Notices,
                transport.topics.notices,
                history_qos(NOTICES_KEPT),
                transport.topics.run,
            )
            node.create_timer(protocol.sense_period, self._read)
            node.create_timer(1.0, self._forget)

    def _joined(self, index: int, round_: int) -> None:
        """Robot `index` is in round `round_` now: its watch looks for its reference anew."""
        if self.watch is not None:
            self._joins.append(index)
            self.idle[index] = False
        self.projection.protected.add(round_)  # its frame is kept while a robot is in it

    def _read(self) -> None:
        """Continuous camouflage: every robot reads the newest frame; those that notice a change
        are told so a batch a turn (`_notice_batch`), each with the frame of this reading."""
        grid = self.projection.latest
        if grid is None or self.watch is None:
            return
        if self._joins:
            self._reset(self._joins)
        frame = self.projection.newest
        judged = self.watch.read(grid, frame, self.idle)
        if not len(judged.robots):
            return
        wall = self.node.get_clock().now().nanoseconds * 1e-9
        stamps, noticing = self.projection.stamps, self._noticing
        for index, changed in zip(
            judged.robots.tolist(), judged.changed_frames.tolist(), strict=True
        ):
            # A robot not told yet keeps its first notice: its watch still holds the reference
            # it noticed against, and judges it again until it is told.
            if index not in noticing:
                noticing[index] = (frame, stamps.get(changed, wall), wall)
        self.projection.protected.add(frame)  # read off by those robots once they are told

    def _notice_batch(self) -> None:
        """A batch of the robots that noticed a change told so: each starts the round of the
        frame it noticed it in (unless it is in that round or a later one by now), and its watch
        takes a new reference. Once all are told, who started a round goes to the monitor."""
        now = time.monotonic()
        noticing, notice = self._noticing, self._notice
        batch = list(itertools.islice(noticing, BATCH))
        for index in batch:
            frame, changed_at, noticed_at = noticing.pop(index)
            robot = self.robots[index]
            before = robot.protocol.round
            robot.notice(frame, now)
            if robot.protocol.round != before:
                notice.robot.append(robot.protocol.id)
                notice.round.append(frame)
                notice.changed_at.append(changed_at)
                notice.noticed_at.append(noticed_at)
        self._reset(batch)  # noticed: a new reference, joined or not
        if not noticing and notice.robot:
            notice.header.stamp = self.node.get_clock().now().to_msg()
            notice.header.frame_id = "camo"
            self.notices.publish(notice)
            self._notice = Notices(name=self.node.get_name())

    def _reset(self, robots: list[int]) -> None:
        """New references for these robots, from their rounds' frames; those whose frame has not
        come yet wait for it."""
        assert self.watch is not None
        by_round: dict[int, list[int]] = {}
        for index in robots:
            by_round.setdefault(self.robots[index].protocol.round, []).append(index)
        resetting = set(robots)
        self._joins = [index for index in self._joins if index not in resetting]  # still to do
        for round_, indices in by_round.items():
            grid = self.projection.frames.get(round_) if round_ >= 0 else None
            if round_ >= 0 and grid is None and round_ > self.projection.newest:
                self._joins.extend(indices)  # its frame is on its way
                continue
            self.watch.reset(indices, grid, round_)

    def _forget(self) -> None:
        """Drop what was kept of rounds no hosted robot is in any more; keep the frames of those
        they are in; say once more a frame had to be read in place of one let go."""
        rounds = {robot.protocol.round for robot in self.robots}
        self.projection.protected = rounds | {f for f, _, _ in self._noticing.values()}
        earliest = min(rounds)
        if earliest > 0:
            self.transport.forget_before(earliest)
        if self.projection.substituted > self._substituted:
            self._substituted = self.projection.substituted
            self.node.get_logger().warning(
                f"{self._substituted} readings were of a frame other than their round's (it "
                "came before this process joined, or was let go): those rounds can differ "
                "from ./camo sim on their frame"
            )

    def _on_background(self, data: bytes, gid: bytes) -> None:
        msg = deserialize_message(data, Image)
        stamp = (msg.header.stamp.sec, msg.header.stamp.nanosec)
        if stamp in self._stamps:
            return
        number = frame_number(msg.header.frame_id) if self.numbered else None
        try:
            image = image_from_msg(msg)
        except ImageEncodingError:
            self.transport.rejected.refuse("a background that cannot be decoded", gid)
            return
        problem = self.backgrounds.problem(image_digest(image), gid)
        if problem is not None:
            if problem != BackgroundCheck.REPEAT:
                self.transport.rejected.refuse(problem, gid)
            return
        self._stamps[stamp] = None
        if len(self._stamps) > STAMPS_KEPT:
            self._stamps.popitem(last=False)
        if number is not None and number in self.projection.frames:
            return  # a frame already held, stamped anew
        try:
            self.shown = self.projection.add(image, number, stamp[0] + stamp[1] * 1e-9)
        except ImageError as exc:
            self.node.get_logger().error(f"background not used: {exc}", throttle_duration_sec=5.0)
            return
        if self.watch is None:
            self._to_show = 0  # every robot is told, a batch a turn (`_work`)

    def _work(self) -> bool:
        """A batch of robots told they noticed a change, started or shown the new background;
        whether any is left. Those that noticed go first: a robot not started when it noticed
        is not started when it is told, as if told at once."""
        if self.watch is not None and self._noticing:
            self._notice_batch()
            return True
        now = time.monotonic()
        if self._to_start is not None:
            first, self._to_start = self._to_start, self._to_start + BATCH
            for index in range(first, min(self._to_start, len(self.robots))):
                self.robots[index].start()
            if self._to_start >= len(self.robots):
                self._to_start = None
            return True
        if self._to_show is not None:
            first, self._to_show = self._to_show, self._to_show + BATCH
            for index in range(first, min(self._to_show, len(self.robots))):
                self.robots[index].background(now, self.shown)
            if self._to_show >= len(self.robots):
                self._to_show = None
            return True
        return False

    def _tick(self) -> None:
        now = time.monotonic()
        self.ticks.stall(now)
        robots, ticks = self.robots, self.ticks
        for index in (*ticks.due(now, TICKS_PER_TURN), *self.hardware):
            robots[index].tick(now)
            ticks.add(index, now)  # again: at its next deadline, or to ask again

    def _hardware_state(self) -> None:
        offline = frozenset(
            self.robots[i].protocol.id for i in self.hardware if not self._hardware_ok(i)
        )
        if offline != self.transport.offline:
            self.transport.set_offline(offline)

    def _hardware_ok(self, index: int) -> bool:
        protocol = self.robots[index].protocol
        return protocol.sensor.ok() and protocol.display.ok()

    def _loop(self, executor, stop, until) -> None:
        transport = self.transport
        last_message = next_turn = time.monotonic()
        while not stop and rclpy.ok() and not (until and until()):
            working = self._work()
            taken = transport.poll()
            now = time.monotonic()
            if now >= next_turn:  # the executor's turn (a turn costs more than a poll)
                executor.spin_once(timeout_sec=0.0)
                next_turn = now + SPIN_EVERY
            transport.flush()  # what the robots sent in this turn, an array per topic
            if taken or working or transport.busy:
                last_message = now
            elif now - last_message < IDLE:
                time.sleep(POLL_BUSY)  # the next message is near: a short sleep, then poll
            else:
                executor.spin_once(timeout_sec=POLL_IDLE)  # idle: let the executor wait

    def run(
        self, stop=None, until=None, extra_nodes: tuple[Node, ...] = (), destroy: bool = True
    ) -> int:
        """Start every robot and spin until Ctrl-C, SIGTERM, shutdown or `until()`. What the
        robots reported is written, and acknowledged by its readers, before this returns.
        `destroy=False` leaves the nodes for the process's exit to take: destroying thousands
        of nodes one by one costs longer than creating them (each says the graph anew), and a
        worker that exits (os._exit) needs none of it."""
        # The robots and their nodes live as long as the loop: kept out of the collector's
        # scans (a full scan of a 2048-robot process takes tens of ms), and the collector runs
        # less often, since stepping makes short-lived objects without cycles (measured: a
        # 64x64 worker spent 8% of its time collecting; docs/swarm.md).
        gc.freeze()
        gc.set_threshold(GC_THRESHOLD, *gc.get_threshold()[1:])
        executor = EventsExecutor()
        nodes = [*self.spun, *extra_nodes]
        transport = self.transport
        try:
            for node in nodes:
                executor.add_node(node)
            # spin_once in a loop: EventsExecutor.spin() busy-waits and starves its timers here.
            self._loop(executor, stop, until)
        except KeyboardInterrupt:
            pass
        finally:
            # Stopped mid-round (Ctrl-C, the run's end): each robot reports what it did since
            # its last report, which went out up to a second ago, before the last statuses go.
            now = time.monotonic()
            for robot in self.robots:
                robot.report_now(now)
            transport.close()
            if destroy:
                # Executor first, then nodes: the EventsExecutor must let go of the nodes'
                # handles before they are destroyed, or interpreter exit can crash.
                executor.shutdown()
                for node in nodes:
                    executor.remove_node(node)
                for node in [*nodes, *(r for r in self.robots if r not in nodes)]:
                    node.destroy_node()
                if self.participants is not None:
                    self.participants.shutdown()
        return 0
