"""Robots started alone with `robot_node`, and a worker started by hand: one-line errors, and a
run of them equals the simulator. And how often a process's robots report."""

import os
import subprocess
import sys
from types import SimpleNamespace

import pytest
from support import SWARM, assert_like_sim, domain, finished, ros_node, run_camo, start_run

from camo_core.swarm.keys import KEY_FILE_ENV, new_key_file


def test_robot_with_cell_outside_grid_exits_with_one_line():
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "camo_nodes.robot_node",
            "--ros-args",
            "-p",
            "rows:=4",
            "-p",
            "cols:=4",
            "-p",
            "row:=9",
            "-p",
            "col:=0",
        ],
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "ROS_DOMAIN_ID": str(domain())},
    )
    assert out.returncode == 2
    assert "outside the 4x4 grid" in out.stderr and len(out.stderr.strip().splitlines()) == 1


def test_a_processs_robots_report_about_2000_times_a_second_at_most_however_many(monkeypatch):
    """Between phase changes a robot reports once a period at most (tests/camo_core/
    test_protocol.py): the periods host_robots gives a process's robots, as many as it hosts."""
    import camo_nodes.robot_node as robot_node
    from camo_core.algorithm.params import CamoParams
    from camo_core.swarm.run_setup import ProtocolParams
    from camo_nodes.topics.names import RunTopics

    def transport(node, params, topics, tiles, *args):  # what host_robots asks of it, no DDS
        hosted = {cell for first, last in tiles for cell in range(first, last + 1)}
        return SimpleNamespace(hosted=hosted, alive=lambda robot: True, mailbox=None)

    monkeypatch.setattr(robot_node, "host_node", lambda topics: SimpleNamespace(context=None))
    monkeypatch.setattr(robot_node, "Transport", transport)
    monkeypatch.setattr(robot_node, "Participants", lambda context: SimpleNamespace(next=object))
    monkeypatch.setattr(robot_node, "RobotNode", lambda steps, *args, **kwargs: steps)
    monkeypatch.setattr(robot_node, "Host", lambda node, transport, projection, robots, *a: robots)
    rates = {}
    for tile in ((0, 0), (0, 4095)):
        robots = robot_node.host_robots(
            CamoParams(rows=64, cols=64), ProtocolParams(), RunTopics("rates"), [tile]
        )
        rates[len(robots)] = sum(1 / robot.report_period for robot in robots)
    # A robot alone: 4 reports a second. 4096 robots: not 16384, about 2000.
    assert rates == {1: pytest.approx(4.0), 4096: pytest.approx(2000.0)}


@pytest.mark.slow(SWARM)
def test_robot_with_negative_rho_exits_with_one_line():
    out = subprocess.run(
        [sys.executable, "-m", "camo_nodes.robot_node", "--ros-args", "-p", "rho_comm:=-0.5"],
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "ROS_DOMAIN_ID": str(domain())},
    )
    assert out.returncode == 2
    assert "rho_comm must be" in out.stderr and len(out.stderr.strip().splitlines()) == 1


