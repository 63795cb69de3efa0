"""Names the user gives that become ROS names: checked by rclpy's rules, in one line."""

import rclpy
from hypothesis import example, given, settings
from hypothesis import strategies as st
from std_msgs.msg import String
from support import ros_context

from camo_nodes.topics.names import RunIdError, TopicNameError, check_run_id, check_topic_name

NAMES = st.one_of(
    st.text(max_size=30),
    st.text(alphabet="/_~{}abc019 .", max_size=30),
    st.integers(1, 400).map(lambda n: "/" + "a" * n),
)


@settings(max_examples=150, deadline=None)
@given(name=NAMES)
@example(name="{run}/x")  # a substitution rclpy does not know: a ValueError, not its exception
@example(name="{node}/x")
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


@settings(max_examples=150, deadline=None)
@given(run_id=st.one_of(st.text(max_size=45), st.text(alphabet="ab_1\n -", max_size=45)))
@example(run_id="abc\n")  # `$` matches before a last newline: the whole id must match
def test_a_run_id_passes_only_if_it_names_a_node_namespace_else_one_line(run_id):
    try:
        check_run_id(run_id)
        refused = None
    except RunIdError as exc:
        refused = str(exc)
    if refused is None:
        with ros_context() as context:
            node = rclpy.create_node("camo", namespace=f"/{run_id}/camo", context=context)
            node.destroy_node()
    else:
        assert "\n" not in refused
