"""The robot's step protocol, driven with a fake clock and no ROS: when a robot steps, waits
and gives up waiting."""

import numpy as np
import pytest
from support import Bus, FixedSensor

from camo_core.algorithm import rng
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.sensing import Reading
from camo_core.algorithm.simulator import simulate
from camo_core.swarm.protocol import (
    CONSENSUS,
    DISCOVERY,
    DONE,
    SENSING,
    TICK,
    StepProtocol,
)
from camo_core.swarm.robot_io import Message


def robot(params: CamoParams, row: int, col: int, value: float = 100.0, **kwargs) -> StepProtocol:
    kwargs.setdefault("step_timeout", 2.0)
    kwargs.setdefault("discovery_timeout", 2.0)
    protocol = StepProtocol(params, row, col, FixedSensor(value), **kwargs)
    protocol.background(0.0)
    return protocol


def hello(sender: int) -> Message:
    return Message("hello", sender, 0, 0, (0, sender))


def color(sender: int, value: float = 50.0) -> Message:
    return Message("color", sender, 0, 0, value)


def vote(sender: int, step: int, degree: int = 1) -> Message:
    return Message("vote", sender, 0, step, ((0.0, 1.0, 0.0), degree))


def state(sender: int, step: int, value: int = 1) -> Message:
    return Message("state", sender, 0, step, value)


def tick_until(protocol: StepProtocol, start: float, end: float):
    """Tick every TICK seconds, as a process that is not stalled does; the last tick's output."""
    out = None
    for k in range(round((end - start) / TICK) + 1):
        out = protocol.tick(start + k * TICK)
    return out


def into_consensus(protocol: StepProtocol, neighbours: list[int], now: float = 0.0) -> None:
    protocol.start(now)
    for n in neighbours:
        protocol.deliver(hello(n), now)
    for n in neighbours:
        protocol.deliver(color(n), now)
    assert (protocol.phase, protocol.step) == (CONSENSUS, 0)


def test_a_robot_says_hello_on_start_and_votes_once_it_has_its_neighbours_colours():
    protocol = robot(CamoParams(rows=1, cols=2), 0, 0)
    out = protocol.start(0.0)
    assert [m.kind for m in out.send] == ["hello"] and protocol.phase == DISCOVERY
    out = protocol.deliver(hello(1), 0.0)
    assert [m.kind for m in out.send] == ["color"] and protocol.phase == SENSING
    out = protocol.deliver(color(1), 0.0)
    assert [(m.kind, m.step) for m in out.send] == [("vote", 0)]
    assert [r.phase for r in out.reports] == [CONSENSUS]


def test_a_message_for_a_later_step_is_kept_until_its_step():
    protocol = robot(CamoParams(rows=1, cols=2), 0, 0)
    into_consensus(protocol, [1])
    protocol.deliver(vote(1, 1), 0.1)  # early: step 1's vote before step 0's
    assert protocol.step == 0 and protocol.holds(0, "vote", 1, 1)
    out = protocol.deliver(vote(1, 0), 0.2)
    # Step 0 is taken, then step 1 at once with the vote that waited for it.
    assert protocol.step == 2 and [m.step for m in out.send] == [1, 2]
    assert not protocol.mailbox.boxes  # both steps taken: nothing kept


def test_a_message_the_link_will_drop_is_not_waited_for():
    # A seed whose link delivers 1's hello and colour to 0 but drops its step-0 vote.
    def lost(seed, stream, step):
        return rng.lost(seed, stream, step, 1, 0, 0.5)

    seed = next(
        s
        for s in range(1000)
        if not lost(s, rng.STREAM_HELLO, 0)
        and not lost(s, rng.STREAM_COLOR, 0)
        and lost(s, rng.STREAM_CONSENSUS, 0)
        and not lost(s, rng.STREAM_CONSENSUS, 1)
    )
    protocol = robot(CamoParams(rows=1, cols=2, seed=seed, rho_comm=0.5), 0, 0)
    protocol.start(0.0)
    protocol.deliver(hello(1), 0.0)
    out = protocol.deliver(color(1), 0.0)
    # Step 0 did not wait for the dropped vote; step 1 waits for the one that will arrive.
    assert (protocol.phase, protocol.step, protocol.deadlines) == (CONSENSUS, 1, 0)
    assert [m.step for m in out.send if m.kind == "vote"] == [0, 1]


