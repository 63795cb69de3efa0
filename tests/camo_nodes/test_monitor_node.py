"""The monitor: the swarm's pattern image, one record per round, offline hardware, and what came
before its host's word taken over several turns, in order."""

import time

import numpy as np
import pytest
from support import SWARM, domain, finished, ros_context, start_run


@pytest.mark.slow(SWARM)
def test_monitor_publishes_the_swarm_pattern_as_an_image(tmp_path):
    import rclpy
    from sensor_msgs.msg import Image

    domain_id = domain()
    # A long consensus, stopped with Ctrl-C once the picture is complete.
    proc = start_run(
        "--pattern",
        "forest",
        "--rows",
        "5",
        "--cols",
        "7",
        "--procs",
        "1",
        "--consensus-steps",
        "100000",
        "--run-id",
        "pattern",
        "--out",
        str(tmp_path),
        domain_id=domain_id,
    )
    images = []
    try:
        with ros_context(domain_id) as context:
            node = rclpy.create_node("pattern_viewer", context=context)
            node.create_subscription(Image, "/pattern/swarm/pattern", images.append, 10)
            executor = rclpy.executors.SingleThreadedExecutor(context=context)
            executor.add_node(node)
            deadline = time.monotonic() + 120
            while time.monotonic() < deadline and not any(
                set(bytes(m.data)) <= {0, 255} for m in images
            ):
                executor.spin_once(timeout_sec=0.2)
            executor.shutdown()
            node.destroy_node()
    finally:
        proc.send_signal(2)
        _, err = finished(proc, 120)
    assert images, f"no /swarm/pattern image; launcher said: {err[-1500:]}"
    complete = [m for m in images if set(bytes(m.data)) <= {0, 255}]
    assert complete, (
        f"{len(images)} images, none with every robot's state; launcher said: {err[-1500:]}"
    )
    last = complete[0]
    assert (last.height, last.width, last.encoding) == (5, 7, "mono8")
    # Every pixel is a robot's state (black on, white off): the forest's initial stripes here.
    assert bytes(last.data) != bytes([last.data[0]]) * 35
    assert proc.returncode == 130


HOST_GID = bytes(range(16))  # the writer of the statuses and of the host announcement


def hosting_all(monitor, count: int) -> None:
    """A host announcement, as if polled, that gives robots 0..count-1 to HOST_GID's process."""
    from rclpy.serialization import serialize_message

    from camo_msgs.msg import Host

    monitor._on_host(serialize_message(Host(name="w", first=[0], last=[count - 1])), HOST_GID)


def status(**fields):
    """One robot's report in a process's StatusArray, as polled: its CDR bytes and its
    writer's GID."""
    from types import SimpleNamespace

    from rclpy.serialization import serialize_message

    from camo_core.swarm.status_rows import StatusRows
    from camo_msgs.msg import StatusArray

    report = SimpleNamespace(**{"sensed": 100.0, "p": [1.0, 0.0, 0.0], **fields})
    msg = StatusArray(name="w", **StatusRows.from_reports([report]).message_fields())
    return serialize_message(msg), HOST_GID


def test_monitor_keeps_one_record_per_round_whatever_the_number_of_statuses(count_round_records):
    # A record allocated per status made a long run's monitor fall far behind its robots.
    from camo_core.algorithm.params import CamoParams
    from camo_nodes.monitor_node import MonitorNode
    from camo_nodes.topics.names import RunTopics

    made = count_round_records
    with ros_context() as context:
        monitor = MonitorNode(
            CamoParams(rows=2, cols=2), RunTopics("monitor_test"), context=context
        )
        hosting_all(monitor, 4)
        for round_index in (0, 1):
            for step in range(5):
                for robot in range(4):
                    monitor._on_status(
                        *status(sender_id=robot, phase=2, step=step, round=round_index)
                    )
        assert monitor.record(1).step.tolist() == [4, 4, 4, 4]
        assert len(made) == 2 and monitor.statuses_heard == 40
        monitor.destroy_node()


def notices(noticed: float, gid: bytes = HOST_GID, robot: int = 0, round_: int = 5):
    """A process's Notices message that `robot` started round `round_` at `noticed` (s), as
    polled."""
    from rclpy.serialization import serialize_message

    from camo_msgs.msg import Notices

    msg = Notices(name="w", robot=[robot], round=[round_], changed_at=[0.5], noticed_at=[noticed])
    return serialize_message(msg), gid


def test_statuses_that_came_before_their_host_are_taken_a_bounded_number_a_turn_in_order():
    from camo_core.algorithm.params import CamoParams
    from camo_nodes.monitor_node import REPLAY_PER_TURN, MonitorNode
    from camo_nodes.topics.names import RunTopics

    with ros_context() as context:
        params = CamoParams(rows=2, cols=2, consensus_steps=2000)
        monitor = MonitorNode(params, RunTopics("monitor_test"), context=context)
        for step in range(2 * REPLAY_PER_TURN + 5):
            monitor._on_status(*status(sender_id=0, phase=2, step=step, round=0))
        assert not monitor.heard  # nothing taken before its host's word
        hosting_all(monitor, 4)
        monitor._on_status(*status(sender_id=0, phase=2, step=1000, round=0))  # came after them
        steps = []
        while monitor._replay:
            monitor.turn()
            steps.append(int(monitor.record(0).step[0]))
        assert steps == [REPLAY_PER_TURN - 1, 2 * REPLAY_PER_TURN - 1, 1000]
        assert monitor.statuses_heard == 2 * REPLAY_PER_TURN + 6 and not monitor.rejected.counts
        monitor.destroy_node()


