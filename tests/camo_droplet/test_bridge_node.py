"""The Droplet bridge: monitor mode, one-line errors, and bridged swarms that equal the
reference simulator given the Droplets' readings."""

import os
import subprocess
import sys

import cv2
import numpy as np
import pytest
from support import (
    COMPUTE,
    ROOT,
    SWARM,
    StatusListener,
    assert_like_sim,
    camo_run,
    domain,
    finished,
    ros_node,
    run_camo,
)

from camo_core.algorithm.backgrounds import background
from camo_core.algorithm.sensing import Calibration, rgb_to_gray
from camo_droplet.emulator import DropletEmulator, Faults, emulated_rgb

TRANSCRIPT = ROOT / "tests" / "data" / "firmware_transcript.txt"


CELLS = [(2, 3), (5, 6)]


LED_ON, LED_OFF = (255, 0, 0), (255, 255, 255)


def tinted_forest(path) -> np.ndarray:
    """A colour background, so that the profile's grey weights matter."""
    grey = background("forest").astype(np.float64)
    image = np.dstack([grey * 0.5, grey * 0.9, grey]).astype(np.uint8)
    cv2.imwrite(str(path), image)
    return image


def bridged_run(
    tmp_path, emulator, faults: list[Faults], extra: tuple[str, ...] = ()
) -> list[DropletEmulator]:
    """A bridged swarm equal to the simulator given the Droplets' readings (`extra`: more of
    the run's options); each Droplet's LED shows what its robot shows."""
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
        *extra,
    ]
    emulators, overrides = [], []
    for (row, col), fault in zip(CELLS, faults, strict=False):
        rgb = emulated_rgb(image, 8, 8, row, col)
        emulators.append(emulator(rgb=rgb, faults=fault))
        grey = calibration.apply(rgb_to_gray(*rgb, "droplet"))
        colour = ",".join(repr(calibration.apply(c)) for c in rgb)  # calibrated as the grey
        overrides += ["--sensed", f"{row},{col}={grey!r}/{colour}"]
    bridges = [
        x
        for (row, col), em in zip(CELLS, emulators, strict=False)
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
    run_summary = assert_like_sim(tmp_path / "run", tmp_path / "sim")
    for (row, col), em in zip(CELLS, emulators, strict=False):
        if "--colours" in extra:  # the palette colour its robot shows
            assert em.led == tuple(run_summary["display"][row][col])
        else:
            assert em.led == (LED_ON if run_summary["final"][row][col] == 1 else LED_OFF)
    return emulators


@pytest.mark.slow(SWARM)
def test_monitor_mode_turns_a_transcript_into_status_messages():
    from camo_msgs.msg import RobotStatus

    domain_id = domain()
    bridge = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "camo_droplet.bridge_node",
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
            "-p",
            "run_id:=firmware",
        ],
        env={**os.environ, "ROS_DOMAIN_ID": str(domain_id)},
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        with StatusListener(domain_id, "firmware") as listener:
            listener.spin_until(lambda: len(listener.got) >= 5, timeout=30)
    finally:
        bridge.send_signal(2)
        finished(bridge, 30)
    got = listener.got
    assert len(got) == 5
    assert {m.sender_id for m in got} == {6}  # the cell (1, 2) of a 3-column grid
    assert got[0].phase == RobotStatus.PHASE_SENSING and got[0].sensed == 187.0
    last = got[-1]
    assert last.phase == RobotStatus.PHASE_CONSENSUS and last.step == 2
    assert list(last.p) == [0.5, 0.25, 0.25] and last.pattern == RobotStatus.PATTERN_HORIZONTAL


def bridge(*ros_args: str) -> subprocess.CompletedProcess:
    return ros_node("camo_droplet.bridge_node", *ros_args)


@pytest.mark.slow(COMPUTE)
def test_bridge_without_a_port_exits_with_one_line():
    out = bridge("-p", "rows:=4", "-p", "cols:=4")
    assert out.returncode == 2 and "serial port" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1


@pytest.mark.slow(COMPUTE)
def test_a_port_that_is_not_there_is_said_at_once_not_after_waiting_for_a_run(tmp_path):
    # No run is in this domain: had the bridge waited for one, it would say so after 60 s.
    out = bridge("-p", "rows:=4", "-p", "cols:=4", "-p", f"port:={tmp_path / 'ttyUSB9'}")
    assert out.returncode == 2, out.stderr
    port = tmp_path / "ttyUSB9"
    said = f"droplet_bridge: error: no serial port {port} (is the Droplet plugged in?)"
    assert out.stderr.strip() == said


@pytest.mark.slow(COMPUTE)
def test_bridged_droplets_give_the_simulators_states_for_their_readings(tmp_path, emulator):
    bridged_run(tmp_path, emulator, [Faults(), Faults()])


@pytest.mark.slow(COMPUTE)
def test_a_bridged_droplets_led_shows_its_palette_colour(tmp_path, emulator):
    bridged_run(tmp_path, emulator, [Faults(), Faults()], ("--colours", "3"))


@pytest.mark.slow(COMPUTE)
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


@pytest.mark.slow(SWARM)
def test_bad_bridge_options_are_one_line_errors(tmp_path):
    for bad in (
        ["--bridge", "2,3"],
        ["--bridge", "9,9=/dev/null"],
        ["--bridge", "1,1=/dev/null", "--bridge", "1,1=/dev/zero"],
        ["--bridge", "1,1=/tmp"],  # not a serial port
        ["--bridge", "1,1=/a", "--calibration", str(tmp_path / "missing.yaml")],
    ):
        out = camo_run("--rows", "4", "--cols", "4", *bad, "--out", str(tmp_path / "o"))
        assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1, (bad, out.stderr)


@pytest.mark.slow(COMPUTE)
@pytest.mark.parametrize(
    "options, named",
    [
        (["threshold_auto:=true"], "threshold_auto (--threshold auto)"),
        (["orientation:=any"], "orientation any (--orientation any)"),
        (["threshold_auto:=true", "orientation:=any"], "threshold_auto (--threshold auto) or"),
        (["levels:=4"], "levels 4 (--levels 4)"),
        (["colours:=4"], "colours 4 (--colours 4)"),
    ],
)
def test_monitor_mode_names_the_options_the_firmware_does_not_have(options, named):
    settings = [x for option in options for x in ("-p", option)]
    out = bridge("-p", "monitor:=true", "-p", "port:=/dev/null", *settings)
    assert out.returncode == 2, out.stderr
    assert len(out.stderr.strip().splitlines()) == 1
    assert out.stderr.strip().startswith(
        f"droplet_bridge: error: a Droplet's firmware cannot run {named}"
    )
