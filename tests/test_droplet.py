"""The hardware bridge: a Droplet's serial link, its emulator, monitor mode, and bridged swarms that
equal the reference simulator given the Droplets' readings."""

import json
import os
import subprocess
import sys
import time

import cv2
import numpy as np
import pytest
from conftest import ROOT, StatusListener, camo_run, domain, ros_context, run_camo

from camo_core.backgrounds import background
from camo_core.sensing import rgb_to_gray, to_gray
from camo_nodes.droplet_emulator import DropletEmulator, Faults, emulated_rgb
from camo_nodes.droplet_link import (
    Calibration,
    DropletDisconnected,
    DropletError,
    DropletLink,
    LineReader,
)
from camo_nodes.firmware import FirmwareState

TRANSCRIPT = ROOT / "tests" / "data" / "firmware_transcript.txt"


@pytest.fixture
def emulator(tmp_path):
    made = []

    def make(rgb=(10, 20, 30), faults=None, droplet_id=0x1A2B):
        em = DropletEmulator(
            tmp_path / f"droplet{len(made)}",
            droplet_id,
            rgb,
            faults,
            led_log=tmp_path / f"led{len(made)}.log",
            seed=len(made),
        ).start()
        made.append(em)
        return em

    yield make
    for em in made:
        em.stop()


def connected(em, **kwargs) -> DropletLink:
    link = DropletLink(str(em.link), **kwargs)
    link.open()
    return link


# ---- grey, calibration, lines -------------------------------------------------------------


@pytest.mark.parametrize("profile", ["paper", "droplet"])
def test_a_grey_reading_gives_its_own_value_in_both_profiles(profile):
    for v in (0, 1, 77, 128, 254, 255):
        assert rgb_to_gray(v, v, v, profile) == v


def test_a_colour_reading_is_grey_as_the_image_pixel_would_be():
    for r, g, b in ((200, 10, 30), (0, 255, 7), (13, 14, 250)):
        pixel = np.array([[[b, g, r]]], np.uint8)
        assert rgb_to_gray(r, g, b, "paper") == to_gray(pixel, "paper")[0, 0]
        assert rgb_to_gray(r, g, b, "droplet") == 0.5 * r + 0.5 * g
    with pytest.raises(ValueError):
        rgb_to_gray(256, 0, 0, "paper")


def test_calibration_is_identity_by_default_and_reads_yaml(tmp_path):
    assert Calibration().apply(123.5) == 123.5
    path = tmp_path / "cal.yaml"
    path.write_text("gain: 1.1\noffset: -5\n")
    cal = Calibration.from_yaml(path)
    assert (
        cal.apply(100) == pytest.approx(105.0) and cal.apply(250) == 255.0 and cal.apply(1) == 0.0
    )
    path.write_text("gain: [1\n")
    with pytest.raises(ValueError, match="not YAML"):
        Calibration.from_yaml(path)
    path.write_text("gain: 0\n")
    with pytest.raises(ValueError, match="positive"):
        Calibration.from_yaml(path)


def test_line_reader_splits_crlf_and_discards_garbage_and_long_lines():
    reader = LineReader()
    lines = reader.feed(b"My ID is: 00C3\r\nr: 1, g: 2,") + reader.feed(
        b" b: 3\r\n\xff\xfe\x01junk\r\n"
    )
    lines += reader.feed(b"#" * 500 + b"\r\nok\n")
    assert lines == ["My ID is: 00C3", "r: 1, g: 2, b: 3", "ok"]
    assert reader.discarded == 2


# ---- the link against the emulator --------------------------------------------------------


def test_link_reads_id_and_colour_and_sets_the_led(emulator):
    em = emulator(rgb=(200, 100, 50), droplet_id=0x00C3)
    link = connected(em)
    assert link.get_id() == 0x00C3
    assert link.get_rgb() == (200, 100, 50)
    link.set_led(255, 0, 0)
    assert em.led == (255, 0, 0)
    assert json.loads((em.led_log).read_text().splitlines()[-1])["rgb"] == [255, 0, 0]


def test_unknown_command_is_an_error_naming_it(emulator):
    link = connected(emulator())
    with pytest.raises(DropletError, match="does not know the command 'blink'"):
        link.command("blink", None)
    assert link.get_rgb() == (10, 20, 30)  # and the link still works