def test_notices_that_came_before_their_host_are_taken_over_turns_the_first_of_a_round_kept():
    from camo_core.algorithm.params import CamoParams
    from camo_nodes.monitor_node import REPLAY_PER_TURN, MonitorNode
    from camo_nodes.topics.names import RunTopics

    with ros_context() as context:
        monitor = MonitorNode(
            CamoParams(rows=2, cols=2), RunTopics("monitor_test"), context=context
        )
        waited = 2 * REPLAY_PER_TURN + 1
        for k in range(waited):  # each noticed earlier than the one before
            monitor._on_notices(*notices(100.0 - k, robot=k % 4))
        assert monitor.notices == {}
        hosting_all(monitor, 4)
        monitor._on_notices(*notices(1.0, gid=bytes(16)))  # not its robot's host: refused
        firsts = []
        while monitor._replay:
            monitor.turn()
            firsts.append(monitor.notices[5][2])
        latest = [REPLAY_PER_TURN - 1, 2 * REPLAY_PER_TURN - 1, waited - 1]  # taken by each turn
        assert firsts == [100.0 - k for k in latest]
        assert monitor.notices[5] == ((waited - 1) % 4, 0.5, 100.0 - (waited - 1))
        assert monitor.rejected.counts == {"not from the process hosting its sender": 1}
        monitor.destroy_node()


def test_monitor_counts_bridged_robots_whose_hardware_is_offline():
    from camo_core.algorithm.params import CamoParams
    from camo_nodes.monitor_node import MonitorNode
    from camo_nodes.topics.names import RunTopics

    with ros_context() as context:
        monitor = MonitorNode(
            CamoParams(rows=2, cols=2), RunTopics("monitor_test"), context=context
        )
        hosting_all(monitor, 4)
        monitor._on_status(*status(sender_id=3, phase=2, alive=False))
        assert "hardware offline 1" in monitor.progress_line()
        monitor._on_status(*status(sender_id=3, phase=2, alive=True))
        assert "offline" not in monitor.progress_line()
        monitor.destroy_node()


def test_a_noticed_round_superseded_before_any_robot_reported_lets_its_frame_go():
    # Its frame, pinned at the notice, was kept for as long as the run went.
    from camo_core.algorithm.params import CamoParams
    from camo_nodes.monitor_node import MonitorNode
    from camo_nodes.topics.names import RunTopics

    with ros_context() as context:
        monitor = MonitorNode(
            CamoParams(rows=2, cols=2), RunTopics("monitor_test"), context=context
        )
        hosting_all(monitor, 4)
        for frame in range(10):
            monitor.images.add((frame, 0), lambda: np.zeros((8, 8), np.uint8), frame)
        for robot, frame in ((1, 3), (2, 5), (3, 7)):  # notices: rounds of frames 3, 5 and 7
            columns = (np.array([robot]), np.array([frame]), np.array([1.0]), np.array([2.0]))
            monitor._notice_rows(columns, HOST_GID, next(monitor._arrivals))
        for robot in range(4):  # only round 7 is reported in, and done
            monitor._on_status(*status(sender_id=robot, phase=2, step=0, round=7))
        monitor.close(7)
        assert not monitor.notices and not monitor.images.pinned
        for frame in range(10, 10 + monitor.images.keep):
            monitor.images.add((frame, 0), lambda: np.zeros((8, 8), np.uint8), frame)
        assert not {3, 5, 7} & set(monitor.images)
        monitor.destroy_node()


# ---- every option with bad values (issue 27) -------------------------------------------------


def test_every_option_of_monitor_with_a_bad_value_is_one_line_and_exit_2(
    tmp_path, monkeypatch, capsys
):
    from support import bad_values_of_a_ros_tool

    import camo_nodes.monitor_node as command

    monkeypatch.chdir(tmp_path)
    options, problems = bad_values_of_a_ros_tool(command, [], monkeypatch, capsys)
    assert len(options) >= 4
    assert problems == []


def test_a_robot_past_discovery_is_one_that_reported_a_later_phase():
    from camo_core.algorithm.params import CamoParams
    from camo_core.swarm.robot_io import DISCOVERY, SENSING
    from camo_nodes.monitor_node import MonitorNode
    from camo_nodes.topics.names import RunTopics

    with ros_context() as context:
        params = CamoParams(rows=2, cols=2)
        monitor = MonitorNode(params, RunTopics("monitor_test"), context=context)
        hosting_all(monitor, 4)
        monitor._on_status(*status(sender_id=1, phase=DISCOVERY, step=0, round=0))
        assert not monitor.past_discovery(0)  # heard, but still searching
        monitor._on_status(*status(sender_id=2, phase=SENSING, step=0, round=0))
        assert monitor.past_discovery(0)
        monitor.destroy_node()
