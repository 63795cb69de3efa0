"""`./camo sweep`: the same table whatever the engine, every row reproduced by ./camo sim,
resumption after Ctrl-C without duplicates, failed trials as rows, one-line errors that write
nothing."""

import os
import re
import shlex
import shutil
import signal
import subprocess
import sys

import cv2
import pyarrow.dataset as ds
import pytest
from support import (
    CLUSTER,
    PROCESS,
    ROOT,
    SWARM,
    bad_value_outcomes,
    finished,
    run_camo,
    sweep,
    validated,
    value_options,
)
from support import sweep_table as table

from camo_core.algorithm.backgrounds import background
from camo_core.algorithm.sensing import sense_image
from camo_core.algorithm.simulator import simulate
from camo_core.cli.options import params_from
from camo_sweep import cli
from camo_sweep.spec import sim_parser


@pytest.fixture(scope="module")
def two_images(tmp_path_factory):
    folder = tmp_path_factory.mktemp("images")
    paths = []
    for name in ("forest", "desert"):
        path = folder / f"{name}.png"
        cv2.imwrite(str(path), background(name))
        paths.append(str(path))
    return paths


@pytest.fixture(scope="module")
def in_process(tmp_path_factory, two_images):
    out = tmp_path_factory.mktemp("sweep") / "one"
    args = ["--axis", f"image={','.join(two_images)}", "--axis", "rho_comm=0,0.25,0.5"]
    done = sweep(*args, "--trials", "20", "--workers", "1", "--out", str(out))
    assert done.returncode == 0, done.stderr
    return args, out, done


@pytest.mark.slow(CLUSTER)
def test_two_workers_over_tcp_give_the_table_of_one_process(in_process, tmp_path):
    args, one, _ = in_process
    two = tmp_path / "two"
    done = sweep(*args, "--trials", "20", "--workers", "2", "--batch-s", "0.01", "--out", str(two))
    assert done.returncode == 0, done.stderr
    assert "LocalCluster of 2 workers" in done.stdout
    rows = table(one)
    assert len(rows) == 2 * 3 * 20 and len({r["trial_id"] for r in rows}) == len(rows)
    assert rows == table(two)
    assert all(r["status"] == "ok" for r in rows)
    # The errors move the pattern: some trials at 0.5 differ from the error-free run.
    assert any(r["diff_cells"] > 0 for r in rows if r["rho_comm"] == 0.5)
    assert all(r["diff_cells"] == 0 and r["correct"] for r in rows if r["rho_comm"] == 0)


@pytest.mark.slow(PROCESS)
def test_every_row_is_reproduced_by_camo_sim(in_process, tmp_path):
    _, one, _ = in_process
    rows = table(one)
    parser = sim_parser()
    for row in rows:  # each row's command line, parsed as ./camo sim parses it, and run
        args = parser.parse_args([*shlex.split(row["sim_args"]), "--seed", str(row["seed"])])
        params = params_from(args)
        image = cv2.imread(args.image)
        result = simulate(params, sense_image(image, params.rows, params.cols, params.profile))
        assert result.majority_pattern == row["chosen_pattern"]
        assert result.selection_counts["vertical"] == row["votes_vertical"]
    # And ./camo sim itself, for a row with errors.
    row = next(r for r in rows if r["rho_comm"] == 0.5 and r["diff_cells"] > 0)
    out = tmp_path / "sim"
    done = run_camo(
        "sim", *shlex.split(row["sim_args"]), "--seed", str(row["seed"]), "--out", str(out)
    )
    assert done.returncode == 0, done.stderr
    import json

    summary = json.loads((out / "summary.json").read_text())
    assert summary["pattern"] == row["chosen_pattern"]
    assert [summary["votes"][k] for k in ("horizontal", "vertical", "mottled")] == [
        row["votes_horizontal"],
        row["votes_vertical"],
        row["votes_mottled"],
    ]
    assert summary["mean_p"] == [
        row["mean_p_horizontal"],
        row["mean_p_vertical"],
        row["mean_p_mottled"],
    ]


@pytest.mark.slow(CLUSTER)
def test_the_same_command_again_runs_nothing_and_duplicates_nothing(in_process, tmp_path):
    args, done_once, _ = in_process
    one = tmp_path / "one"  # a copy: the module's other tests read the table of 120 rows
    shutil.copytree(done_once, one)
    before = table(one)
    again = sweep(*args, "--trials", "20", "--workers", "1", "--out", str(one))
    assert again.returncode == 0, again.stderr
    assert "120 already in the table, 0 run" in again.stdout
    assert table(one) == before
    # More replicates add only the new ones.
    more = sweep(*args, "--trials", "21", "--workers", "1", "--out", str(one), "--quiet")
    assert more.returncode == 0 and "120 already in the table, 6 run" in more.stdout
    rows = table(one)
    assert len(rows) == 126 and [r for r in rows if r["replicate"] < 20] == before


