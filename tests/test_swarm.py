"""The distributed swarm: ROS 2 robot nodes in several processes agree with the reference simulator."""

import json
import os
import subprocess
import sys
import time

import pytest
from conftest import (
    ROOT,
    StatusListener,
    camo_run,
    count_round_records,
    domain,
    ros_context,
    run_camo,
    wait_for_line,
)


def summaries(tmp_path, options: list[str], procs: int) -> tuple[dict, dict]:
    swarm = camo_run(*options, "--procs", str(procs), "--out", str(tmp_path / "run"))
    assert swarm.returncode == 0, swarm.stderr[-2000:]
    assert json.loads((tmp_path / "run" / "timing.json").read_text())["deadlines"] == 0
    sim = run_camo("sim", *options, "--out", str(tmp_path / "sim"))
    assert sim.returncode == 0, sim.stderr
    load = lambda name: json.loads((tmp_path / name / "summary.json").read_text())  # noqa: E731
    return load("run"), load("sim")


CASES = [
    (["--pattern", "forest", "--profile", "paper"], 1),
    (
        [
            "--pattern",
            "desert",
            "--profile",
            "droplet",
            "--rows",
            "5",
            "--cols",
            "7",
            "--rho-meas",
            "0.1",
            "--rho-comm",
            "0.1",
            "--seed",
            "3",
        ],
        2,
    ),
    (
        [
            "--pattern",
            "leopard",
            "--profile",
            "paper",
            "--rows",
            "6",
            "--cols",
            "4",
            "--rho-meas",
            "0.3",
            "--rho-comm",
            "0.3",
            "--seed",
            "11",
        ],
        2,
    ),
    (
        [
            "--pattern",
            "forest",
            "--profile",
            "droplet",
            "--rows",
            "4",
            "--cols",
            "4",
            "--rho-comm",
            "0.3",
            "--seed",
            "5",
        ],
        1,
    ),
    (
        [
            "--pattern",
            "desert",
            "--profile",
            "paper",
            "--rows",
            "7",
            "--cols",
            "3",
            "--rho-meas",
            "0.1",
            "--seed",
            "8",
        ],
        2,
    ),
]


@pytest.mark.parametrize("options, procs", CASES)
def test_swarm_equals_reference_simulator(tmp_path, options, procs):
    swarm, sim = summaries(tmp_path, options, procs)
    for key in sim:
        if key != "elapsed_s":
            assert swarm[key] == sim[key], key
    assert (tmp_path / "run" / "figure.png").stat().st_size > 10_000


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


def test_run_rejects_bad_options_in_one_line(tmp_path):
    out = camo_run("--procs", "0", "--out", str(tmp_path))
    assert (
        out.returncode == 2
        and "--procs" in out.stderr
        and len(out.stderr.strip().splitlines()) == 1
    )


def test_switching_the_background_makes_the_same_swarm_camouflage_again(tmp_path):
    out = camo_run(
        "--pattern", "forest", "--then", "desert", "--procs", "2", "--out", str(tmp_path / "run")
    )
    assert out.returncode == 0, out.stderr[-2000:]
    first = json.loads((tmp_path / "run" / "round_0" / "summary.json").read_text())
    second = json.loads((tmp_path / "run" / "round_1" / "summary.json").read_text())
    assert (first["pattern"], second["pattern"]) == ("vertical", "horizontal"), (
        first["votes"],
        second["votes"],
        second.get("dead"),
        out.stderr[-3000:],
    )
    sim = run_camo("sim", "--pattern", "desert", "--out", str(tmp_path / "sim"))
    assert sim.returncode == 0
    reference = json.loads((tmp_path / "sim" / "summary.json").read_text())
    assert second["final"] == reference["final"] and second["mean_p"] == reference["mean_p"]


def test_two_runs_on_different_domains_do_not_disturb_each_other(tmp_path):
    runs = []
    for k, pattern in enumerate(("forest", "desert")):
        runs.append(
            subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "camo_nodes.launcher",
                    "--pattern",
                    pattern,
                    "--procs",
                    "1",
                    "--domain-id",
                    str(domain()),
                    "--out",
                    str(tmp_path / pattern),
                ],
                cwd=ROOT,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
        )
    for proc in runs:
        _, err = proc.communicate(timeout=240)
        assert proc.returncode == 0, err[-2000:]
    for pattern, expected in (("forest", "vertical"), ("desert", "horizontal")):
        summary = json.loads((tmp_path / pattern / "summary.json").read_text())
        assert summary["pattern"] == expected
        assert sum(summary["votes"].values()) == 64 and "dead" not in summary


