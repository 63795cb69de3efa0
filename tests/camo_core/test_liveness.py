"""The failure detector behind "slow is not dead": a process is judged by the rhythm of its own
heartbeats, never by how late one robot message is."""

import math

from hypothesis import given
from hypothesis import strategies as st

from camo_core.swarm.liveness import HEARTBEAT_PERIOD, Liveness, PhiAccrual, phi


class Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def beating(period: float, beats: int, pause: float = 1.0) -> tuple[PhiAccrual, float]:
    detector, t = PhiAccrual(pause), 0.0
    for _ in range(beats):
        t += period
        detector.heard(t)
    return detector, t


def test_phi_grows_with_silence():
    values = [phi(s, 1.0, 0.2) for s in (0.5, 1.0, 1.5, 2.0, 3.0)]
    assert values == sorted(values) and values[0] < 0.5 and values[-1] > 8


def test_a_regular_process_is_suspected_soon_after_its_pause_allowance():
    detector, t = beating(HEARTBEAT_PERIOD, 40, pause=1.0)
    assert detector.phi(t + HEARTBEAT_PERIOD + 1.0) < 1  # within the allowed pause
    assert detector.phi(t + 2.0) > 8


def test_a_process_that_always_beats_slowly_is_not_suspected_for_it():
    slow, t = beating(3.0, 30, pause=1.0)
    assert slow.phi(t + 3.5) < 1
    fast, t = beating(HEARTBEAT_PERIOD, 30, pause=1.0)
    assert fast.phi(t + 3.5) > 8  # the same silence from a regular fast one is suspicious


def test_a_robot_is_alive_while_its_process_beats_and_dead_once_it_is_silent_a_timeout():
    clock = Clock()
    owner = {5: "A", 6: "B"}.get
    liveness = Liveness(step_timeout=3.0, owner=owner, clock=clock)
    assert not liveness.robot_alive(5)  # never heard: not known to be alive
    for _ in range(20):
        clock.now += HEARTBEAT_PERIOD
        liveness.heard("A")
    assert liveness.robot_alive(5) and not liveness.robot_alive(6) and not liveness.robot_alive(7)
    clock.now += 1.0  # a pause within a third of the timeout
    assert liveness.robot_alive(5)
    clock.now += 2.0  # killed: silent for the whole timeout
    assert not liveness.robot_alive(5)


def test_robots_whose_hardware_is_offline_are_not_alive_in_a_live_process():
    clock = Clock()
    liveness = Liveness(3.0, {1: "A", 2: "A"}.get, clock)
    liveness.heard("A", frozenset({2}))
    assert liveness.robot_alive(1) and not liveness.robot_alive(2)


def test_processes_beyond_the_limit_are_not_remembered():
    liveness = Liveness(3.0, lambda r: None, Clock(), limit=2)
    assert liveness.heard("A") and liveness.heard("B") and not liveness.heard("C")
    assert liveness.heard("A")  # one already known still counts


@given(
    st.lists(st.floats(0.01, 5.0), min_size=1, max_size=50),
    st.floats(0.0, 100.0),
    st.floats(0.1, 60.0),
)
def test_any_silence_as_long_as_the_timeout_is_suspected(intervals, extra, timeout):
    clock = Clock()
    liveness = Liveness(timeout, {0: "A"}.get, clock)
    for interval in intervals:
        clock.now += interval
        liveness.heard("A")
    clock.now += timeout + extra + 1e-9  # (past float rounding of the sum)
    assert not liveness.robot_alive(0)
    assert not math.isnan(liveness.processes["A"].phi(clock.now))
