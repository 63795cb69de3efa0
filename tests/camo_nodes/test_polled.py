"""A poll takes a bounded batch of each topic's messages, however fast they come: the loop that
polls gets back to its stop flag, timers and heartbeat."""

import time

import rclpy
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String
from support import ros_context

from camo_nodes.polled import PolledTopics

KEEP_ALL = QoSProfile(
    depth=1,
    history=HistoryPolicy.KEEP_ALL,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)


def test_a_flood_is_taken_a_bounded_batch_per_poll_in_order_and_all_of_it():
    with ros_context() as context:
        writer_node = rclpy.create_node("flood", context=context)
        writer = writer_node.create_publisher(String, "/flood", KEEP_ALL)
        polled = PolledTopics("flood_listener", "/", context)
        got: list[bytes] = []
        polled.listen(String, "/flood", KEEP_ALL, lambda data, gid: got.append(data), limit=50)
        for k in range(300):
            writer.publish(String(data=str(k)))
        deadline = time.monotonic() + 10
        while not got and time.monotonic() < deadline:
            polled.poll()
        taken = []
        while len(got) < 300 and time.monotonic() < deadline:
            before = len(got)
            polled.poll()
            taken.append(len(got) - before)
        assert len(got) == 300 and max(taken) <= 50
        assert polled.more or taken[-1] < 50  # it says when it left messages waiting
        from rclpy.serialization import deserialize_message

        assert [deserialize_message(d, String).data for d in got] == [str(k) for k in range(300)]
        polled.close()
        writer_node.destroy_node()