def test_swarm_survives_two_robots_killed_during_consensus(tmp_path):
    out_dir = tmp_path / "run"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "camo_nodes.launcher",
            "--pattern",
            "forest",
            "--procs",
            "1",
            "--own-process",
            "2,3",
            "--own-process",
            "5,6",
            "--step-timeout",
            "2",
            "--discovery-timeout",
            "20",
            "--consensus-steps",
            "1000",
            "--domain-id",
            str(domain()),
            "--out",
            str(out_dir),
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    seen = wait_for_line(proc, "consensus 64")  # every robot has voted and is in consensus
    processes = json.loads((out_dir / "processes.json").read_text())
    victims = [int(pid) for pid, cells in processes.items() if cells in ([19], [46])]
    for pid in victims:
        os.kill(pid, 9)
    assert len(victims) == 2, "".join(seen[-30:])
    rest, _ = proc.communicate(timeout=240)
    assert proc.returncode == 0, rest
    summary = json.loads((out_dir / "summary.json").read_text())
    assert sorted(summary["dead"]) == [[2, 3], [5, 6]]
    assert summary["final"][2][3] is None and summary["final"][5][6] is None
    assert summary["pattern"] == "vertical" and summary["votes"]["vertical"] == 62
    assert "2 dead robots [[2, 3], [5, 6]]" in rest
    # Their neighbours each let a deadline pass once, and the run says so.
    assert json.loads((out_dir / "timing.json").read_text())["deadlines"] > 0
    assert "step deadlines passed" in rest


def test_ctrl_c_stops_every_process_and_keeps_what_was_reported(tmp_path):
    out_dir = tmp_path / "run"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "camo_nodes.launcher",
            "--pattern",
            "forest",
            "--procs",
            "2",
            "--consensus-steps",
            "5000",
            "--domain-id",
            str(domain()),
            "--out",
            str(out_dir),
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    wait_for_line(proc, "consensus 64")
    time.sleep(1.0)
    proc.send_signal(2)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "interrupted" in err and "Traceback" not in err
    pids = [int(pid) for pid in json.loads((out_dir / "processes.json").read_text())]
    for pid in pids:
        assert (
            not os.path.exists(f"/proc/{pid}")
            or "zombie" in open(f"/proc/{pid}/status").read().lower()
        )
    summary = json.loads((out_dir / "summary.json").read_text())
    assert "incomplete" in summary and "dead" not in summary
    assert len(summary["consensus_trace"]) >= 2 and summary["votes"]["vertical"] == 64
    assert (out_dir / "figure.png").exists()


def test_bare_exchange_benchmark_measures_a_rate():
    from camo_nodes.bench_ros import bare_rate

    rate = bare_rate(3, 10, 1, domain())
    assert 0 < rate < 10_000


def test_bench_runs_are_longer_on_small_grids_and_reject_absurd_step_counts():
    from camo_nodes.bench_ros import default_steps

    assert (default_steps(8), default_steps(16), default_steps(64)) == (1562, 390, 300)
    out = subprocess.run(
        [sys.executable, "-m", "camo_nodes.bench_ros", "--steps", "5"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2 and "--steps must be in 20..100000" in out.stderr


def test_run_writes_timing(tmp_path):
    out = camo_run("--rows", "4", "--cols", "4", "--procs", "1", "--out", str(tmp_path))
    assert out.returncode == 0, out.stderr[-2000:]
    timing = json.loads((tmp_path / "timing.json").read_text())
    assert timing["steps"] == 45 and timing["steps_per_s"] > 0 and timing["deadlines"] == 0
    assert 0 < timing["startup_s"] <= timing["launch_to_done_s"]


def test_monitor_publishes_the_swarm_pattern_as_an_image(tmp_path):
    import rclpy
    from sensor_msgs.msg import Image

    domain_id = domain()
    # A long consensus, stopped with Ctrl-C once the picture is complete.
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "camo_nodes.launcher",
            "--pattern",
            "forest",
            "--rows",
            "5",
            "--cols",
            "7",
            "--procs",
            "1",
            "--consensus-steps",
            "100000",
            "--domain-id",
            str(domain_id),
            "--out",
            str(tmp_path),
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    images = []
    try:
        with ros_context(domain_id) as context:
            node = rclpy.create_node("pattern_viewer", context=context)
            node.create_subscription(Image, "/swarm/pattern", images.append, 10)
            executor = rclpy.executors.SingleThreadedExecutor(context=context)
            executor.add_node(node)
            deadline = time.monotonic() + 120
            while time.monotonic() < deadline and not any(
                set(bytes(m.data)) <= {0, 255} for m in images
            ):
                executor.spin_once(timeout_sec=0.2)
            executor.shutdown()
            node.destroy_node()
    finally:
        proc.send_signal(2)
        _, err = proc.communicate(timeout=120)
    assert images, f"no /swarm/pattern image; launcher said: {err[-1500:]}"
    complete = [m for m in images if set(bytes(m.data)) <= {0, 255}]
    assert complete, (
        f"{len(images)} images, none with every robot's state; launcher said: {err[-1500:]}"
    )
    last = complete[0]
    assert (last.height, last.width, last.encoding) == (5, 7, "mono8")
    # Every pixel is a robot's state (black on, white off): the forest's initial stripes here.
    assert bytes(last.data) != bytes([last.data[0]]) * 35
    assert proc.returncode == 130


def test_robots_started_alone_with_robot_node_finish_like_the_simulator(tmp_path):
    domain_id = domain()
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
    procs = [
        subprocess.Popen(
            [
                sys.executable,
                "-m",
                "camo_projector.projector_node",
                "--ros-args",
                "-p",
                "pattern:=desert",
            ],
            env=env,
            stderr=subprocess.DEVNULL,
        )
    ]
    for col in range(3):
        procs.append(
            subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "camo_nodes.robot_node",
                    "--ros-args",
                    "-p",
                    "rows:=2",
                    "-p",
                    "cols:=3",
                    "-p",
                    "row:=1",
                    "-p",
                    f"col:={col}",
                    "-p",
                    "seed:=4",
                    "-p",
                    "rho_comm:=0.2",
                ],
                env=env,
            )
        )
    # The other row's robots share one process, as a second machine might.
    procs.append(
        subprocess.Popen(
            [
                sys.executable,
                "-m",
                "camo_nodes.swarm_worker",
                "--params",
                json.dumps({"rows": 2, "cols": 3, "seed": 4, "rho_comm": 0.2}),
                "--cells",
                "0,1,2",
            ],
            env=env,
        )
    )
    try:
        with StatusListener(domain_id) as listener:
            listener.spin_until(lambda: len(listener.final_states()) == 6, timeout=120)
        done = listener.final_states()
    finally:
        for proc in procs:
            proc.send_signal(2)
        for proc in procs:
            proc.wait(timeout=30)
    sim = run_camo(
        "sim",
        "--pattern",
        "desert",
        "--rows",
        "2",
        "--cols",
        "3",
        "--seed",
        "4",
        "--rho-comm",
        "0.2",
        "--out",
        str(tmp_path),
    )
    assert sim.returncode == 0, sim.stderr
    final = json.loads((tmp_path / "summary.json").read_text())["final"]
    assert done == {r * 3 + c: final[r][c] for r in range(2) for c in range(3)}
    assert all(proc.returncode == 0 for proc in procs[1:4])


