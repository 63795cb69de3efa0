"""The tests' warm process (tests/warm_cli.py): a command run in a child of it says, writes and
exits as a fresh `python -m camo_core.cli` process does."""

import json
import subprocess
import sys

import pytest
import warm_cli
from support import PROCESS, ROOT, run_camo, run_whole


def fresh(*args: str) -> subprocess.CompletedProcess:
    return run_whole([sys.executable, "-m", "camo_core.cli", *args], 120)


@pytest.mark.slow(PROCESS)
def test_a_sim_in_the_warm_process_writes_and_says_what_a_fresh_process_does(tmp_path):
    options = ["sim", "--rows", "6", "--cols", "6", "--seed", "3", "--rho-comm", "0.1"]
    warm = run_camo(*options, "--out", str(tmp_path / "warm"))
    new = fresh(*options, "--out", str(tmp_path / "fresh"))
    assert warm.returncode == new.returncode == 0, warm.stderr
    assert warm.args[:3] == ["python", "-m", "camo_core.cli"]  # it did run in the warm process
    summaries = [
        json.loads((tmp_path / f / "summary.json").read_text()) for f in ("warm", "fresh")
    ]
    for summary in summaries:
        summary.pop("elapsed_s")
    assert summaries[0] == summaries[1]
    for name in ("figure.png", "run.gif"):
        assert (tmp_path / "warm" / name).stat().st_size > 0
    said = [done.stdout.split("; wrote")[0] for done in (warm, new)]
    assert said[0] == said[1] and said[0].startswith("pattern: ")


@pytest.mark.slow(PROCESS)
def test_an_error_in_the_warm_process_is_the_fresh_processs_line_and_exit_code(tmp_path):
    for args in (["sim", "--rows", "0"], ["no-such-command"], ["sim", "--image", str(tmp_path)]):
        warm, new = run_camo(*args), fresh(*args)
        assert (warm.returncode, warm.stdout, warm.stderr) == (
            new.returncode,
            new.stdout,
            new.stderr,
        )
        assert warm.returncode == 2 and warm.args[0] == "python"


def test_a_command_in_another_environment_runs_as_a_fresh_process(monkeypatch):
    monkeypatch.setenv("NUMBA_NUM_THREADS", "1")  # read as numba is imported
    assert warm_cli.run(["--help"], ROOT) is None


@pytest.mark.slow(PROCESS)
def test_a_command_that_outlives_its_timeout_is_stopped_and_said(tmp_path):
    with pytest.raises(AssertionError, match=r"did not end in 0\.5 s"):
        run_camo("sim", "--rows", "64", "--cols", "64", "--out", str(tmp_path / "s"), timeout=0.5)
    done = run_camo("sim", "--rows", "4", "--cols", "4", "--out", str(tmp_path / "next"))
    assert done.returncode == 0, done.stderr  # the warm process goes on serving