@pytest.mark.slow(SWARM)
def test_robots_started_alone_and_a_remote_worker_join_a_run_and_equal_the_simulator(tmp_path):
    domain_id = domain()
    key = str(new_key_file(tmp_path / "alone.key").path)  # the run's, given to all its processes
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id), KEY_FILE_ENV: key}
    options = ["--pattern", "desert", "--rows", "2", "--cols", "3", "--seed", "4"]
    options += ["--rho-comm", "0.2"]
    # The launcher starts no robot: row 0 is a worker's, row 1 three robots alone.
    launcher = start_run(
        *options,
        *["--remote-cells", "0-2", "--remote-cells", "3-5", "--run-id", "alone"],
        *["--key-file", key],
        *["--out", str(tmp_path / "run")],
        domain_id=env["ROS_DOMAIN_ID"],
    )
    robots = []
    for col in range(3):
        robots.append(
            subprocess.Popen(
                [sys.executable, "-m", "camo_nodes.robot_node", "--ros-args"]
                + ["-p", "rows:=2", "-p", "cols:=3", "-p", "row:=1", "-p", f"col:={col}"]
                + ["-p", "seed:=4", "-p", "rho_comm:=0.2", "-p", "run_id:=alone"],
                env=env,
                stderr=subprocess.PIPE,
                text=True,
            )
        )
    # The other row's robots share one process, as a second machine might; it finds the run.
    worker = subprocess.Popen(
        [sys.executable, "-m", "camo_bringup.worker", "--cells", "0-2"],
        env=env,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        _, err = finished(launcher, 180)
        assert launcher.returncode == 0, err[-2000:]
        # Every one of them notices that the run has ended, and exits 0 (their output read as
        # they go: a pipe left full would hold a process up).
        worker_said = worker.communicate(timeout=60)[1]
        assert worker.returncode == 0, worker_said[-2000:]
        for robot in robots:
            said = robot.communicate(timeout=60)[1]
            assert robot.returncode == 0, said[-2000:]
    finally:
        for proc in (launcher, worker, *robots):
            if proc.poll() is None:
                proc.kill()
    assert "hosting robots 0-2 of alone" in worker_said and "alone has ended" in worker_said
    sim = run_camo(*["sim", *options], "--out", str(tmp_path / "sim"))
    assert sim.returncode == 0, sim.stderr
    assert_like_sim(tmp_path / "run", tmp_path / "sim")


def robot_node(*ros_args: str) -> subprocess.CompletedProcess:
    return ros_node("camo_nodes.robot_node", *ros_args)


@pytest.mark.slow(SWARM)
def test_wrong_kinds_and_unknown_parameters_are_one_line_not_a_traceback():
    wrong = robot_node("-p", "rows:=eight", "-p", "run_id:=x")
    assert wrong.returncode == 2 and "rows must be an integer (got 'eight')" in wrong.stderr
    unknown = robot_node("-p", "rowz:=8", "-p", "run_id:=x")
    assert unknown.returncode == 2 and "robot_parameters has no parameter rowz" in unknown.stderr
    for out in (wrong, unknown):
        assert "Traceback" not in out.stderr and len(out.stderr.strip().splitlines()) == 1


def test_an_argument_rcl_does_not_know_is_one_line_not_a_traceback():
    out = robot_node("--help", "-p", "row:=1")
    assert out.returncode == 2, out.stderr
    assert (
        out.stderr.strip() == "robot_node: error: unknown ROS arguments after --ros-args: --help"
    )


def test_an_integer_where_a_number_is_declared_is_that_number():
    # rho_comm:=0 is an integer to ROS; the robot takes it as 0.0 and goes on to its checks.
    out = robot_node("-p", "rho_comm:=0", "-p", "row:=9", "-p", "run_id:=x")
    assert out.returncode == 2 and "outside the 8x8 grid" in out.stderr, out.stderr


@pytest.mark.slow(SWARM)
def test_a_params_file_key_naming_the_robot_applies_to_it(tmp_path):
    params = tmp_path / "params.yaml"
    params.write_text(
        "/**:\n  ros__parameters:\n    rows: 4\n    cols: 4\n    row: 1\n    col: 2\n"
        "    run_id: lab\n"
        "/**/robot_1_2:\n  ros__parameters:\n    rho_comm: 2.0\n"
        "/**/robot_0_0:\n  ros__parameters:\n    rho_comm: 3.0\n"
    )
    out = robot_node("--params-file", str(params))
    # Its own key's value (not robot_0_0's) reaches the checks.
    assert out.returncode == 2 and "rho_comm must be" in out.stderr and "2.0" in out.stderr


def test_a_process_on_a_layout_senses_each_robots_grey_and_colour_round_its_position():
    import numpy as np

    from camo_core.algorithm.layout import colours_at, layout_for, sense_at
    from camo_core.algorithm.params import CamoParams
    from camo_core.algorithm.sensing import ProjectedSensor, Projection
    from camo_nodes.robot_node import projected_on

    params = CamoParams(rows=4, cols=5, layout="hex", orientation="any", colours=3)
    image = np.random.default_rng(1).integers(0, 256, (60, 80, 3)).astype(np.uint8)
    projection = Projection(params.rows, params.cols, params.profile, *projected_on(params))
    projection.add(image)
    layout = layout_for(params)
    greys, colours = sense_at(image, layout), colours_at(image, layout)
    for robot in range(params.count):
        reading = ProjectedSensor(projection, *divmod(robot, params.cols)).read()
        assert reading.value == greys[robot] and reading.rgb == tuple(colours[robot])
    assert not np.allclose(colours[:, 0], colours[:, 2])  # a colour image's channels differ


@pytest.mark.slow(SWARM)
@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_a_robot_stopped_while_it_waits_for_a_run_ends_without_a_traceback(sig):
    import signal
    import time

    proc = subprocess.Popen(
        [sys.executable, "-m", "camo_nodes.robot_node", "--ros-args", "-p", "rows:=2",
         "-p", "cols:=2", "-p", "row:=0", "-p", "col:=0"],
        env={**os.environ, "ROS_DOMAIN_ID": str(domain())},
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    time.sleep(3)  # no run in its domain: it waits for one
    proc.send_signal(getattr(signal, sig))
    _, err = finished(proc, 30)
    assert proc.returncode == 0 and "Traceback" not in err, err
