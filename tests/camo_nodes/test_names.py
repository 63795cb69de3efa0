"""Names the user gives that become ROS names: checked by rclpy's rules, in one line."""

import rclpy
from hypothesis import given, settings
from hypothesis import strategies as st
from std_msgs.msg import String
from support import ros_context

from camo_nodes.topics.names import TopicNameError, check_topic_name

NAMES = st.one_of(
    st.text(max_size=30),
    st.text(alphabet="/_~{}abc019 .", max_size=30),
    st.integers(1, 400).map(lambda n: "/" + "a" * n),
)


@settings(max_examples=150, deadline=None)
@given(name=NAMES)
def test_a_topic_name_passes_only_if_rclpy_takes_it_else_one_line(name):
    """The check refuses exactly what a node would refuse to subscribe to (at the root)."""
    try:
        check_topic_name(name, "--background-topic")
        refused = None
    except TopicNameError as exc:
        refused = str(exc)
    with ros_context() as context:
        node = rclpy.create_node("camo", context=context)
        try:
            node.create_subscription(String, name, lambda m: None, 1)
            taken = True
        except Exception:  # noqa: BLE001 - rclpy raises several kinds
            taken = False
        finally:
            node.destroy_node()
    assert taken == (refused is None), (name, refused)
    if refused is not None:
        assert "\n" not in refused and refused.startswith("--background-topic ")
