"""`./camo run --continuous`: the swarm notices a changed scene by itself, on a camera-like image
topic, and each round it starts equals the simulator on its frame with its seed."""

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest
from support import (
    SWARM,
    assert_like_sim,
    bag_tool,
    camo_run,
    domain,
    finished,
    run_camo,
    start_run,
    wait_for_line,
)

CAMERA = "camo_bringup.scene_stream"


def camera(domain_id: int, out: Path, *args: str) -> subprocess.Popen:
    """The camera-like publisher (camo_bringup.scene_stream) on /cam/image_raw in `domain_id`."""
    env = {**__import__("os").environ, "ROS_DOMAIN_ID": str(domain_id)}
    argv = [sys.executable, "-m", CAMERA, "/cam/image_raw", "--out", str(out), *args]
    return subprocess.Popen(argv, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def rounds_of(folder: Path) -> list[dict]:
    with open(folder / "rounds.csv") as file:
        return list(csv.DictReader(file))


def assert_round_like_sim(run: Path, k: int, frames: Path, tmp: Path, *options: str) -> dict:
    """Round k equals `./camo sim` on the frame it names (one the camera sent) with its seed."""
    summary = json.loads((run / f"round_{k}" / "summary.json").read_text())
    frame = frames / f"{summary['background_sha256']}.png"
    assert frame.exists(), "the round's frame is not one the camera sent"
    out = tmp / f"sim_{k}"
    sim = run_camo(
        "sim", "--image", str(frame), "--seed", str(summary["seed"]), *options, "--out", str(out)
    )
    assert sim.returncode == 0, sim.stderr
    assert_like_sim(run / f"round_{k}", out)
    return summary


@pytest.mark.slow(SWARM)
def test_a_continuous_swarm_follows_a_camera_through_three_switches(tmp_path):
    domain_id = domain()
    frames = tmp_path / "frames"
    options = ["--rows", "16", "--cols", "16", "--rho-meas", "0.15", "--rho-comm", "0.05"]
    run = tmp_path / "run"
    cam = camera(
        domain_id, frames, "--scenes", "forest,desert,leopard,forest", "--switch", "6",
        "--fps", "15", "--noise", "6", "--seconds", "90", "--start-when", str(run / "round_0"),
    )  # fmt: skip
    try:
        proc = start_run(
            "--continuous", "--rounds", "4", "--background-topic", "/cam/image_raw",
            *options, "--procs", "2", "--out", str(run), domain_id=domain_id,
        )  # fmt: skip
        _, err = finished(proc, 120)
    finally:
        cam.terminate()
        cam.wait(10)
    assert proc.returncode == 0, err[-3000:]
    rounds = rounds_of(run)
    assert [int(r["round"]) for r in rounds] == [0, 1, 2, 3], err[-3000:]
    assert [r["pattern"] for r in rounds] == ["vertical", "horizontal", "mottled", "vertical"]
    switched = {}  # scene -> when the camera first sent it (wall clock, as ROS time is)
    for line in (frames / "switches.txt").read_text().split("\n"):
        if line:
            _, scene, at = line.split()
            switched.setdefault(int(scene), float(at))
    for k, row in enumerate(rounds):
        summary = assert_round_like_sim(run, k, frames, tmp_path, *options)
        assert summary["noticed_by"] is not None and summary["changed_at"] <= summary["noticed_at"]
        assert summary["noticed_at"] <= summary["done_at"]
        if k:  # a switch: every robot done within 5 s of it
            assert summary["done_at"] - switched[k] < 5.0, (row, switched)


@pytest.mark.slow(SWARM)
def test_a_static_noisy_camera_is_camouflaged_once(tmp_path):
    domain_id = domain()
    cam = camera(domain_id, tmp_path / "frames", "--fps", "15", "--noise", "8", "--seconds", "60")
    try:
        proc = start_run(
            "--continuous", "--duration", "30", "--background-topic", "/cam/image_raw",
            "--rows", "16", "--cols", "16", "--rho-meas", "0.15", "--procs", "2",
            "--out", str(tmp_path / "run"), domain_id=domain_id,
        )  # fmt: skip
        _, err = finished(proc, 120)
    finally:
        cam.terminate()
        cam.wait(10)
    assert proc.returncode == 0, err[-3000:]
    rounds = rounds_of(tmp_path / "run")
    assert len(rounds) == 1 and rounds[0]["pattern"] == "vertical", err[-3000:]
    assert "superseded" not in err


@pytest.mark.slow(SWARM)
def test_a_continuous_run_on_a_still_image_camouflages_it_once_and_ends_after_its_rounds(
    tmp_path,
):
    out = camo_run("--continuous", "--rounds", "1", "--out", str(tmp_path / "run"))
    assert out.returncode == 0, out.stderr[-2000:]
    (row,) = rounds_of(tmp_path / "run")
    assert (row["round"], row["frame"], row["pattern"]) == ("0", "0", "vertical")
    sim = run_camo("sim", "--out", str(tmp_path / "sim"))
    assert sim.returncode == 0
    assert_like_sim(tmp_path / "run" / "round_0", tmp_path / "sim")


@pytest.mark.parametrize(
    "argv, said",
    [
        (["--rounds", "3"], "--rounds ends a --continuous run"),
        (["--duration", "5"], "--duration ends a --continuous run"),
        (["--continuous", "--rounds", "0"], "--rounds must be an integer in 1..1000000"),
        (["--continuous", "--then", "desert"], "--continuous and --then do not go together"),
        (["--video", "a.mp4", "--images", "*.png"], "one background source: video and images"),
        (["--image", "x.png", "--background-topic", "/c"], "image and background_topic"),
    ],
)
def test_continuous_options_that_do_not_fit_are_one_line(argv, said, capsys):
    from camo_bringup import launcher

    code = launcher.main([*argv, "--rows", "2", "--cols", "2"])
    err = capsys.readouterr().err
    assert code == 2 and said in err and len(err.strip().splitlines()) == 1, err


@pytest.mark.slow(SWARM)
def test_a_recorded_continuous_run_renders_its_rounds_one_after_another(tmp_path):
    from PIL import Image

    domain_id = domain()
    run = tmp_path / "run"
    cam = camera(
        domain_id, tmp_path / "frames", "--scenes", "desert,forest", "--switch", "2",
        "--fps", "10", "--seconds", "90", "--start-when", str(run / "round_0"),
    )  # fmt: skip
    try:
        proc = start_run(
            "--continuous", "--rounds", "2", "--background-topic", "/cam/image_raw",
            "--rho-comm", "0.1", "--record", str(tmp_path / "bag"), "--out", str(run),
            domain_id=domain_id,
        )  # fmt: skip
        _, err = finished(proc, 120)
    finally:
        cam.terminate()
        cam.wait(10)
    assert proc.returncode == 0, err[-3000:]
    rendered = bag_tool("render", str(tmp_path / "bag"), "--out", str(tmp_path / "rendered"))
    assert rendered.returncode == 0, rendered.stderr
    for k in (0, 1):
        live = json.loads((run / f"round_{k}" / "summary.json").read_text())
        again = json.loads((tmp_path / "rendered" / f"round_{k}" / "summary.json").read_text())
        live.pop("elapsed_s"), again.pop("elapsed_s")
        assert again == live
    for folder in (run, tmp_path / "rendered"):
        with Image.open(folder / "run.gif") as gif:
            parts = []
            for k in (0, 1):
                with Image.open(folder / f"round_{k}" / "run.gif") as part:
                    parts.append(part.n_frames)
            assert gif.n_frames == sum(parts) + 2  # each round after a card with its frame


@pytest.mark.slow(SWARM)
def test_ctrl_c_of_a_continuous_run_writes_the_round_under_way(tmp_path):
    proc = start_run(
        "--continuous", "--consensus-steps", "30000", "--out", str(tmp_path / "run"),
    )  # fmt: skip
    wait_for_line(proc, "consensus 64")
    proc.send_signal(2)
    _, err = finished(proc, 60)
    assert proc.returncode == 130, err[-2000:]
    summary = json.loads((tmp_path / "run" / "round_0" / "summary.json").read_text())
    assert "incomplete" in summary and summary["frame"] == 0
    assert len(summary["consensus_trace"]) >= 2
