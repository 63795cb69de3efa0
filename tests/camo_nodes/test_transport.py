"""A process's transport: its statuses go out as a few arrays, not a message per robot, and its
pump hands messages over for a bounded time per turn, in order, the rest on later turns."""

import time
from types import SimpleNamespace

import pytest
import rclpy
from rclpy.serialization import serialize_message
from support import ros_context

from camo_core.algorithm.params import CamoParams
from camo_core.swarm.robot_io import CONSENSUS, DONE, NOTHING, Message, Output
from camo_msgs.msg import Host
from camo_nodes.topics.names import RunTopics
from camo_nodes.transport import (
    MAX_STATUS_BYTES,
    STATUS_PERIOD,
    Statuses,
    Transport,
    row_bytes,
)
from camo_nodes.trust import OWN_TILES_CLAIMED


class Writer:
    def __init__(self) -> None:
        self.sent: list = []

    def publish(self, msg) -> None:
        self.sent.append(msg)


def report(robot: int, phase: int = CONSENSUS, step: int = 1, steps: int = 0) -> SimpleNamespace:
    """A status report; `steps`: how many steps' p and states it carries."""
    return SimpleNamespace(
        sender_id=robot, phase=phase, step=step, sensed=9.0, p=(1.0, 0.0, 0.0),
        p_from=step, p_trace=(1.0, 0.0, 0.0) * steps, state_trace=(), silent=(), palette=(),
        sensed_rgb=(9.0, 9.0, 9.0), palette_rgb=(), shades=(),
    )  # fmt: skip


def test_thousands_of_reports_go_out_as_a_few_arrays_and_no_more_often_than_the_period():
    writer = Writer()
    statuses = Statuses(writer, "w")
    now = time.monotonic()
    rows = MAX_STATUS_BYTES // row_bytes(report(0))
    for robot in range(2 * rows + 5):
        statuses.add(report(robot))
    assert [len(m.sender_id) for m in writer.sent] == [rows, rows]
    statuses.flush(now)  # within the period since the last array: not yet
    assert len(writer.sent) == 2
    statuses.flush(now + STATUS_PERIOD + 1.0)
    assert len(writer.sent[-1].sender_id) == 5 and writer.sent[-1].sender_id[-1] == 2 * rows + 4
    statuses.flush()  # nothing left: nothing written
    assert len(writer.sent) == 3


def test_reports_with_long_traces_go_out_in_arrays_within_the_shared_memory_segment():
    """A stopping process sends every robot's report at once; an array past Fast DDS's
    shared-memory segment would go out slowly, in UDP fragments."""
    writer = Writer()
    statuses = Statuses(writer, "w")
    for robot in range(2000):
        statuses.add(report(robot, steps=40))  # 40 steps of p since its last report
    statuses.flush()
    assert [r for m in writer.sent for r in m.sender_id] == list(range(2000))  # all, in order
    assert len(writer.sent) > 1
    assert all(len(serialize_message(m)) <= 512 * 1024 for m in writer.sent)
    assert all(len(serialize_message(m)) <= MAX_STATUS_BYTES * 1.25 for m in writer.sent)


@pytest.mark.parametrize(("phase", "step"), [(CONSENSUS, 0), (DONE, 10)])
def test_a_report_of_voting_or_finishing_goes_out_at_the_turns_end_not_the_period(phase, step):
    """Those reports time a run (timing.json): held for the period, a run shorter than it
    measured no time at all."""
    writer = Writer()
    statuses = Statuses(writer, "w")
    now = time.monotonic()
    statuses.add(report(1))
    statuses.flush(now)  # a step's report: it waits for the period
    assert writer.sent == []
    statuses.add(report(2, phase, step))
    statuses.flush(now)
    assert [list(m.sender_id) for m in writer.sent] == [[1, 2]]
    statuses.add(report(3))  # and the period holds again after it
    statuses.flush(now)
    assert len(writer.sent) == 1


def test_a_pump_stops_at_its_budget_and_the_next_ones_wake_every_robot_once():
    with ros_context() as context:
        node = rclpy.create_node("pump_test", context=context)
        params = CamoParams(rows=20, cols=20)
        transport = Transport(node, params, RunTopics("pump_test"), [(0, 399)])
        woken: list[int] = []

        def slow_robot(robot: int):
            def wake(now: float) -> Output:
                time.sleep(0.0005)
                woken.append(robot)
                return NOTHING

            return wake

        for robot in range(1, 400):  # every robot hears robot 0: 0.2 s of waking
            transport.add(robot, [(0, "vote")], slow_robot(robot), emit=None)
        transport.send(Message("vote", 0, 0, 0, ((1.0, 0.0, 0.0), 1)))
        assert transport.mailbox.box((0, "vote", 0)) == {0: ((1.0, 0.0, 0.0), 1)}
        started = time.monotonic()
        transport.pump(budget=0.02)
        assert time.monotonic() - started < 0.1 and 0 < len(woken) < 399
        assert transport.busy  # it says that work is left for the next turn
        while transport.busy:
            transport.pump(budget=0.02)
        assert sorted(woken) == list(range(1, 400))  # each once, however many turns it took
        transport.close()
        node.destroy_node()


