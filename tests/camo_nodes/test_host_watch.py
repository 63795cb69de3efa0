"""A host's watch over its robots (continuous camouflage), driven without ROS: robots whose
round's frame has not come keep waiting for it, whatever else happens meanwhile."""

from types import SimpleNamespace

import numpy as np

from camo_core.algorithm.change import Watch
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.sensing import Projection
from camo_nodes.host import Host


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
