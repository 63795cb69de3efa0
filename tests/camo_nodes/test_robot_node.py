"""Robots started alone with `robot_node`: one-line errors, and a swarm of them equals the
simulator."""

import json
import os
import subprocess
import sys

from support import StatusListener, domain, run_camo


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
                "camo_nodes.worker",
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
