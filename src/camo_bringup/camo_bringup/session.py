"""The launcher's own ROS side: its node (the run's parameters, the background switch), the
monitor, one executor that spins them, and the waits a run needs."""

from __future__ import annotations

import time
from collections.abc import Iterable

from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from std_msgs.msg import String

from camo_bringup.camouflage_action import CamouflageAction
from camo_bringup.failures import EXIT_CONFLICT, Interrupted, RunFailed
from camo_bringup.recording import Recorders
from camo_bringup.run_config import RunConfig
from camo_core.shutdown import StopFlag
from camo_nodes.host import host_node_name
from camo_nodes.monitor_node import MonitorNode
from camo_nodes.topics import keyed
from camo_nodes.topics.qos import LATCHED
from camo_nodes.trust import OWN_TILES_CLAIMED as CLAIMED

HOSTS_SETTLE = 2.0  # s: a host the graph shows has its latched announcement taken by then


class Session:
    """The launcher's nodes (the monitor, and a node that publishes the run's parameters and
    switches backgrounds) in one executor, the recorders they hear from, and the waits."""

    def __init__(self, config: RunConfig, stop: StopFlag, context=None) -> None:
        self.config = config
        self.stop = stop
        topics = config.topics
        self.topics = topics
        self.node = Node("launcher", namespace=topics.swarm_namespace, context=context)
        # rclpy's own executor: its EventsExecutor can crash destroying a node at the run's end
        # while another process still writes to it (rclpy issue 1644, seen in CI).
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.action: CamouflageAction | None = None  # served once the run's nodes are up
        if config.named:
            self.refuse_a_live_run()
        setup = config.setup()
        self.setup = setup
        self.monitor = MonitorNode(config.params, topics, setup, context=context)
        self.executor.add_node(self.monitor)
        self.loader = keyed.publisher(self.node, String, topics.load, 10, topics.run)
        self.started = time.monotonic()
        keyed.publisher(self.node, String, topics.params, LATCHED, topics.run).publish(
            String(data=setup.to_json())
        )
        self.recorders = Recorders(self)
        self.action = CamouflageAction(self)

    def refuse_a_live_run(self, settle: float = 1.0) -> None:
        """Two launchers of one run id would share its topics: the second refuses to start."""
        deadline = time.monotonic() + settle  # discovery needs a moment to show a live run
        while time.monotonic() < deadline:
            if self.node.count_publishers(self.topics.params):
                raise RunFailed(
                    f"a run named {self.topics.run} is already running in this domain; "
                    f"choose another --run-id (or leave it out for a new one)",
                    EXIT_CONFLICT,
                )
            self.spin(0.05)

    def check_hosts(self, started: Iterable[int], final: bool = False) -> None:
        """RunFailed (code 2) once a tile of the run's own processes (`started`: their pids) is
        announced by another process, first or not: every process that heard it first trusts it
        as the tile's host (trust.py) and never hears the run's own robots there, which no
        process can tell of another, so the run could only wait for good. Its own processes are
        told by the name they announce (host_node_name); cells left to remote workers are
        anyone's to take. Said once the run's own processes have announced theirs (they are
        past their start, and stop cleanly), or after the discovery timeout.

        `final`: before a round is written. A small run can finish before the stranger's
        announcement is taken (the monitor may have heard the run's own host first, and its
        robots each other), yet a process that heard the stranger first computed without the
        run's robots there: the announcements of every host the graph shows are waited for
        (at most HOSTS_SETTLE s), then any conflict ends the run. A process of the run that
        hears another announce its tiles says so at once (trust.OWN_TILES_CLAIMED): that ends
        the run too, even before this process hears the other (named if it does within the
        discovery timeout)."""
        ours = {host_node_name(pid) for pid in started}
        hosts = self.monitor.trusted
        if final:
            deadline = time.monotonic() + HOSTS_SETTLE
            while (
                self.node.count_publishers(self.topics.hosts) > len(hosts.names)
                and time.monotonic() < deadline
            ):
                self.spin(0.05)

        def others():
            return hosts.held_by_others(self.setup.tiles, lambda p: hosts.names.get(p) in ours)

        conflict = others()
        # Processes of the run that heard another announce their cells (said at once in their
        # own announcements): a conflict even before this process hears that one.
        told = [
            name
            for prefix, name in hosts.names.items()
            if name in ours and hosts.refused.get(prefix, {}).get("by_reason", {}).get(CLAIMED)
        ]
        if conflict is None and told:
            conflict = self._hear_claimant(others)
        if conflict is None and not told:
            return
        waited = time.monotonic() - self.started
        settled = ours <= set(hosts.names.values()) or waited > self.setup.discovery_timeout
        if told or final or settled:
            who = f"({conflict.process})" if conflict else f"(heard by {told[0]}, not here)"
            raise RunFailed(
                f"run {self.topics.run}: cells {conflict.cells if conflict else 'of ' + told[0]} "
                f"were announced by a process this run did not start {who}: wherever it was "
                f"heard first, the run's own robots there go unheard; stop that process or "
                f"choose another --run-id",
                EXIT_CONFLICT,
            )

    def _hear_claimant(self, conflict):
        """One of the run's processes reported another announcing its cells, which this one
        has not heard yet: the claimant's announcement, waited for (discovery under load takes
        seconds) at most the discovery timeout, to say who it is."""
        deadline = time.monotonic() + self.setup.discovery_timeout
        while (found := conflict()) is None and time.monotonic() < deadline:
            self.spin(0.05)
        return found

    def spin(self, seconds: float = 0.1) -> None:
        if self.stop:
            raise Interrupted
        self.executor.spin_once(timeout_sec=seconds)
        if self.action is not None:
            self.action.update()

    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            self.spin(left)

    def wait(self, done, what: str, limit: float) -> None:
        deadline = time.monotonic() + limit
        while not done():
            if time.monotonic() > deadline:
                raise RunFailed(f"{what} after {limit:g} s")
            self.spin()

    def switch_background(self, label: str, limit: float = 60.0) -> None:
        """/camo/projector/load is volatile: it reaches only a projector matched when sent."""
        self.wait(
            lambda: self.loader.get_subscription_count() > 0,
            f"no projector listens on {self.topics.load}",
            limit,
        )
        self.loader.publish(String(data=label))

    def close(self) -> None:
        if self.action is not None:
            self.action.close()
        # Executor first, then nodes, then context: the nodes' handles are let go of before
        # they are destroyed.
        self.executor.shutdown()
        for node in (self.monitor, self.node):
            self.executor.remove_node(node)
            node.destroy_node()
