"""`camo bench ros`: the bare rclpy exchange it compares against, and its options; `camo bench
dynamic`, a continuous swarm against --then switches."""

import signal
import subprocess
import sys
import time

import pytest
from support import COMPUTE, PROCESS, ROOT, SWARM, TIMED, domain


@pytest.mark.slow(SWARM)
def test_a_comparison_measures_the_bare_exchange_and_the_swarm_with_and_without_loss(tmp_path):
    import json

    from camo_bringup.bench import compare, format_loss

    row = compare(4, 2, domain(), tmp_path, 30, 1, loss=0.2)
    runs = ("4_0", "4_0_loss")
    assert 0 < row["bare_setup_s"] < row["bare_wall_s"] and 0 < row["bare_steps_per_s"] < 1e5
    assert row["rate_ratio"] == row["swarm_steps_per_s"] / row["bare_steps_per_s"]
    assert row["loss_ratio"] == row["lossy_steps_per_s"] / row["swarm_steps_per_s"] > 0
    summaries = [json.loads((tmp_path / run / "summary.json").read_text()) for run in runs]
    for summary in summaries:
        summary.pop("elapsed_s")
    assert summaries[0] != summaries[1]  # the lossy run lost messages
    loss_free = {key: value for key, value in row.items() if key != "loss"}
    table = format_loss([row, loss_free]).splitlines()  # rows measured without loss: none
    assert len(table) == 3 and table[2].split()[:3] == ["4x4", "30", "0.20"]


@pytest.mark.slow(COMPUTE)
def test_the_packed_bare_exchange_crosses_processes_in_arrays():
    from camo_bringup.bare_exchange import bare_exchange

    # It finishes only once each process has had every remote vote its robots need, unpacked
    # from the arrays.
    # A minute's budget: a process that hangs fails the test in two, its stacks on stderr.
    packed = bare_exchange(4, 20, 2, domain(), packed=True, budget=60)
    assert 0 < packed["setup_s"] < packed["wall_s"] and 0 < packed["steps_per_s"] < 100_000


@pytest.mark.slow(PROCESS)
def test_a_bare_process_that_hangs_is_one_line_with_its_stacks_and_none_is_left(capfd):
    from camo_bringup.bare_exchange import worker_reports

    # One process reports and ends; one hangs, as a process stuck in DDS would.
    code = (
        "import sys, time; from camo_core.shutdown import stacks_on_faults; stacks_on_faults(); "
        "print('{}', flush=True); time.sleep(float(sys.argv[1]))"
    )
    workers = [
        subprocess.Popen([sys.executable, "-c", code, wait], stdout=subprocess.PIPE, text=True)
        for wait in ("0", "600")
    ]
    # Under load either may take seconds to start: the one that ends has ended, and the one that
    # hangs has its stacks' handler, before the 3 s begin.
    workers[0].wait(timeout=120)
    assert workers[1].stdout.readline().strip() == "{}"
    started = time.monotonic()
    with pytest.raises(RuntimeError) as failed:
        worker_reports(workers, "the bare exchange at 4x4", 3.0)
    assert time.monotonic() - started < 20
    assert str(failed.value) == (
        "the bare exchange at 4x4: process 1 did not end in 3 s (its threads' stacks are on "
        "stderr)"
    )
    assert [w.returncode for w in workers] == [0, -signal.SIGKILL]  # none is left
    assert 'File "<string>", line 1 in <module>' in capfd.readouterr().err  # the hung one's


def test_a_bare_process_that_fails_ends_the_others_at_once_in_one_line():
    from camo_bringup.bare_exchange import worker_reports

    # Process 0 would wait for its failed peer for its whole budget: it is not waited for.
    workers = [
        subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
        for code in ("import time; time.sleep(600)", "exit(3)")
    ]
    started = time.monotonic()
    with pytest.raises(RuntimeError, match=r"^the bare exchange at 4x4: process 1 failed \(exit"):
        worker_reports(workers, "the bare exchange at 4x4", 300.0)
    assert time.monotonic() - started < 60
    assert workers[0].returncode in (-signal.SIGUSR1, -signal.SIGKILL)  # ended, not left


