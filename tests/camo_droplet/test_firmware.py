"""The camouflage firmware's printouts read as a robot's state."""

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st
from support import ROOT

from camo_core.swarm.validation import REPORT_TOLERANCE, probability_vector
from camo_droplet.firmware import FirmwareState

TRANSCRIPT = ROOT / "tests" / "data" / "firmware_transcript.txt"


def test_firmware_printouts_become_state():
    state = FirmwareState(droplet_id=0x00C3)
    changed = [state.feed(line) for line in TRANSCRIPT.read_text(errors="replace").splitlines()]
    assert state.sensed == 187.0 and state.neighbour_colors == {0x00A1: 40}
    assert state.p == (0.5, 0.25, 0.25) and state.steps == 2 and state.pattern == 0
    assert sum(changed) == 5


# ---- fuzzed: whatever the firmware prints ----------------------------------------------------

NUMBERISH = st.text(alphabet="0123456789.-e+ ,naif", max_size=12)
LINES = st.one_of(
    st.text(max_size=80),
    st.builds("Px: {} Py: {}".format, NUMBERISH, NUMBERISH),
    st.builds("Pre-pattern: [{}] Cur-pattern: [{}]".format, NUMBERISH, NUMBERISH),
    st.builds(
        "{}[{}] Color: {}".format,
        NUMBERISH,
        st.text("0123456789ABCDEFabcdef", max_size=5),
        NUMBERISH,
    ),
)


@given(st.lists(LINES, max_size=30))
def test_any_printout_leaves_a_state_the_monitor_can_take(lines):
    state = FirmwareState(droplet_id=0x00C3)
    for line in lines:
        state.feed(line)
    assert state.p is None or probability_vector(state.p, REPORT_TOLERANCE)
    assert math.isnan(state.sensed) or 0 <= state.sensed <= 255
    assert state.pattern in (None, 0, 1, 2)


@pytest.mark.parametrize(
    "line",
    [
        "Px: nan Py: 0.1",
        "Px: 1e400 Py: 0",
        "Px: -0.5 Py: 0.2",
        "Px: 1.2.3 Py: 0",
        "Pre-pattern: [0 0 1] Cur-pattern: [nan 0.5 0.5]",
        "Pre-pattern: [0 0 1] Cur-pattern: [inf 0 0]",
        "Pre-pattern: [0 0 1] Cur-pattern: [0.5 0.5]",
        "Pre-pattern: [0 0 1] Cur-pattern: [2 -1 0]",
        "195[00C3] Color: 256",
        "195[00C3] Color: " + "9" * 5000,
        "195[00C3] Color: \u0661\u0662",
        "195[00C3] Color: -1",
        "\x00\x01\x02",
        "P" * 5000,
    ],
)
def test_a_line_with_a_number_no_robot_prints_is_ignored_and_counted(line):
    state = FirmwareState(droplet_id=0x00C3)
    assert state.feed(line) is False
    assert state.ignored == 1 and state.p is None and math.isnan(state.sensed)
