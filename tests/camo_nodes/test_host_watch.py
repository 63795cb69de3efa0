"""A host's robots driven without ROS: its watch (continuous camouflage), where robots whose
round's frame has not come keep waiting for it, whatever else happens meanwhile; and its loop's
work, a bounded batch of robots a turn."""

from types import SimpleNamespace

import numpy as np
from rclpy.clock import Clock

from camo_core.algorithm.change import Watch
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.sensing import Projection
from camo_nodes.host import BATCH, Host


def host_of(rounds: list[int]) -> Host:
    """A Host with only what its watch uses: robots in these rounds, frames 0 and 1 held."""
    host = object.__new__(Host)
    params = CamoParams(rows=1, cols=len(rounds))
    host.watch = Watch(np.arange(len(rounds)), params, 8, 24.0)
    host.robots = [SimpleNamespace(protocol=SimpleNamespace(round=r)) for r in rounds]
    host.projection = Projection(1, len(rounds), "paper")
    for _ in range(2):
        host.projection.add(np.full((4, 4 * len(rounds)), 90, np.uint8))
    host._joins = []
    return host


def test_a_robot_waiting_for_its_rounds_frame_keeps_waiting_when_another_notices():
    host = host_of([1, 1, 1, 5])  # robot 3 joined round 5: its process has frames 0 and 1
    host._reset([3])
    assert host._joins == [3]  # its reference is to be read off frame 5, once it comes
    host._reset([0])  # robot 0 noticed something in the same reading
    assert host._joins == [3] and np.isfinite(host.watch.reference[0])
    host.projection.add(np.full((4, 16), 200, np.uint8), 5)
    host._reset(host._joins)
    assert host._joins == [] and host.watch.reference[3] == 200.0


class Robot:
    """What a host's loop asks of a robot, counted: started, shown a background, told it noticed
    (it joins the frame's round, unless in that round or a later one)."""

    def __init__(self, robot_id: int, round_: int = -1) -> None:
        self.protocol = SimpleNamespace(id=robot_id, round=round_)
        self.started = self.shown = 0

    def start(self) -> None:
        self.started += 1

    def background(self, now: float, frame: int) -> None:
        self.shown += 1

    def notice(self, frame: int, now: float) -> None:
        self.protocol.round = max(self.protocol.round, frame)


def loop_host(count: int, rounds: int = -1) -> Host:
    """A Host with what its loop's work uses, `count` robots in round `rounds` (-1: none yet,
    all watching), frame 0 (grey 90) projected; its Notices messages in `host.published`."""
    from camo_msgs.msg import Notices

    host = host_of([rounds] * count)
    host.robots = [Robot(k, rounds) for k in range(count)]
    host.node = SimpleNamespace(get_clock=Clock, get_name=lambda: "worker")
    host.published = []
    host.notices = SimpleNamespace(publish=host.published.append)
    host.idle = np.array([rounds < 0] * count)
    host._noticing, host._notice = {}, Notices(name="worker")
    host._to_start = host._to_show = None
    host.shown = 0
    return host


def per_turn(host: Host, count) -> list[int]:
    """How many robots each turn of the host's loop worked on (by `count()`, in total so far),
    until it says nothing is left."""
    done = []
    while host._work():
        done.append(count() - sum(done))
    return done


def test_robots_are_started_and_shown_a_background_a_bounded_batch_a_turn():
    host = loop_host(2 * BATCH + 10)
    host.watch = None
    host._to_start = 0
    assert per_turn(host, lambda: sum(r.started for r in host.robots)) == [BATCH, BATCH, 10]
    assert all(r.started == 1 for r in host.robots)
    host._to_show = 0
    assert per_turn(host, lambda: sum(r.shown for r in host.robots)) == [BATCH, BATCH, 10]


def test_robots_that_noticed_are_told_a_batch_a_turn_each_of_the_frame_it_noticed_in():
    host = loop_host(2 * BATCH + 10)
    for _ in range(2 * host.watch.window):  # readings enough to know the scene: all notice it
        host._read()
    assert len(host._noticing) == len(host.robots) and host.published == []
    # A later frame of the same scene comes before they are all told: they noticed frame 1.
    host.projection.add(np.full((4, 4 * len(host.robots)), 90, np.uint8))
    host._read()
    told = lambda: sum(r.protocol.round >= 0 for r in host.robots)  # noqa: E731
    assert per_turn(host, told) == [BATCH, BATCH, 10]
    assert {r.protocol.round for r in host.robots} == {1}
    (notice,) = host.published  # once every robot was told
    assert sorted(notice.robot) == list(range(len(host.robots))) and set(notice.round) == {1}


def test_a_robot_not_told_yet_that_it_noticed_keeps_the_frame_it_noticed_in():
    host = loop_host(BATCH + 1, rounds=1)
    host._reset(list(range(len(host.robots))))  # their reference: frame 1's grey, 90
    darker = np.full((4, 4 * len(host.robots)), 200, np.uint8)
    changed = host.projection.add(darker)
    while not host._noticing:
        host._read()
    noticed = dict(host._noticing)
    # Frames of the new scene keep coming: robots told at once would see no change in them.
    host.projection.add(darker)
    host._read()
    assert {k: v[0] for k, v in host._noticing.items()} == {k: changed for k in noticed}
    while host._work():
        pass
    assert {host.robots[k].protocol.round for k in noticed} == {changed}
