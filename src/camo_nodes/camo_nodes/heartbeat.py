"""A process's heartbeat: sent from a thread of its own, so that a busy process is not a dead one.

The robots of a process share its loop; when they keep it busy (thousands of
them, a slow machine, a throttled container) their messages come late, but the
process is alive, and its neighbours must wait for it rather than give up
(`camo_core.swarm.liveness`). The heartbeat thread wakes every
HEARTBEAT_PERIOD, takes the interpreter's lock for a few microseconds and
publishes one small message: a process that can still run Python at all
beats. One that is killed, or stopped (SIGSTOP), or whose machine is gone,
does not.
"""

from __future__ import annotations

import threading
import time

from rclpy.node import Node

from camo_core.swarm.liveness import HEARTBEAT_PERIOD
from camo_msgs.msg import Heartbeat
from camo_nodes.topics import keyed
from camo_nodes.topics.names import RunTopics
from camo_nodes.topics.qos import HEARTBEAT_WRITER


class HeartbeatThread:
    """Publishes the process's heartbeat every HEARTBEAT_PERIOD until closed."""

    def __init__(self, node: Node, topics: RunTopics, period: float = HEARTBEAT_PERIOD) -> None:
        self.period = period
        self.publisher = keyed.publisher(
            node, Heartbeat, topics.heartbeat, HEARTBEAT_WRITER, topics.run
        )
        self.msg = Heartbeat(name=node.get_name())
        self.msg.header.frame_id = "camo"
        self.offline: tuple[int, ...] = ()  # robots whose hardware is off, set by the host's loop
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._beat, name="camo-heartbeat", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def _beat(self) -> None:
        msg = self.msg
        while not self._stop.is_set():
            msg.offline = list(self.offline)
            stamp = msg.header.stamp
            now = time.time_ns()
            stamp.sec, stamp.nanosec = divmod(now, 1_000_000_000)
            try:
                self.publisher.publish(msg)
            except Exception:  # noqa: BLE001 - the context is going away: the process ends
                return
            msg.sequence += 1
            self._stop.wait(self.period)

    def close(self) -> None:
        """Before the node goes: no publish on a destroyed publisher."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
