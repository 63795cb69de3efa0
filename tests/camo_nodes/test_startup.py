"""How a process's many lean nodes are spread over DDS participants: every node is in the ROS
graph whatever participant holds it, and the participants a process added end with it."""

import os
import subprocess
import sys
import time

import pytest
import rclpy
from rclpy.node import Node
from support import PROCESS, domain, ros_context

from camo_nodes.topics.startup import GROUPED_NODE, LEAN_NODE, Participants


def graph_names(node: Node, wanted: set[str], timeout: float = 10.0) -> set[str]:
    """The node names `node` sees in the graph, once it sees all of `wanted` (or at `timeout`)."""
    deadline = time.monotonic() + timeout
    while True:
        names = {name for name, _ in node.get_node_names_and_namespaces()}
        if wanted <= names or time.monotonic() > deadline:
            return names
        time.sleep(0.05)


def test_nodes_beyond_a_participants_share_go_to_new_participants_and_all_are_in_the_graph():
    with ros_context() as context:
        participants = Participants(context, per=3)
        nodes = [
            Node(f"grouped_{k}", **LEAN_NODE, **GROUPED_NODE, context=participants.next())
            for k in range(7)
        ]
        contexts = [node.context for node in nodes]
        assert contexts[:3] == [context] * 3  # the first share the process's own
        assert len(participants.contexts) == 3
        assert contexts[3:6] == [participants.contexts[1]] * 3 and contexts[6] is not context
        domain = context.get_domain_id()
        assert all(c.get_domain_id() == domain for c in participants.contexts)
        observer = rclpy.create_node("observer", context=context)
        wanted = {f"grouped_{k}" for k in range(7)}
        assert wanted <= graph_names(observer, wanted)
        for node in nodes:
            node.destroy_node()
        participants.shutdown()
        assert [c.ok() for c in participants.contexts] == [True, False, False]
        # The added participants' nodes leave the graph with them.
        deadline = time.monotonic() + 10.0
        while wanted & graph_names(observer, set()) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not wanted & graph_names(observer, set())
        observer.destroy_node()


@pytest.mark.slow(PROCESS)
@pytest.mark.parametrize("rule", [":=x", "a:="])
def test_a_remap_rule_rcl_refuses_is_one_line_without_rcls_log(rule):
    # rcl logged "[ERROR] [rcl]: Failed to parse global arguments" above camo's own line.
    done = subprocess.run(
        [sys.executable, "-m", "camo_projector.projector_node", "--ros-args", "-r", rule],
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "ROS_DOMAIN_ID": str(domain())},
    )
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    assert lines[0].startswith("projector_node: error: ROS arguments refused: Couldn't parse")
