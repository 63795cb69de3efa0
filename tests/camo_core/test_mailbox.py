"""A process's robots share one mailbox: each message kept once, forgotten once every robot took
its step, and robots woken (not handed each message) step exactly as the simulator does."""

import random

import numpy as np
import pytest
from support import FixedSensor

from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.simulator import simulate
from camo_core.swarm.mailbox import Mailbox
from camo_core.swarm.protocol import StepProtocol
from camo_core.swarm.robot_io import DONE, NOTHING


def test_a_step_is_forgotten_once_every_reader_took_it_and_a_late_message_is_not_kept():
    mailbox = Mailbox(readers=2)
    mailbox.put((0, "vote", 3), 7, "v7")
    mailbox.put((0, "vote", 3), 8, "v8")
    assert mailbox.take((0, "vote", 3)) == {7: "v7", 8: "v8"}  # the first reader
    assert mailbox.box((0, "vote", 3)) == {7: "v7", 8: "v8"}  # still there for the second
    assert mailbox.take((0, "vote", 3)) == {7: "v7", 8: "v8"}
    assert not mailbox.boxes
    mailbox.put((0, "vote", 3), 9, "late")  # nobody waits for step 3 any more
    assert not mailbox.boxes and mailbox.spoke == {7: 1, 8: 1, 9: 1}


def test_a_step_taken_before_any_message_came_still_counts_its_reader():
    mailbox = Mailbox(readers=2)
    assert mailbox.take((0, "hello", 0)) == {}  # a robot that expected nobody moved on
    mailbox.put((0, "hello", 0), 1, (0, 1))
    assert mailbox.take((0, "hello", 0)) == {1: (0, 1)}
    assert not mailbox.boxes


class SharedBus:
    """Robots of one process as the transport drives them: every message put once into their
    shared mailbox (in a random order), the robots that hear its sender woken in a random
    order, generation after generation."""

    def __init__(self, params: CamoParams, grid: np.ndarray, seed: int) -> None:
        self.random = random.Random(seed)
        self.mailbox = Mailbox(readers=params.count)
        self.robots = [
            StepProtocol(params, i, j, FixedSensor(float(grid[i, j])), mailbox=self.mailbox)
            for i in range(params.rows)
            for j in range(params.cols)
        ]
        self.hearers: dict[tuple[int, str], list[int]] = {}
        for p in self.robots:
            for sender, kind in p.listens_to():
                self.hearers.setdefault((sender, kind), []).append(p.id)
        self.sent: list = []
        self.woken: set[int] = set()

    def post(self, out) -> None:
        if out is not NOTHING:
            self.sent.extend(out.send)

    def run(self) -> None:
        for p in self.robots:
            self.post(p.background(0.0))
            self.post(p.start(0.0))
        while self.sent or self.woken:
            self.random.shuffle(self.sent)
            for m in self.sent:
                self.mailbox.put((m.round, m.kind, m.step), m.sender, m.value)
                self.woken.update(self.hearers.get((m.sender, m.kind), ()))
            self.sent = []
            generation = sorted(self.woken)
            self.random.shuffle(generation)
            self.woken.clear()
            for robot in generation:
                self.post(self.robots[robot].wake(0.0))


@pytest.mark.parametrize(
    "params",
    [
        CamoParams(rows=5, cols=4),
        CamoParams(rows=4, cols=6, rho_comm=0.3, rho_meas=0.2, seed=5, threshold_auto=True),
        CamoParams(rows=6, cols=5, levels=4, orientation="any", rho_comm=0.2, seed=2),
    ],
)
def test_robots_woken_from_a_shared_mailbox_equal_the_simulator_and_leave_it_empty(params):
    grid = np.random.default_rng(params.seed).uniform(0, 255, (params.rows, params.cols))
    bus = SharedBus(params, grid, seed=params.seed)
    bus.run()
    assert all(p.phase == DONE and p.deadlines == 0 for p in bus.robots)
    reference = simulate(params, grid)
    final = np.array([p.core.state for p in bus.robots]).reshape(params.rows, params.cols)
    assert np.array_equal(final, reference.final)
    assert not bus.mailbox.boxes  # every step's messages dropped once all had taken them
