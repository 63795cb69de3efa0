"""Hand-worked cases of the per-robot rules, one rule at a time."""

import pytest
from hypothesis import given
from hypothesis import strategies as st

from camo_core.algorithm import rules
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.rules import HORIZONTAL, MOTTLED, VERTICAL

PAPER = CamoParams(profile="paper")
DROPLET = CamoParams(profile="droplet")


# ---- descriptor --------------------------------------------------------------


def test_missing_side_takes_the_opposite_side():
    # Top row: no top neighbour, so T takes B ("counts its bottom neighbour twice").
    assert rules.reflect_four(100.0, [None, 10.0, 40.0, 20.0]) == (40.0, 10.0, 40.0, 20.0)


def test_corner_takes_opposites_and_lone_robot_takes_itself():
    # Top-left corner: T <- B, L <- R.
    assert rules.reflect_four(100.0, [None, 10.0, 40.0, None]) == (40.0, 10.0, 40.0, 10.0)
    # A 1x1 grid: everything is the robot's own value.
    assert rules.reflect_four(7.0, [None] * 4) == (7.0, 7.0, 7.0, 7.0)


def test_paper_vote_uses_second_differences():
    # Px = L + R - 2M = 0; Py = T + B - 2M = 200 -> |Py| - |Px| = 200 > 50: horizontal.
    assert rules.vote(100.0, [200.0, 100.0, 200.0, 100.0], PAPER) == HORIZONTAL
    assert rules.vote(100.0, [100.0, 0.0, 100.0, 0.0], PAPER) == VERTICAL
    # |Py| - |Px| = 50 exactly is not above the threshold: mottled.
    assert rules.vote(100.0, [125.0, 100.0, 125.0, 100.0], PAPER) == MOTTLED


def test_paper_and_droplet_disagree_on_a_ramp():
    # A vertical ramp T=0, M=100, B=200: Py = 0 for the paper, Dy = 200 for the droplet.
    received = [0.0, 100.0, 200.0, 100.0]
    assert rules.vote(100.0, received, PAPER) == MOTTLED
    assert rules.vote(100.0, received, DROPLET) == HORIZONTAL


def test_threshold_is_a_parameter():
    received = [160.0, 100.0, 160.0, 100.0]  # Dy - Dx = 120
    assert rules.vote(100.0, received, DROPLET) == HORIZONTAL
    assert rules.vote(100.0, received, DROPLET.with_(threshold=130.0)) == MOTTLED


# ---- consensus ---------------------------------------------------------------


def test_metropolis_step_by_hand():
    # Robot of degree 2 with neighbours of degree 3 and 1: weights 1/4 and 1/3.
    p = rules.consensus_step(
        (1.0, 0.0, 0.0), 2, [((0.0, 1.0, 0.0), 3), ((0.0, 0.0, 1.0), 1)] + [None] * 6
    )
    assert p == pytest.approx((1 - 0.25 - 1 / 3, 0.25, 1 / 3))
    assert sum(p) == pytest.approx(1.0)


unit = st.floats(0.0, 1.0)
vote3 = st.tuples(st.tuples(unit, unit, unit), st.integers(0, 8))


@given(st.tuples(unit, unit, unit), st.integers(0, 8), st.lists(st.none() | vote3, max_size=8))
def test_the_written_out_3_vector_step_has_the_bits_of_the_general_loop(p, degree, received):
    """The paper's 3-vector takes a written-out path; each component of the general loop is
    computed alone, so a 4-vector's first three are what the loop gives the 3-vector."""
    general = rules.consensus_step(
        (*p, 0.5), degree, [m and ((*m[0], 0.25), m[1]) for m in received]
    )
    assert rules.consensus_step(p, degree, received) == general[:3]


def test_lost_message_keeps_its_weight_at_home():
    both = [((0.0, 1.0, 0.0), 2), ((0.0, 1.0, 0.0), 2)] + [None] * 6
    one_lost = [((0.0, 1.0, 0.0), 2), None] + [None] * 6
    assert rules.consensus_step((1.0, 0.0, 0.0), 2, both) == pytest.approx((1 / 3, 2 / 3, 0.0))
    # The lost neighbour's 1/3 stays with the robot: 1 - 1/3 on its own vote, not renormalised.
    assert rules.consensus_step((1.0, 0.0, 0.0), 2, one_lost) == pytest.approx((2 / 3, 1 / 3, 0.0))


