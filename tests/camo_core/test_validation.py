"""What a received message must look like: each malformed kind is refused with its reason, and
every message a real robot sends passes."""

import math

import pytest

from camo_core.algorithm.params import CamoParams
from camo_core.swarm.protocol import CONSENSUS, DISCOVERY, FORMATION, SENSING
from camo_core.swarm.robot_io import Message
from camo_core.swarm.validation import message_problem, phase_problem

PARAMS = CamoParams(rows=4, cols=5, consensus_steps=20, formation_steps=6)


@pytest.mark.parametrize(
    "message",
    [
        Message("hello", 7, 0, 0, (1, 2)),
        Message("color", 0, 3, 0, 255.0),
        Message("vote", 19, 0, 19, ((0.2, 0.3, 0.5), 8)),
        Message("state", 4, 1, 5, 1),
    ],
)
def test_well_formed_messages_pass(message):
    assert message_problem(message, PARAMS) is None


@pytest.mark.parametrize(
    ("message", "reason"),
    [
        (Message("vote", 20, 0, 0, ((1.0, 0.0, 0.0), 1)), "sender is not a robot of the grid"),
        (Message("vote", -1, 0, 0, ((1.0, 0.0, 0.0), 1)), "sender is not a robot of the grid"),
        (Message("hello", 7, 0, 0, (0, 7)), "hello from the wrong cell"),
        (Message("color", 3, 0, 0, math.nan), "colour out of range"),
        (Message("color", 3, 0, 0, 300.0), "colour out of range"),
        (Message("color", 3, -1, 0, 10.0), "round out of range"),
        (Message("vote", 3, 0, 20, ((1.0, 0.0, 0.0), 1)), "step out of range"),
        (Message("vote", 3, 0, 0, ((math.nan, 0.5, 0.5), 1)), "vote out of range"),
        (Message("vote", 3, 0, 0, ((2.0, -1.0, 0.0), 1)), "vote out of range"),
        (Message("vote", 3, 0, 0, ((0.5, 0.5, 0.5), 1)), "vote out of range"),
        (Message("vote", 3, 0, 0, ((1.0, 0.0, 0.0), 9)), "vote out of range"),
        (Message("state", 3, 0, 6, 1), "step out of range"),
        (Message("state", 3, 0, 0, 2), "state out of range"),
        (Message("shout", 3, 0, 0, 2), "unknown kind"),
    ],
)
def test_malformed_messages_are_refused_with_their_reason(message, reason):
    assert message_problem(message, PARAMS) == reason


def test_a_message_must_carry_its_kinds_phase():
    phases = {"hello": DISCOVERY, "color": SENSING, "vote": CONSENSUS, "state": FORMATION}
    for kind, phase in phases.items():
        assert phase_problem(kind, phase) is None
        assert phase_problem(kind, phase + 1) == "phase does not match the kind"


def test_energies_pass_only_in_a_run_with_threshold_auto_and_within_range():
    from camo_core.algorithm.rules import energy_step

    auto = PARAMS.with_(threshold_auto=True)
    assert message_problem(Message("energy", 3, 0, 19, (510.0, 8)), auto) is None
    # Averaging the largest energy with itself can round above it: still an energy.
    averaged = energy_step(510.0, 1, [(510.0, 2), *[None] * 7])
    assert (
        averaged > 510.0
        and message_problem(Message("energy", 3, 0, 1, (averaged, 1)), auto) is None
    )
    assert message_problem(Message("energy", 3, 0, 0, (12.5, 8)), PARAMS) == (
        "an energy in a run without --threshold auto"
    )
    assert message_problem(Message("energy", 3, 0, 20, (12.5, 8)), auto) == "step out of range"
    for energy, degree in ((math.nan, 8), (-1.0, 8), (510.5, 8), (12.5, 9)):
        assert message_problem(Message("energy", 3, 0, 0, (energy, degree)), auto) == (
            "energy out of range"
        )
    assert phase_problem("energy", SENSING) is None and phase_problem("energy", CONSENSUS)