def test_link_survives_garbage_chatter_and_dropped_replies(emulator):
    em = emulator(faults=Faults(drop=0.3, garbage=0.5, chatter=0.5))
    link = connected(em, timeout=0.2, retries=8)
    for _ in range(15):
        assert link.get_rgb() == (10, 20, 30)
    assert link.reader.discarded > 0
    assert any(line.startswith("Px:") for line in link.poll())


def test_a_robot_that_never_answers_gives_a_clear_error(emulator):
    link = connected(emulator(faults=Faults(drop=1.0)), timeout=0.1, retries=2)
    with pytest.raises(DropletError, match="did not answer 'get_rgb' \\(3 tries"):
        link.get_rgb()


def test_a_port_that_disappears_raises_and_can_be_reopened(emulator):
    em = emulator(faults=Faults(disconnect_after=2, disconnect_for=0.5))
    link = connected(em)
    assert link.get_rgb() == (10, 20, 30)
    with pytest.raises(DropletDisconnected):
        link.get_rgb()
    assert not link.connected
    deadline = time.monotonic() + 10
    while True:
        try:
            link.open()
            break
        except DropletDisconnected:
            assert time.monotonic() < deadline
            time.sleep(0.1)
    assert link.get_rgb() == (10, 20, 30)


def test_emulator_reads_the_mean_colour_of_its_block():
    image = np.zeros((16, 16, 3), np.uint8)
    image[8:, 8:] = (10, 20, 30)  # BGR: bottom-right block
    image[8:12, 8:] = (10, 20, 40)
    assert emulated_rgb(image, 2, 2, 1, 1) == (35, 20, 10)
    assert emulated_rgb(image, 2, 2, 0, 0) == (0, 0, 0)


def test_emulator_command_line_rejects_bad_options(tmp_path):
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "camo_nodes.droplet_emulator",
            "--link",
            str(tmp_path / "x"),
            "--cell",
            "9,9",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2 and "inside the 8x8 arena" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1


# ---- monitor mode ---------------------------------------------------------------------------


def test_firmware_printouts_become_state():
    state = FirmwareState(droplet_id=0x00C3)
    changed = [state.feed(line) for line in TRANSCRIPT.read_text(errors="replace").splitlines()]
    assert state.sensed == 187.0 and state.neighbour_colors == {0x00A1: 40}
    assert state.p == (0.5, 0.25, 0.25) and state.steps == 2 and state.pattern == 0
    assert sum(changed) == 5


def test_monitor_mode_turns_a_transcript_into_status_messages():
    from camo_msgs.msg import RobotStatus

    domain_id = domain()
    bridge = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "camo_nodes.droplet_bridge",
            "--ros-args",
            "-p",
            "rows:=4",
            "-p",
            "cols:=4",
            "-p",
            "row:=1",
            "-p",
            "col:=2",
            "-p",
            f"transcript:={TRANSCRIPT}",
        ],
        env={**os.environ, "ROS_DOMAIN_ID": str(domain_id)},
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        with StatusListener(domain_id) as listener:
            listener.spin_until(lambda: len(listener.got) >= 5, timeout=30)
    finally:
        bridge.send_signal(2)
        bridge.communicate(timeout=30)
    got = listener.got
    assert len(got) == 5
    assert {(m.sender_id, m.row, m.col) for m in got} == {(6, 1, 2)}
    assert got[0].phase == RobotStatus.PHASE_SENSING and got[0].sensed == 187.0
    last = got[-1]
    assert last.phase == RobotStatus.PHASE_CONSENSUS and last.step == 2
    assert list(last.p) == [0.5, 0.25, 0.25] and last.pattern == RobotStatus.PATTERN_HORIZONTAL


def test_bridge_without_a_port_exits_with_one_line():
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "camo_nodes.droplet_bridge",
            "--ros-args",
            "-p",
            "rows:=4",
            "-p",
            "cols:=4",
        ],
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "ROS_DOMAIN_ID": str(domain())},
    )
    assert out.returncode == 2 and "serial port" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1


# ---- the simulator's real readings ---------------------------------------------------------


def test_sim_takes_real_readings_without_noise(tmp_path):
    out = run_camo("sim", "--rho-meas", "1.0", "--sensed", "2,3=201.5", "--out", str(tmp_path))
    assert out.returncode == 0, out.stderr
    sensed = json.loads((tmp_path / "summary.json").read_text())["sensed"]
    assert sensed[2][3] == 201.5
    assert (
        sum(v == int(v) for row in sensed for v in row) == 64 - 1
    )  # the others are noise: integers
    for bad in ("2,3", "9,9=4", "1,1=300"):
        out = run_camo("sim", "--sensed", bad, "--out", str(tmp_path))
        assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1, out.stderr