def test_selection_is_strict_maximum_and_ties_go_to_mottled():
    assert rules.select_pattern((0.5, 0.3, 0.2)) == HORIZONTAL
    assert rules.select_pattern((0.2, 0.5, 0.3)) == VERTICAL
    assert rules.select_pattern((0.4, 0.4, 0.2)) == MOTTLED
    assert rules.select_pattern((0.4, 0.2, 0.4)) == MOTTLED
    assert rules.select_pattern((1 / 3, 1 / 3, 1 / 3)) == MOTTLED


# ---- pattern formation -------------------------------------------------------


def test_initial_state_is_dark_below_127():
    assert rules.initial_state(126.99) == 1
    assert rules.initial_state(127.0) == 0


def test_cardinal_and_far_slots_take_the_opposite():
    received = [None, 1, 0, None, 1, 1, 1, 1, None, 0, 1, None]
    filled = rules.fill_states(received)
    assert filled[0] == 0 and filled[3] == 1 and filled[8] == 1 and filled[11] == 0


def test_diagonal_mirror_order_row_then_column_then_point():
    # Slot 4 (up-right) missing: row mirror 5 (down-right) first.
    received = [0] * 12
    received[4], received[5], received[7], received[6] = None, 1, 0, 0
    assert rules.fill_states(received)[4] == 1
    # Top-right corner robot: 4, 0, 1, 5 ... 4 and 5 missing -> column mirror 7.
    received[5], received[7] = None, 1
    assert rules.fill_states(received)[4] == 1
    # Only the point-opposite 6 is left.
    received[7], received[6] = None, 1
    assert rules.fill_states(received)[4] == 1
    # Nothing at all: off.
    assert rules.fill_states([None] * 12) == [0] * 12


def test_fill_reads_only_values_that_arrived():
    # 4 and 5 missing, 7 on: 5 must fill from 6 (its column mirror), not from a filled 4.
    received = [0, 0, 0, 0, None, None, 0, 1, 0, 0, 0, 0]
    filled = rules.fill_states(received)
    assert filled[4] == 1 and filled[5] == 0


def test_young_rule_counts_activators_and_inhibitors():
    # Horizontal: left and right on (2 activators + self on = 3), top and bottom on (2 inhibitors):
    # S = 3 - 0.75 * 2 = 1.5 > 0 -> on.
    states = [1, 1, 1, 1] + [0] * 8
    assert rules.formation_step(1, HORIZONTAL, states, PAPER) == 1
    # Vertical stripes see the same neighbourhood with roles swapped the other way: still 3 - 1.5.
    assert rules.formation_step(1, VERTICAL, states, PAPER) == 1
    # Self off, only inhibitors on: S < 0 -> off.
    assert rules.formation_step(0, HORIZONTAL, [1, 0, 1, 0, 1, 1, 1, 1, 0, 0, 0, 0], PAPER) == 0


def test_zero_strength_turns_off_on_paper_and_keeps_state_on_droplet():
    # Horizontal: self on + 2 activators = 3, and 4 inhibitors on: S = 3 - 0.75 * 4 = 0 exactly.
    states = [1, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0]
    assert rules.formation_step(1, HORIZONTAL, states, PAPER) == 0
    assert rules.formation_step(1, HORIZONTAL, states, DROPLET) == 1
    # Droplet mottled weight is -0.60: self + 2 = 3 = 0.6 * 5 inhibitors -> S == 0, state kept.
    mottled = [1, 1, 0, 0, 1, 1, 1, 1, 1, 0, 0, 0]
    assert rules.formation_step(1, MOTTLED, mottled, DROPLET) == 1
    assert rules.formation_step(0, MOTTLED, [1, 1, 1, 0, 1, 1, 1, 1, 1, 0, 0, 0], DROPLET) == 0
