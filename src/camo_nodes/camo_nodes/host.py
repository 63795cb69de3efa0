"""A process hosting robots: the background, the clock and the spin loop they share.

Every process with robots runs one Host: a worker started by the launcher or by
hand on another machine, a robot alone (`robot_node`), a Droplet bridge. It
owns one node of its own, which holds the transport's DDS endpoints
(`transport.py`, with the process's heartbeat), the background subscription and
the one timer that ticks the robots whose deadline is due; its loop spins the
executor and polls the transport. Each turn of the loop does a bounded amount of
work (a batch of robots started or shown a new background, a bounded take, 20
ms of handing messages over), so that its timers and stop flag keep up whatever
the number of robots.
"""

from __future__ import annotations

import gc
import os
import socket
import time
from functools import partial

import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import Image

from camo_core.algorithm.liveness import HEARTBEAT_PERIOD
from camo_core.algorithm.protocol import TICK
from camo_core.algorithm.sensing import ImageError, Projection, image_digest
from camo_core.algorithm.ticks import Ticks
from camo_nodes.topics.images import ImageEncodingError, image_from_msg
from camo_nodes.topics.names import RunTopics
from camo_nodes.topics.qos import LATCHED_READER
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
# Robots started, or shown a new background, per turn of the loop; robots ticked per tick at
# most: each costs tens of microseconds, and a turn stays short.
BATCH = 256
TICKS_PER_TURN = 2048


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
    participants the robot nodes were created in, ended after them."""

    def __init__(
        self,
        node: Node,
        transport: Transport,
        projection: Projection,
        robots: list,
        spin_robots: bool,
        hardware: tuple[int, ...] = (),
        participants: Participants | None = None,
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
        self._stamps: set[tuple[int, int]] = set()
        self.spun = [node, *robots] if spin_robots else [node]
        self.backgrounds = BackgroundCheck(transport.setup)
        # Robots still to start, and to be told of a new background: a bounded number a turn.
        self._to_start = 0 if robots else None
        self._to_show: int | None = None
        transport.listen(
            Image, transport.topics.background, LATCHED_READER, self._on_background, 1
        )
        node.create_timer(TICK, self._tick)
        node.create_timer(1.0, transport.announce_rejections)
        if hardware:
            node.create_timer(HEARTBEAT_PERIOD, self._hardware_state)

    def _on_background(self, data: bytes, gid: bytes) -> None:
        msg = deserialize_message(data, Image)
        stamp = (msg.header.stamp.sec, msg.header.stamp.nanosec)
        if stamp in self._stamps:
            return
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
        self._stamps.add(stamp)
        try:
            self.projection.add(image)
        except ImageError as exc:
            self.node.get_logger().error(f"background not used: {exc}")
            return
        self._to_show = 0  # every robot is told, a batch a turn (`_work`)

    def _work(self) -> bool:
        """A batch of robots started or shown the new background; whether any is left."""
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
                self.robots[index].background(now)
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
