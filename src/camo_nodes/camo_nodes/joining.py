"""A process joining a run started elsewhere (a worker, a monitor): the run's setup, as its
launcher published it."""

from __future__ import annotations

import time

from std_msgs.msg import String

from camo_nodes.topics import LATCHED_READER, NoRun, RunTopics, setup_from


def wait_for_setup(node, spin, topics: RunTopics, timeout: float, stop=None) -> dict:
    """The run's /swarm/params (latched) as the launcher published it."""
    got: list[dict] = []

    def take(msg: String) -> None:
        setup = setup_from(msg.data, topics.run)
        if setup is not None:
            got.append(setup)

    subscription = node.create_subscription(String, topics.params, take, LATCHED_READER)
    deadline = time.monotonic() + timeout
    try:
        while not got and not stop:
            if time.monotonic() > deadline:
                raise NoRun(f"no parameters on {topics.params} after {timeout:g} s")
            spin()
        if node.count_publishers(topics.params) > 1:
            raise NoRun(
                f"{node.count_publishers(topics.params)} processes publish the parameters of "
                f"{topics.run}: cannot tell which is its launcher"
            )
    finally:
        node.destroy_subscription(subscription)
    if stop:
        raise KeyboardInterrupt
    return got[0]
