"""Topics taken with their publisher's GID: a node of their own that no executor spins, polled.

An executor that spun these subscriptions would take their messages first, and
rclpy hands a callback no publisher GID; `poll()` takes them through
`rcl_take.py` instead and calls each topic's handler with (CDR bytes, GID).
"""

from __future__ import annotations

from collections.abc import Callable

from rclpy.node import Node
from rclpy.qos import QoSProfile

from camo_nodes.rcl_take import Taker
from camo_nodes.topics.startup import LEAN_NODE

Handler = Callable[[bytes, bytes], None]


class PolledTopics:
    def __init__(self, name: str, namespace: str, context=None) -> None:
        self.node = Node(name, namespace=namespace, context=context, **LEAN_NODE)
        self.takers: list[tuple[Taker, Handler]] = []
        self._buffer: list[tuple[bytes, bytes]] = []

    def listen(self, msg_type, topic: str, qos: QoSProfile, handle: Handler) -> None:
        subscription = self.node.create_subscription(
            msg_type, topic, lambda m: None, qos, raw=True
        )
        self.takers.append((Taker(subscription), handle))

    def poll(self) -> int:
        """Hand every waiting message to its topic's handler; how many there were."""
        count = 0
        buffer = self._buffer
        for taker, handle in self.takers:
            if not taker.take_all(buffer):
                continue
            count += len(buffer)
            for data, gid in buffer:
                handle(data, gid)
            buffer.clear()
        return count

    def close(self) -> None:
        """Before the context goes: taking from a destroyed subscription crashes."""
        for taker, _ in self.takers:
            taker.close()
        self.takers.clear()
        self.node.destroy_node()
