"""`./camo sweep --driver ros`: every trial a whole swarm of robot nodes (two at once, in one
domain, kept apart by their run ids), in the same table as the simulator's trials, and equal
to ./camo sim bit for bit."""

import os
import subprocess
import sys

import pytest
from support import CLUSTER, ROOT, domain, sweep_table


@pytest.mark.slow(CLUSTER)
def test_swarm_trials_fill_the_table_and_equal_the_simulator(tmp_path):
    args = ["--axis", "rho_comm=0,0.2", "--set", "rows=3", "--set", "cols=3", "--trials", "2"]
    done = subprocess.run(
        [sys.executable, "-m", "camo_sweep.cli", *args, "--driver", "ros", "--workers", "2"]
        + ["--ros-timeout", "120", "--quiet", "--out", str(tmp_path / "ros")],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=ROOT,
        env={**os.environ, "ROS_DOMAIN_ID": str(domain())},
    )
    assert done.returncode == 0, done.stderr
    rows = sweep_table(tmp_path / "ros")
    assert len(rows) == 4 and all(r["status"] == "ok" for r in rows), rows
    assert all(r["driver"] == "ros" and r["equals_sim"] is True for r in rows)
    sim = subprocess.run(
        [sys.executable, "-m", "camo_sweep.cli", *args, "--workers", "1", "--quiet"]
        + ["--out", str(tmp_path / "sim")],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
    )
    assert sim.returncode == 0, sim.stderr
    results = ("seed", "chosen_pattern", "diff_cells", "votes_vertical", "mean_p_vertical")
    by_seed = lambda table: sorted(tuple(r[k] for k in results) for r in table)  # noqa: E731
    assert by_seed(rows) == by_seed(sweep_table(tmp_path / "sim"))


@pytest.mark.slow(CLUSTER)
def test_a_trial_that_failed_runs_again_and_leaves_one_row(tmp_path):
    out = tmp_path / "s"
    args = ["--axis", "rho_comm=0.1", "--set", "rows=2", "--set", "cols=2", "--driver", "ros"]
    args += ["--workers", "1", "--quiet", "--out", str(out)]
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain())}

    def run(timeout: str) -> subprocess.CompletedProcess:
        return subprocess.run(
            [sys.executable, "-m", "camo_sweep.cli", *args, "--ros-timeout", timeout],
            capture_output=True,
            text=True,
            timeout=300,
            cwd=ROOT,
            env=env,
        )

    short = run("0.2")  # too short for any swarm: the trial fails, the sweep does not
    assert short.returncode == 0 and "(1 failed)" in short.stdout, short.stderr
    (row,) = sweep_table(out)
    assert row["status"] == "error: the swarm did not finish within 0.2 s"
    again = run("120")
    assert again.returncode == 0 and "0 already in the table, 1 run (0 failed)" in again.stdout
    (row,) = sweep_table(out)
    assert row["status"] == "ok" and row["equals_sim"] is True
    import pyarrow.dataset as ds

    assert ds.dataset(str(out / "trials"), format="parquet").count_rows() == 1