def test_a_robot_the_process_does_not_host_or_one_left_out_is_refused():
    with ros_context() as context:
        node = rclpy.create_node("hosted_test", context=context)
        transport = Transport(node, CamoParams(rows=2, cols=2), RunTopics("hosted_test"), [(0, 2)])
        with pytest.raises(ValueError, match="robot 3 is not hosted"):
            transport.add(3, [], lambda now: NOTHING, emit=None)
        for robot in (0, 1):
            transport.add(robot, [], lambda now: NOTHING, emit=None)
        # Robot 2 never added: the shared mailbox would keep every step it never takes.
        with pytest.raises(ValueError, match="1 hosted robots were not added"):
            transport.check_hosted()
        transport.add(2, [], lambda now: NOTHING, emit=None)
        transport.check_hosted()
        transport.close()
        node.destroy_node()


def test_a_message_taken_twice_counts_once_until_its_round_is_forgotten():
    from camo_msgs.msg import Host

    with ros_context() as context:
        node = rclpy.create_node("seen_test", context=context)
        transport = Transport(node, CamoParams(rows=2, cols=2), RunTopics("seen_test"), [(0, 1)])
        other = bytes(range(16))  # the process hosting robots 2 and 3
        transport.trusted.learn(Host(name="other", first=[2], last=[3]), other)
        vote = lambda round_, p: Message("vote", 2, round_, 0, (p, 3))  # noqa: E731
        for round_ in (1, 2):
            transport._robot_message(vote(round_, (1.0, 0.0, 0.0)), other)
            transport._robot_message(vote(round_, (1.0, 0.0, 0.0)), other)  # again: nothing said
        assert transport.rejected.counts == {}
        transport.forget_before(2)
        transport._robot_message(vote(1, (0.0, 1.0, 0.0)), other)  # round 1 is let go
        transport._robot_message(vote(2, (0.0, 1.0, 0.0)), other)  # round 2 is not
        assert transport.rejected.counts == {"a second, different message for the same step": 1}
        transport.close()
        node.destroy_node()


def test_a_step_every_hosted_robot_took_is_let_go_and_a_late_message_for_it_is_not_kept():
    """A long round keeps only the steps under way: once both hosted robots took step 0, what
    was taken for it is let go at the next flush, and a late, different vote for it is read by
    no one: neither kept nor refused. Step 1, still under way, still refuses one."""
    from camo_msgs.msg import Host

    with ros_context() as context:
        node = rclpy.create_node("late_test", context=context)
        transport = Transport(node, CamoParams(rows=2, cols=2), RunTopics("late_test"), [(0, 1)])
        other = bytes(range(16))  # the process hosting robots 2 and 3
        transport.trusted.learn(Host(name="other", first=[2], last=[3]), other)
        for robot in (0, 1):
            transport.add(robot, [(2, "vote")], lambda now: NOTHING, emit=None)
        vote = lambda step, p: Message("vote", 2, 0, step, (p, 3))  # noqa: E731
        for step in (0, 1):
            transport._robot_message(vote(step, (1.0, 0.0, 0.0)), other)
        for _ in (0, 1):  # each hosted robot takes step 0
            assert transport.mailbox.take((0, "vote", 0)) == {2: ((1.0, 0.0, 0.0), 3)}
        transport.flush()
        assert list(transport._seen) == [(0, "vote", 1)]
        transport._robot_message(vote(0, (0.0, 1.0, 0.0)), other)  # late: step 0 is over
        assert transport.rejected.counts == {}
        assert transport.mailbox.box((0, "vote", 0)) == {}
        assert list(transport._seen) == [(0, "vote", 1)]
        transport._robot_message(vote(1, (0.0, 1.0, 0.0)), other)
        assert transport.rejected.counts == {"a second, different message for the same step": 1}
        transport.close()
        node.destroy_node()


def test_another_process_announcing_its_tiles_is_said_at_once_in_its_own_announcement():
    """The launcher may hear that process later than this one does (or not before a small run
    ends): the claim is reported by reason in this process's next announcement, sent at once."""
    with ros_context() as context:
        node = rclpy.create_node("claimed_test", context=context)
        transport = Transport(
            node, CamoParams(rows=2, cols=2), RunTopics("claimed_test"), [(0, 3)]
        )
        sent = Writer()
        transport.host_pub = sent
        other = bytes(range(1, 13)) + bytes(4)  # another process's writer GID
        elsewhere = Host(name="stranger", first=[0], last=[1])
        transport._on_host(serialize_message(Host(name="stranger", first=[9], last=[9])), other)
        assert transport.conflict is None and not sent.sent  # out of range: only refused
        transport._on_host(serialize_message(elsewhere), other)
        assert transport.conflict.name == "stranger" and transport.conflict.tiles == [(0, 3)]
        (announced,) = sent.sent
        reasons = dict(zip(announced.rejected_reasons, announced.rejected_counts, strict=True))
        assert reasons[OWN_TILES_CLAIMED] == 1, reasons
        transport.close()
        node.destroy_node()