# ---- bridged swarms --------------------------------------------------------------------------

CELLS = [(2, 3), (5, 6)]
LED_ON, LED_OFF = (255, 0, 0), (255, 255, 255)


def tinted_forest(path) -> np.ndarray:
    """A colour background, so that the profile's grey weights matter."""
    grey = background("forest").astype(np.float64)
    image = np.dstack([grey * 0.5, grey * 0.9, grey]).astype(np.uint8)
    cv2.imwrite(str(path), image)
    return image


def bridged_run(tmp_path, emulator, faults: list[Faults]) -> list[DropletEmulator]:
    image = tinted_forest(tmp_path / "tinted.png")
    (tmp_path / "cal.yaml").write_text("gain: 1.1\noffset: -5\n")
    calibration = Calibration.from_yaml(tmp_path / "cal.yaml")
    options = [
        "--image",
        str(tmp_path / "tinted.png"),
        "--profile",
        "droplet",
        "--rho-meas",
        "0.2",
        "--rho-comm",
        "0.1",
        "--seed",
        "3",
    ]
    emulators, overrides = [], []
    for (row, col), fault in zip(CELLS, faults):
        rgb = emulated_rgb(image, 8, 8, row, col)
        emulators.append(emulator(rgb=rgb, faults=fault))
        overrides += [
            "--sensed",
            f"{row},{col}={calibration.apply(rgb_to_gray(*rgb, 'droplet'))!r}",
        ]
    bridges = [
        x
        for (row, col), em in zip(CELLS, emulators)
        for x in ("--bridge", f"{row},{col}={em.link}")
    ]
    swarm = camo_run(
        *options,
        *bridges,
        "--calibration",
        str(tmp_path / "cal.yaml"),
        "--out",
        str(tmp_path / "run"),
    )
    assert swarm.returncode == 0, swarm.stderr[-3000:]
    sim = run_camo("sim", *options, *overrides, "--out", str(tmp_path / "sim"))
    assert sim.returncode == 0, sim.stderr
    run_summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    sim_summary = json.loads((tmp_path / "sim" / "summary.json").read_text())
    for key in sim_summary:
        if key != "elapsed_s":
            assert run_summary[key] == sim_summary[key], key
    for (row, col), em in zip(CELLS, emulators):
        assert em.led == (LED_ON if run_summary["final"][row][col] == 1 else LED_OFF)
    return emulators


def test_bridged_droplets_give_the_simulators_states_for_their_readings(tmp_path, emulator):
    bridged_run(tmp_path, emulator, [Faults(), Faults()])


def test_bridged_run_finishes_through_garbage_and_a_reconnect(tmp_path, emulator):
    emulators = bridged_run(
        tmp_path,
        emulator,
        [
            Faults(garbage=0.4, chatter=0.4),
            Faults(garbage=0.4, disconnect_after=3, disconnect_for=1.0),
        ],
    )
    assert emulators[1].disconnects >= 1


def test_bad_bridge_options_are_one_line_errors(tmp_path):
    for bad in (
        ["--bridge", "2,3"],
        ["--bridge", "9,9=/dev/null"],
        ["--bridge", "1,1=/a", "--bridge", "1,1=/b"],
        ["--bridge", "1,1=/a", "--calibration", str(tmp_path / "missing.yaml")],
    ):
        out = camo_run("--rows", "4", "--cols", "4", *bad, "--out", str(tmp_path / "o"))
        assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1, (bad, out.stderr)


def test_monitor_counts_bridged_robots_whose_hardware_is_offline():
    from camo_core.params import CamoParams
    from camo_msgs.msg import RobotStatus
    from camo_nodes.monitor_node import MonitorNode

    with ros_context() as context:
        monitor = MonitorNode(CamoParams(rows=2, cols=2), context=context)
        monitor._on_status(RobotStatus(sender_id=3, row=1, col=1, phase=2, alive=False))
        assert "hardware offline 1" in monitor.progress_line()
        monitor._on_status(RobotStatus(sender_id=3, row=1, col=1, phase=2, alive=True))
        assert "offline" not in monitor.progress_line()
        monitor.destroy_node()
