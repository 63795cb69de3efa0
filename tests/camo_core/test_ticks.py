"""A host ticks only its robots whose deadline is due, a bounded number at a time, and takes a
stall of its own process off every robot's deadline."""

import math

from camo_core.swarm.protocol import RECHECK, TICK
from camo_core.swarm.ticks import Ticks


class Robot:
    def __init__(self, due: float) -> None:
        self.at = due
        self.stalls = 0.0

    def due(self) -> float:
        return self.at

    def stalled(self, seconds: float) -> None:
        self.stalls += seconds
        self.at += seconds


def test_only_robots_whose_due_has_come_are_ticked_and_at_most_the_limit():
    robots = [Robot(5.0), Robot(1.0), Robot(math.inf), Robot(2.0), Robot(0.5)]
    ticks = Ticks(robots)
    ticks.add_all(0.0)
    assert ticks.due(0.4, 10) == []
    assert ticks.due(2.0, 2) == [4, 1]  # earliest first, two at most
    assert ticks.due(2.0, 10) == [3]
    assert ticks.due(100.0, 10) == [0]  # the one with no due is never ticked


def test_a_robot_queued_again_sooner_is_ticked_once_at_its_new_due():
    robot = Robot(10.0)
    ticks = Ticks([robot])
    ticks.add(0, 0.0)
    robot.at = 3.0
    ticks.add(0, 0.0)
    assert ticks.due(3.0, 10) == [0] and ticks.due(10.0, 10) == []


def test_past_a_deadline_a_robot_asks_again_after_a_while_not_every_tick():
    robot = Robot(1.0)  # its deadline passed; it still waits for a live neighbour
    ticks = Ticks([robot])
    ticks.add(0, 2.0)
    assert ticks.due(2.0 + RECHECK / 2, 10) == []
    assert ticks.due(2.0 + RECHECK, 10) == [0]
    robot.at = -math.inf  # waiting for its hardware: every tick
    ticks.add(0, 3.0)
    assert ticks.due(3.0 + TICK, 10) == [0]


def test_a_stall_of_the_process_moves_every_deadline_by_its_length():
    robots = [Robot(1.0), Robot(2.0)]
    ticks = Ticks(robots)
    ticks.add_all(0.0)
    assert ticks.stall(0.0) == 0.0
    assert ticks.stall(0.05 + TICK) == 0.0  # on time
    stalled = ticks.stall(10.0)
    assert math.isclose(stalled, 10.0 - 0.1 - TICK)
    assert all(math.isclose(r.stalls, stalled) for r in robots)
    assert ticks.due(2.0, 10) == []  # their deadlines moved with the stall
    assert ticks.due(1.0 + stalled, 10) == [0]