def test_relays_and_tensors_pass_only_in_a_run_with_orientation_any():
    oriented = PARAMS.with_(orientation="any")
    relay = Message("relay", 3, 0, 5, (1, 0, None, None, 1, 1, 0, None))
    assert message_problem(relay, oriented) is None
    assert (
        message_problem(relay, PARAMS) == "a relay in a run without --orientation any on the grid"
    )
    on_layout = oriented.with_(layout="hex")
    assert (
        message_problem(relay, on_layout)
        == "a relay in a run without --orientation any on the grid"
    )
    # A layout's robot can have more than eight near neighbours.
    vote = Message("vote", 3, 0, 0, ((0.2, 0.1, 0.0), 11))
    assert message_problem(vote, on_layout) is None
    assert message_problem(vote, oriented) == "vote out of range"
    for bad, reason in (
        ((1, 0, 2, None, 1, 1, 0, None), "relay out of range"),
        ((1, 0), "relay out of range"),
    ):
        assert message_problem(Message("relay", 3, 0, 0, bad), oriented) == reason
    assert message_problem(Message("relay", 3, 0, 6, relay.value), oriented) == "step out of range"
    # What the robots average is a normalised tensor, not a probability vector.
    tensor = Message("vote", 3, 0, 0, ((0.5, 0.2, -0.3), 4))
    assert message_problem(tensor, oriented) is None
    assert message_problem(tensor, PARAMS) == "vote out of range"
    for bad in ((0.7, 0.5, 0.0), (-0.1, 0.5, 0.0), (0.2, 0.2, 0.3), (math.inf, 0.0, 0.0)):
        vote = Message("vote", 3, 0, 0, (bad, 4))
        assert message_problem(vote, oriented) == "vote out of range", bad
    # And every tensor a robot can make passes, however strong or faint its texture.
    from camo_core.algorithm import orientation

    for greys in ([0.0] * 8, [255.0, 0.0] * 4, [0.0, 255.0, 0.0, 255.0, 255.0, 0.0, 0.0, 255.0]):
        for own in (0.0, 128.0, 255.0):
            raw = orientation.raw_tensor(own, greys)
            p = orientation.normalised(*raw, orientation.REGULARISER)
            assert message_problem(Message("vote", 3, 0, 0, (p, 8)), oriented) is None


def test_a_table_of_statuses_gets_each_rows_own_problem():
    """A process's array is checked a column at a time: each row gets what it would alone, so a
    bad row beside good ones refuses that row only."""
    from types import SimpleNamespace

    from camo_core.swarm.status_rows import StatusRows
    from camo_core.swarm.validation import report_problem, rows_problems

    params = CamoParams(rows=3, cols=3, consensus_steps=4, formation_steps=3, levels=4)
    good = dict(phase=2, step=1, sensed=100.0, p=[0.2, 0.3, 0.5], state=1, pattern=0)
    rows = [
        dict(sender_id=0, **good),
        dict(sender_id=9, **good),  # not of the grid
        dict(sender_id=1, **{**good, "step": 5}),  # past the consensus steps
        dict(sender_id=2, **{**good, "p": [0.9, 0.9, 0.9]}),
        dict(sender_id=3, **good, p_trace=[0.2, 0.3, 0.5, 0.1, 0.1]),  # not 3 a step
        dict(sender_id=4, **good, state_trace=[0, 9]),
        dict(sender_id=5, **good, palette=[30, 20, 10, 0]),  # not darkest first
        dict(sender_id=6, **good, silent=[1, 99]),
        dict(sender_id=7, **good, p_trace=[0.2, 0.3, 0.5], palette=[0, 10, 20, 30], silent=[6]),
    ]
    reports = [SimpleNamespace(**r) for r in rows]
    together = rows_problems(StatusRows.from_reports(reports), params)
    alone = [report_problem(r, params) for r in reports]
    assert together == alone
    assert together[0] is None and together[-1] is None
    assert all(problem is not None for problem in together[1:-1])
