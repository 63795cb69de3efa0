"""The link's draws for many robots at once are the simulator's and each robot's own."""

import numpy as np
import pytest

from camo_core.algorithm import rng
from camo_core.algorithm.link import LinkBook, LinkDraws
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.robot import RobotCore
from camo_core.algorithm.simulator import Grid

STREAMS = (
    rng.STREAM_HELLO,
    rng.STREAM_COLOR,
    rng.STREAM_ENERGY,
    rng.STREAM_CONSENSUS,
    rng.STREAM_STATE,
    rng.STREAM_RELAY,
)


@pytest.mark.parametrize("rho", [0.1, 0.5])
def test_a_process_draws_for_every_stream_what_the_simulator_draws(rho):
    params = CamoParams(rows=7, cols=6, rho_comm=rho, seed=11)
    robots = list(range(params.count))
    draws = LinkDraws(params, robots)
    grid = Grid(params.rows, params.cols)
    for stream in STREAMS:
        for step in (0, 1, 17):
            simulated = grid.arrivals(params, stream, step, range(12))
            assert simulated is not None
            expected = np.stack(
                [simulated[s] & grid.exists[s] for s in range(12)], axis=-1
            ).reshape(params.count, 12)
            assert np.array_equal(draws.table(stream, step), expected), (stream, step)


@pytest.mark.parametrize("rho", [0.1, 0.5])
def test_a_robot_with_its_process_draws_hears_what_it_would_draw_alone(rho):
    # Some of the robots only (a process hosts a tile), on the grid and on a layout.
    for params in (
        CamoParams(rows=9, cols=8, rho_comm=rho, seed=5),
        CamoParams(rows=6, cols=6, rho_comm=rho, seed=2, orientation="any", layout="hex"),
    ):
        hosted = list(range(10, params.count, 3))
        draws = LinkBook(hosted).draws(params)
        for robot in hosted:
            row, col = divmod(robot, params.cols)
            alone = RobotCore(params, row, col)
            shared = RobotCore(params, row, col, link=draws)
            for stream in STREAMS:
                for step in (0, 3):
                    assert shared.arrivals(stream, step) == alone.arrivals(stream, step)


def test_without_loss_a_process_has_no_draws_to_make():
    assert LinkBook([0, 1]).draws(CamoParams(rows=2, cols=2)) is None