def test_a_dead_neighbour_costs_one_deadline_and_is_then_silent():
    params = CamoParams(rows=1, cols=2)
    protocol = robot(params, 0, 0)
    into_consensus(protocol, [1])  # then robot 1 dies: no vote ever comes
    tick_until(protocol, 0.0, 1.9)
    assert protocol.step == 0
    out = tick_until(protocol, 1.95, 2.0)
    assert protocol.silent == {protocol.slot_of[1]} and protocol.deadlines == 1
    assert out.warnings and "slots [1]" in out.warnings[0]
    # No further step waits for it: the robot runs through consensus and formation at once.
    assert protocol.phase == DONE and protocol.deadlines == 1


def test_a_silent_neighbour_that_speaks_again_is_waited_for_again():
    params = CamoParams(rows=1, cols=3)
    protocol = robot(params, 0, 1)  # neighbours: 0 (left) and 2 (right)
    into_consensus(protocol, [0, 2])
    protocol.deliver(vote(0, 0, 2), 0.5)  # robot 2 stays quiet
    tick_until(protocol, 0.0, 2.1)
    right = protocol.slot_of[2]
    assert protocol.silent == {right} and protocol.step == 1
    protocol.deliver(vote(0, 1, 2), 2.2)
    assert protocol.step == 2  # 2 is silent: only 0's vote is needed
    protocol.deliver(vote(2, 1, 2), 2.3)  # 2 speaks again (a late message)
    assert right not in protocol.silent
    protocol.deliver(vote(0, 2, 2), 2.4)
    assert protocol.step == 2  # waits for 2 again
    protocol.deliver(vote(2, 2, 2), 2.5)
    assert protocol.step == 3 and protocol.deadlines == 1


def test_a_stall_of_the_robots_own_process_does_not_count_towards_a_deadline():
    protocol = robot(CamoParams(rows=1, cols=3), 0, 0)  # neighbours 1 and 2 (two cells away)
    protocol.start(0.0)
    protocol.tick(0.05)
    # The process stalled for 10 s; a message is handled before the tick that follows.
    protocol.deliver(hello(2), 10.0)
    assert (protocol.phase, protocol.deadlines) == (DISCOVERY, 0)
    protocol.stalled(9.95)  # the host saw its tick come late
    protocol.tick(10.05)
    assert (protocol.phase, protocol.deadlines) == (DISCOVERY, 0)
    tick_until(protocol, 10.1, 12.2)  # now robot 1 really is late
    assert protocol.phase != DISCOVERY and protocol.deadlines == 1
    assert protocol.silent == {protocol.slot_of[1]}


def test_a_robot_is_due_at_its_deadline_and_not_while_it_waits_for_a_background():
    protocol = StepProtocol(CamoParams(rows=1, cols=2), 0, 0, FixedSensor(10.0), step_timeout=2.0)
    assert protocol.due() == float("inf")  # not started
    protocol.start(1.0)
    assert protocol.due() == 1.0 + protocol.discovery_timeout
    protocol.deliver(hello(1), 1.5)
    assert protocol.due() == float("inf")  # sensing, with no background yet
    protocol.background(2.0)
    assert protocol.phase == SENSING and protocol.due() == 2.0 + 2.0  # its colour step


def test_only_a_tick_lets_a_deadline_pass():
    protocol = robot(CamoParams(rows=1, cols=3), 0, 1)
    into_consensus(protocol, [0, 2])
    protocol.deliver(vote(0, 0, 2), 5.0)  # long past the deadline, but not a tick
    assert protocol.step == 0 and protocol.deadlines == 0