@pytest.mark.slow(SWARM)
def test_ctrl_c_mid_sweep_then_the_same_command_gives_the_same_table(tmp_path):
    args = ["--axis", "rho_comm=0:0.5:0.05", "--set", "pattern=forest", "--trials", "300"]
    args += ["--workers", "1", "--batch-s", "0.02"]
    whole = sweep(*args, "--out", str(tmp_path / "whole"), "--quiet")
    assert whole.returncode == 0, whole.stderr
    out = tmp_path / "stopped"
    proc = subprocess.Popen(
        [sys.executable, "-m", "camo_sweep.cli", *args, "--out", str(out)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # As a script's background job starts it: with SIGINT ignored, which Python keeps.
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN),
    )
    # Ctrl-C once the progress line says a tenth is done: read as it is printed, not polled
    # from the table's files (a poll starved on a busy machine saw the sweep end first).
    said = []
    for line in proc.stderr:
        said.append(line)
        shown = re.search(r" (\d+)% ", line)
        if shown and 10 <= int(shown.group(1)) < 100:
            break
    proc.send_signal(signal.SIGINT)
    _, rest = finished(proc, 60)
    stderr = "".join(said) + rest
    assert proc.returncode == 130, stderr
    assert "the same command goes on from there" in stderr and "Traceback" not in stderr
    partial = ds.dataset(str(out / "trials"), format="parquet").count_rows()
    assert 0 < partial < 3300
    again = sweep(*args, "--out", str(out), "--quiet")
    assert again.returncode == 0, again.stderr
    assert f"{partial} already in the table" in again.stdout
    raw = ds.dataset(str(out / "trials"), format="parquet").to_table().column("trial_id")
    assert len(raw) == len(set(raw.to_pylist())) == 3300  # no trial twice, in any part
    assert table(out) == table(tmp_path / "whole")