def test_bench_runs_are_longer_on_small_grids_and_reject_absurd_step_counts():
    from camo_bringup.bench import default_steps

    assert (default_steps(8), default_steps(16), default_steps(64)) == (1562, 390, 300)
    out = subprocess.run(
        [sys.executable, "-m", "camo_bringup.bench", "--steps", "5"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2 and "--steps must be in 20..100000" in out.stderr


@pytest.mark.slow(SWARM)
def test_the_cost_of_a_live_view_with_no_client_is_measured_against_plain_runs(tmp_path):
    from camo_bringup.bench import added_cost

    row = added_cost(3, 1, domain(), tmp_path, 1, lambda folder: ["--foxglove", "0"])
    assert row["robots"] == "3x3" and row["plain_s"] > 0 and row["added_s"] > 0
    assert row["ratio"] == row["added_s"] / row["plain_s"]
    assert (tmp_path / "added_0" / "summary.json").exists()


@pytest.mark.slow(SWARM)
def test_a_large_run_is_timed_weighed_per_process_and_compared_with_the_simulator(tmp_path):
    """bench ros's large runs, on a small grid: the swarm's times, each process's peak memory
    (launcher, projector, workers) and whether it equals ./camo sim, in the table too."""
    from camo_bringup.bench import format_large, large_run

    # With loss and sensor noise, as bench ros's lossy large runs.
    row = large_run(6, domain(), tmp_path, ["--rho-comm", "0.1", "--rho-meas", "0.05"])
    assert row["robots"] == "6x6" and row["equals_sim"] is True and row["deadlines"] == 0
    assert row["links"] == "0.1 0.05"
    assert 0 < row["setup_s"] < row["wall_s"] and row["steps_per_s"] > 0
    processes = row["peak_mib"]["processes"]
    assert {"launcher", "projector_node", "worker 1"} <= set(processes)
    assert all(mib > 10 for mib in processes.values())  # a Python process with rclpy, at least
    assert row["peak_mib"]["all"] >= sum(processes.values()) - 1
    table = format_large([row, {**row, "equals_sim": False}]).splitlines()
    assert table[1].split()[-1] == "yes" and table[2].split()[-1] == "NO"


def test_grid_sides_take_a_list_where_0_or_nothing_means_none():
    import argparse

    from camo_bringup.bench import grid_sides

    assert grid_sides("16,32") == [16, 32] and grid_sides("0") == grid_sides("") == []
    for bad in ("x", "300", "-8"):
        with pytest.raises(argparse.ArgumentTypeError):
            grid_sides(bad)


@pytest.mark.parametrize(
    "module, work", [("bench", "compare"), ("soak", "soak"), ("bench_dynamic", "measure")]
)
def test_every_option_of_bench_ros_and_soak_with_a_bad_value_is_one_line(
    module, work, tmp_path, monkeypatch, capsys
):
    # Only the command line is checked: the runs themselves are replaced.
    import importlib

    from support import bad_value_outcomes, parser_of_main, validated, value_options

    command = importlib.import_module(f"camo_bringup.{module}")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(command, work, validated)
    parser = parser_of_main(command.main, [], monkeypatch)
    options = value_options(parser)
    assert len(options) >= 5
    problems = [
        p for o in options for p in bad_value_outcomes(command.main, [], o, capsys, parser)
    ]
    assert problems == []


@pytest.mark.slow(SWARM)
@pytest.mark.alone(TIMED)
def test_bench_dynamic_times_a_change_against_a_switch_and_counts_false_rounds(tmp_path):
    import json

    out = subprocess.run(
        [sys.executable, "-m", "camo_bringup.bench_dynamic", "--sides", "8", "--changes", "2",
         "--static-s", "10", "--json", "--out", str(tmp_path / "bench")],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr[-2000:]
    figures = json.loads(out.stdout)
    (row,) = figures["following"]
    assert row["continuous"]["changes"] == row["then"]["changes"] == 2
    assert 0 < row["then"]["median_s"] < row["continuous"]["median_s"] < 5  # noticing costs
    assert row["continuous"]["median_s"] <= row["continuous"]["max_s"] < 5
    rounds = row["rounds"]  # one a change, on its frame, each equal to the simulator
    assert rounds["frames"] == [0, 1, 2] and rounds["like_sim"] == 3, rounds
    assert not (rounds["missed"] or rounds["other"] or rounds["incomplete"])
    assert "3 rounds, 3 equal to ./camo sim" in out.stderr
    assert figures["static"]["rounds"] == 1 and figures["static"]["per_minute"] == 0


def test_a_benchmark_runs_its_swarms_in_the_domain_the_environment_sets():
    """ROS_DOMAIN_ID, where set (a test's own domain): a benchmark picking one of its own could
    share it with another run (the docs' bench dynamic did, with a test's); unset, one away
    from domain 0; not a domain, one line."""
    from camo_core.exceptions import UsageError
    from camo_nodes.topics.startup import bench_domain

    assert bench_domain(140, 40, {"ROS_DOMAIN_ID": " 7 "}) == 7
    assert 140 <= bench_domain(140, 40, {}) < 180
    with pytest.raises(UsageError, match=r"ROS_DOMAIN_ID must be an integer in 0\.\.232"):
        bench_domain(140, 40, {"ROS_DOMAIN_ID": "300"})


@pytest.mark.parametrize("scope", ["global", "local"])
def test_bench_dynamic_whose_run_wrote_no_round_says_what_the_run_said_last(
    scope, tmp_path, monkeypatch, capsys
):
    """A swarm that wrote no round (a loaded machine, a run cut short) is one line with what
    the run said last, not a traceback."""
    from camo_bringup import bench_dynamic

    said = "camo run: 0 rounds done; watching\ncamo run: --duration 13.8 s is up\n"
    monkeypatch.setattr(
        bench_dynamic,
        "launch",
        lambda argv, domain, timeout: subprocess.CompletedProcess(argv, 0, "", said),
    )
    argv = ["--sides", "8", "--changes", "1", "--scope", scope, "--out", str(tmp_path / "b")]
    assert bench_dynamic.main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == (
        "camo bench dynamic: error: the continuous run wrote no round: camo run: 0 rounds "
        "done; watching / camo run: --duration 13.8 s is up"
    )