def test_a_robot_that_starts_late_still_gets_every_message_it_needs():
    params = CamoParams(rows=1, cols=2, consensus_steps=3, formation_steps=2)
    protocol = robot(params, 0, 0, value=40.0)
    # Everything its neighbour sent arrives before it starts (as a transient-local history).
    messages = [hello(1), color(1, 200.0)]
    messages += [vote(1, s) for s in range(3)] + [state(1, s) for s in range(2)]
    for message in messages:
        protocol.deliver(message, 0.0)
    assert protocol.phase == DISCOVERY and not protocol.started
    out = protocol.start(1.0)
    assert protocol.phase == DONE and protocol.deadlines == 0
    assert [m.kind for m in out.send] == ["hello", "color", *["vote"] * 3, *["state"] * 2]


def test_a_robot_waits_for_the_background_before_it_senses():
    protocol = StepProtocol(CamoParams(rows=1, cols=1), 0, 0, FixedSensor(10.0))
    protocol.start(0.0)
    assert protocol.phase == SENSING
    tick_until(protocol, 0.0, 100.0)
    assert protocol.phase == SENSING  # no background, no deadline
    protocol.background(100.1)
    assert protocol.phase == DONE


def test_a_sensor_that_cannot_read_yet_is_asked_again_on_the_next_tick():
    class Flaky(FixedSensor):
        tries = 0

        def read(self):
            self.tries += 1
            return None if self.tries < 3 else Reading(self.value, real=True)

    sensor = Flaky(30.0)
    protocol = StepProtocol(CamoParams(rows=1, cols=1, rho_meas=1.0), 0, 0, sensor)
    protocol.background(0.0)
    protocol.start(0.0)
    protocol.tick(0.05)
    assert protocol.phase == SENSING and sensor.tries == 2
    protocol.tick(0.1)
    # A real reading gets no simulated measurement noise, even at rho_meas 1.
    assert protocol.phase == DONE and protocol.core.sensed == 30.0


def test_a_new_background_makes_a_finished_robot_camouflage_again():
    protocol = robot(CamoParams(rows=1, cols=1), 0, 0)
    protocol.start(0.0)
    assert protocol.phase == DONE and protocol.round == 0
    out = protocol.background(1.0, 1)  # frame 1
    assert protocol.round == 1 and protocol.phase == DONE
    assert {m.round for m in out.send} == {1} and out.send[0].kind == "hello"
    assert out.reports[-1].round == 1


def test_messages_from_strangers_and_other_kinds_slots_are_ignored():
    protocol = robot(CamoParams(rows=3, cols=3), 1, 1)
    protocol.start(0.0)
    protocol.deliver(Message("vote", 8, 0, 0, ((1.0, 0.0, 0.0), 3)), 0.0)  # a diagonal: slot 5
    protocol.deliver(Message("color", 8, 0, 0, 3.0), 0.0)  # colours come from slots 0-3 only
    assert not protocol.holds(0, "color", 0, 5) and protocol.holds(0, "vote", 0, 5)