def test_monitor_keeps_one_record_per_round_whatever_the_number_of_statuses(monkeypatch):
    # A record allocated per status made a long run's monitor fall far behind its robots.
    from camo_core.params import CamoParams
    from camo_msgs.msg import RobotStatus
    from camo_nodes.monitor_node import MonitorNode

    made = count_round_records(monkeypatch)
    with ros_context() as context:
        monitor = MonitorNode(CamoParams(rows=2, cols=2), context=context)
        for round_index in (0, 1):
            for step in range(5):
                for robot in range(4):
                    monitor._on_status(
                        RobotStatus(sender_id=robot, phase=2, step=step, round=round_index)
                    )
        assert monitor.record(1).step.tolist() == [4, 4, 4, 4]
        assert len(made) == 2 and monitor.statuses_heard == 40
        monitor.destroy_node()


def test_background_switch_waits_for_a_matched_projector_and_names_a_missing_one():
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import String

    from camo_nodes.launcher import wait_for_listener

    with ros_context() as context:
        executor = SingleThreadedExecutor(context=context)
        node = rclpy.create_node("launcher_test", context=context)
        executor.add_node(node)
        loader = node.create_publisher(String, "/camo/projector/load", 10)
        with pytest.raises(
            RuntimeError, match="no projector listens on /camo/projector/load after 0.5 s"
        ):
            wait_for_listener(executor, loader, "projector", stop=False, limit=0.5)
        node.create_subscription(String, "/camo/projector/load", lambda msg: None, 10)
        wait_for_listener(executor, loader, "projector", stop=False, limit=10.0)
        assert loader.get_subscription_count() == 1
        executor.shutdown()
        node.destroy_node()


def test_a_deadline_passes_only_on_the_tick_after_discounting_a_stall_of_the_robots_process():
    from camo_core.params import CamoParams
    from camo_nodes.robot_node import DISCOVERY, RobotNode

    with ros_context() as context:
        robot = RobotNode(
            CamoParams(rows=1, cols=2),
            0,
            0,
            step_timeout=2.0,
            discovery_timeout=2.0,
            context=context,
        )  # waits for its one neighbour's hello
        # The process stalled for 10 s; a message is handled before the robot's tick.
        robot.wait_started -= 10.0
        robot.last_tick -= 10.0
        robot._advance()
        assert (robot.phase, robot.deadlines) == (DISCOVERY, 0)
        robot._on_timer()  # sees the stall and discounts it
        assert (robot.phase, robot.deadlines) == (DISCOVERY, 0)
        robot.wait_started -= 3.0  # now the neighbour really is late
        robot._on_timer()
        assert robot.phase != DISCOVERY and robot.deadlines == 1 and robot.silent
        robot.destroy_node()