@pytest.mark.slow(CLUSTER)
def test_a_table_part_that_is_not_a_sweeps_is_named_in_one_line(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    out = tmp_path / "s"
    done = sweep("--axis", "rho_comm=0,0.1", "--workers", "1", "--quiet", "--out", str(out))
    assert done.returncode == 0, done.stderr
    stranger = out / "trials" / "part-000.parquet"
    pq.write_table(pa.table({"trial_id": ["x"], "rho_comm": [0.5]}), stranger)
    for again in (
        sweep("--axis", "rho_comm=0,0.1", "--workers", "1", "--out", str(out)),
        sweep("plot", str(out), "--x", "rho_comm"),
    ):
        assert again.returncode == 2, again.stderr
        assert again.stderr.strip() == (
            f"camo sweep: error: {stranger} is not a part of a sweep table (no status column)"
        )


@pytest.mark.slow(CLUSTER)
@pytest.mark.parametrize(
    "args, said",
    [
        (["--axis", "rho_com=0,0.1"], "unknown option or axis 'rho_com'"),
        (["--axis", "rho_comm="], "axis rho_comm is empty"),
        (["--axis", "rho_comm=0.1", "--sett", "rows=4"], "unrecognized arguments: --sett"),
        (["--axis", "rho_comm=0.1", "--scheduler", "tcp://127.0.0.1:9"], "cannot reach the Dask"),
        (["BAD_YAML"], "is not YAML"),
        (["--axis", "rho_comm=0.1", "--print-job-script"], "--print-job-script needs --slurm"),
        (["--axis", "rows=4,0"], "rows must be an integer in 1..8192 (got 0)"),
        (["--axis", "rho_comm=0,2"], "rho_comm must be a number in [0, 1]"),
        (["--axis", "image=missing.png"], "cannot read image missing.png: not found"),
        (["--axis", "rho_comm=0.1", "--scheduler", "tcp://127.0.0.1:notaport"], "cannot reach"),
        (["--axis", "rho_comm=0.1", "--batch-s", "inf"], "--batch-s: invalid float value"),
        (["--axis", "rho_comm=0.1", "--slurm"], "needs SLURM's sbatch"),
        (["--axis", "rows=4", "--ros-timeout", "9"], "--ros-timeout is for --driver ros (this"),
    ],
)
def test_bad_input_is_one_line_exit_2_and_writes_nothing(tmp_path, args, said):
    out = tmp_path / "s"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    bad = tmp_path / "bad.yaml"
    bad.write_text("axes: {rho_comm: [0, 0.1\n")
    args = [str(bad) if a == "BAD_YAML" else a for a in args]
    done = sweep(*args, "--out", str(tmp_path / "new"), timeout=120)
    assert done.returncode == 2, done.stderr
    assert said in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert not (tmp_path / "new").exists()
    # A folder that is not a sweep's is refused, and left as it was.
    other = sweep("--axis", "rho_comm=0.1", "--workers", "1", "--out", str(out))
    assert other.returncode == 2 and "not a sweep's folder" in other.stderr
    assert os.listdir(out) == ["keep.txt"]


@pytest.mark.slow(CLUSTER)
def test_a_folder_of_another_sweep_is_refused(in_process):
    _, one, _ = in_process
    parts = sorted(p.name for p in (one / "trials").iterdir())
    done = sweep("--axis", "rho_comm=0.1", "--workers", "1", "--out", str(one))
    assert done.returncode == 2 and "holds another sweep" in done.stderr
    assert sorted(p.name for p in (one / "trials").iterdir()) == parts


@pytest.mark.slow(CLUSTER)
def test_slurm_prints_a_job_script_that_starts_a_dask_worker(tmp_path):
    options = ["--slurm-queue", "short", "--slurm-cores", "4", "--slurm-walltime", "00:30:00"]
    done = subprocess.run(
        [sys.executable, "-m", "camo_sweep.cli", "--slurm", *options, "--print-job-script"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr
    script = done.stdout
    assert script.startswith("#!/usr/bin/env bash") and "#SBATCH -p short" in script
    assert "#SBATCH -t 00:30:00" in script and "distributed.cli.dask_worker" in script
    assert "--nthreads 1" in script and "--nworkers 4" in script and "ros=1" in script
    assert f"source {ROOT}/ros2_ws/install/setup.bash" in script
    assert os.listdir(tmp_path) == []  # nothing written, nothing submitted
    missing = sweep("--axis", "rho_comm=0.1", "--workers", "1")
    assert missing.returncode == 2 and "required: --out" in missing.stderr


@pytest.mark.slow(CLUSTER)
def test_an_axis_of_numbers_and_auto_is_written_as_text(tmp_path):
    out = tmp_path / "s"
    done = sweep(
        "--axis", "consensus_steps=10,auto", "--workers", "1", "--quiet", "--out", str(out)
    )
    assert done.returncode == 0, done.stderr
    rows = table(out)
    assert sorted(r["consensus_steps"] for r in rows) == ["10", "auto"]
    assert {r["sim_args"] for r in rows} == {"--consensus-steps 10", "--consensus-steps auto"}


@pytest.mark.slow(PROCESS)
def test_a_sweep_refuses_a_layout_it_would_not_run(tmp_path):
    out = sweep("--axis", "rho_comm=0,0.1", "--set", "layout=hex", "--out", str(tmp_path / "s"))
    assert out.returncode == 2, out.stderr
    assert out.stderr.strip().endswith(
        "sweeps run on the grid: --layout is for ./camo sim and run, for now"
    )


# ---- every option with bad values (issue 27) -------------------------------------------------


@pytest.mark.parametrize("option", value_options(cli.build_parser()))
def test_every_option_of_sweep_with_a_bad_value_is_one_line_and_exit_2(
    option, tmp_path, monkeypatch, capsys
):
    # Only the command line and the spec are checked: planning (its first trial) is replaced.
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(cli, "plan", validated)
    argv = ["--axis", "rho_comm=0,0.1"]
    if option != "--out":
        argv += ["--out", str(tmp_path / "out")]
    assert bad_value_outcomes(cli.main, argv, option, capsys, cli.build_parser()) == []


@pytest.mark.parametrize("value", ["", "nan", "-1", "1e300", "/tmp/" + "p" * 5000])
def test_a_bad_sweep_file_argument_is_one_line_and_exit_2(value, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(cli, "plan", validated)
    assert cli.main([value, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("camo sweep: error: "), err


@pytest.mark.parametrize("trials", ["1_000", "\uff11\uff10\uff10"])
def test_bench_sweep_reads_trials_as_ascii_digits_in_one_line(trials, capsys):
    from camo_sweep import bench

    assert bench.main(["--trials", trials]) == 2
    err = capsys.readouterr().err
    assert err.startswith("camo bench sweep: error: argument --trials: invalid int value")
    assert len(err.strip().splitlines()) == 1


def test_a_trials_reference_leaves_out_every_parameter_declared_as_noise(monkeypatch):
    # A trial is compared with its run without errors: what is declared noise=True (and only
    # that) is left out of the reference's options, whatever its name.
    from camo_core.algorithm.params import CamoParams
    from camo_core.schema import declared
    from camo_sweep import trials

    options = {"rows": 8, "cols": 8, "seed": 3, "rho_meas": 0.1, "rho_comm": 0.2}
    assert trials.reference_options(options) == {"rows": 8, "cols": 8, "seed": 3}
    noisy = {name for name, d in declared(CamoParams).items() if d.spec.noise}
    assert noisy == {"rho_meas", "rho_comm"}
    monkeypatch.setattr(trials, "NOISE", ("seed",))  # as if seed were declared noise
    assert trials.reference_options(options) == {k: v for k, v in options.items() if k != "seed"}


def test_the_ros_drivers_options_go_with_the_ros_driver_only():
    from camo_core.exceptions import UsageError
    from camo_sweep.cli import build_parser, check_driver_options

    parser = build_parser()
    both = parser.parse_args(["--ros-per-worker", "2", "--ros-timeout", "9"])
    check_driver_options(parser, both, "ros")  # the driver given here or by the sweep's file
    check_driver_options(parser, parser.parse_args([]), "sim")
    with pytest.raises(UsageError, match=r"^--ros-per-worker and --ros-timeout are for --dri"):
        check_driver_options(parser, both, "sim")
