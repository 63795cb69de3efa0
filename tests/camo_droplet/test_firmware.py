"""The camouflage firmware's printouts read as a robot's state."""

from support import ROOT

from camo_droplet.firmware import FirmwareState

TRANSCRIPT = ROOT / "tests" / "data" / "firmware_transcript.txt"


def test_firmware_printouts_become_state():
    state = FirmwareState(droplet_id=0x00C3)
    changed = [state.feed(line) for line in TRANSCRIPT.read_text(errors="replace").splitlines()]
    assert state.sensed == 187.0 and state.neighbour_colors == {0x00A1: 40}
    assert state.p == (0.5, 0.25, 0.25) and state.steps == 2 and state.pattern == 0
    assert sum(changed) == 5
