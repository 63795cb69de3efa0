"""Topics taken with their publisher's GID: a node of their own that no executor spins, polled.

An executor that spun these subscriptions would take their messages first, and
rclpy hands a callback no publisher GID; `poll()` takes them through
`rcl_take.py` instead and calls each topic's handler with (CDR bytes, GID).
In a keyed run (`keyed.py`) a handler gets only the messages the run's key
tagged, the trailer taken off; the others go to `refuse`.
"""

from __future__ import annotations

from collections.abc import Callable

from rclpy.node import Node
from rclpy.qos import QoSProfile

from camo_nodes.rcl_take import Taker
from camo_nodes.topics.keyed import Refuse, opener, unsealing
from camo_nodes.topics.startup import LEAN_NODE

Handler = Callable[[bytes, bytes], None]
# Messages taken from one topic per poll at most (unless its listen() says otherwise): a poll's
# work is bounded, so that its caller's loop (stop flag, timers, heartbeats) turns however fast
# messages come. What is left waits in the DDS reader for the next poll.
TAKE_LIMIT = 64


class PolledTopics:
    def __init__(
        self, name: str, namespace: str, context=None, run: str = "", refuse: Refuse | None = None
    ) -> None:
        """`run`, `refuse`: the run whose key its messages must carry (if the process has one)
        and what is told of those that do not."""
        self.node = Node(name, namespace=namespace, context=context, **LEAN_NODE)
        self.run = run
        self.refuse = refuse or (lambda reason, gid: None)
        self.takers: list[tuple[Taker, Handler, int]] = []
        self._buffer: list[tuple[bytes, bytes]] = []
        self.more = False  # the last poll left messages waiting

    def listen(
        self, msg_type, topic: str, qos: QoSProfile, handle: Handler, limit: int = TAKE_LIMIT
    ) -> None:
        """`limit`: messages taken per poll at most (an array of robot messages costs more than
        a heartbeat)."""
        subscription = self.node.create_subscription(
            msg_type, topic, lambda m: None, qos, raw=True
        )
        opened = opener(self.run) if self.run else None
        handle = unsealing(handle, subscription.topic_name, opened, self.refuse)
        self.takers.append((Taker(subscription), handle, limit))

    def poll(self) -> int:
        """Hand each topic's waiting messages, up to its limit, to its handler; how many there
        were (`more`: whether a topic may have more waiting)."""
        count = 0
        buffer = self._buffer
        self.more = False
        for taker, handle, limit in self.takers:
            taken = taker.take(buffer, limit)
            if not taken:
                continue
            self.more = self.more or taken == limit
            count += taken
            for data, gid in buffer:
                handle(data, gid)
            buffer.clear()
        return count

    def close(self) -> None:
        """Before the context goes: taking from a destroyed subscription crashes."""
        for taker, _, _ in self.takers:
            taker.close()
        self.takers.clear()
        self.node.destroy_node()