@pytest.mark.parametrize(
    "params, order, shared_link",
    [
        (CamoParams(rows=4, cols=5), 0, False),
        (
            CamoParams(rows=5, cols=3, profile="droplet", rho_comm=0.3, rho_meas=0.2, seed=7),
            1,
            False,
        ),
        (CamoParams(rows=6, cols=6, rho_comm=0.5, seed=3, consensus_steps=12), 2, False),
        # The link's draws made for all robots at once, as a process hosting them makes them.
        (
            CamoParams(rows=5, cols=3, profile="droplet", rho_comm=0.3, rho_meas=0.2, seed=7),
            1,
            True,
        ),
        (CamoParams(rows=6, cols=6, rho_comm=0.5, seed=3, consensus_steps=12), 2, True),
        # Relays, energies and histograms too, each robot's unknown neighbours out of its takes.
        (
            CamoParams(
                rows=6,
                cols=7,
                rho_comm=0.3,
                seed=4,
                consensus_steps=10,
                orientation="any",
                threshold_auto=True,
                levels=3,
            ),
            3,
            True,
        ),
    ],
)
def test_protocols_on_a_bus_equal_the_simulator_whatever_the_delivery_order(
    params, order, shared_link
):
    grid = np.random.default_rng(order).uniform(0, 255, (params.rows, params.cols))
    bus = Bus(params, grid, seed=order, shared_link=shared_link)
    bus.run()
    assert all(p.phase == DONE and p.deadlines == 0 for p in bus.robots.values())
    reference = simulate(params, grid)
    final = np.array([bus.robots[i].core.state for i in range(params.count)])
    width = reference.p.shape[-1]  # a histogram (--levels) follows p in what robots average
    p = np.array([bus.robots[i].core.p[:width] for i in range(params.count)])
    assert np.array_equal(final.reshape(params.rows, params.cols), reference.final)
    assert np.array_equal(p.reshape(reference.p.shape), reference.p)


def test_a_neighbour_known_to_be_alive_is_waited_for_past_the_deadline():
    # Robot 1 between 0 and 2: 2 dies; 0 is alive (say, in 1's own process) but slow.
    params = CamoParams(rows=1, cols=3)
    protocol = robot(params, 0, 1, known_alive=lambda r: r == 0)
    into_consensus(protocol, [0, 2])
    tick_until(protocol, 0.0, 5.0)
    # 2 is given up on, 0 is not: 1 still waits for 0's vote, with one deadline counted.
    assert protocol.silent == {protocol.slot_of[2]} and protocol.deadlines == 1
    assert protocol.step == 0
    protocol.deliver(vote(0, 0, 2), 5.1)
    assert protocol.step == 1 and protocol.deadlines == 1


def test_reports_spaced_in_time_still_carry_every_step_and_rebuild_the_same_record():
    from camo_core.results.record import RoundRecord

    params = CamoParams(rows=2, cols=3, consensus_steps=12, formation_steps=6, seed=2)
    grid = np.random.default_rng(5).uniform(0, 255, (params.rows, params.cols))
    records = []
    for period in (0.0, 10.0):  # every step, or (almost) only at phase changes
        bus = Bus(params, grid, seed=1)
        for p in bus.robots.values():
            p.report_period = period
        bus.run()
        record = RoundRecord(params)
        for report in bus.reports:
            record.add(report)
        records.append((record, len(bus.reports)))
    (every, n_every), (spaced, n_spaced) = records
    assert n_spaced == 3 * params.count < n_every  # vote, end of consensus, done
    for name in ("p_trace", "state_trace", "initial", "state", "selected", "sensed"):
        assert np.array_equal(getattr(every, name), getattr(spaced, name), equal_nan=True), name
    assert not np.isnan(spaced.p_trace).any() and (spaced.state_trace >= 0).all()


def test_a_robot_stopped_between_spaced_reports_reports_every_step_it_took_since():
    protocol = robot(CamoParams(rows=1, cols=2), 0, 0, report_period=10.0)
    into_consensus(protocol, [1])
    for step in range(3):
        assert not protocol.deliver(vote(1, step), 0.1 * (step + 1)).reports  # within the period
    report = protocol.report_now(0.5).reports[-1]
    assert report.step == 3 and report.p_from == 1 and len(report.p_trace) == 3 * 3
    assert not protocol.report_now(0.6).reports[-1].p_trace  # nothing new since


def test_a_robot_done_reports_nothing_more_when_its_process_stops():
    params = CamoParams(rows=2, cols=2, consensus_steps=3, formation_steps=2)
    bus = Bus(params, np.full((2, 2), 100.0), seed=1)
    bus.run()
    assert all(p.done for p in bus.robots.values())
    assert [p.report_now(99.0).reports for p in bus.robots.values()] == [[]] * params.count
