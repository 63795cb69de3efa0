"""A run under attack: a stranger in its domain publishes malformed and forged copies of the
robots' messages, statuses, hosts, background and parameters on the run's own topics. The run
refuses them, counts them, says so, and still computes what the simulator does."""

import json
import os
import subprocess
import sys

import pytest
from support import (
    ROOT,
    SWARM,
    assert_like_sim,
    domain,
    finished,
    run_camo,
    start_run,
    wait_for_line,
)

from camo_core.swarm.keys import KEY_FILE_ENV, NO_TAG, new_key_file
from camo_core.swarm.run_setup import RunSetup
from camo_msgs.msg import Host
from camo_nodes.topics.runs import setup_from
from camo_nodes.trust import BackgroundCheck, Hosts, Rejections, merged

OPTIONS = ["--pattern", "forest", "--rows", "6", "--cols", "6", "--seed", "2"]
# 400 steps (a few seconds): the stranger's writers must be matched by the run's readers before
# it ends; with 120 a run once ended first on a loaded machine and refused nothing.
OPTIONS += ["--rho-comm", "0.1", "--consensus-steps", "400"]
SETUP = {
    "run": "r",
    "params": {"rows": 6, "cols": 6},
    "backgrounds": ["built-in forest"],
    "step_timeout": 30.0,
    "discovery_timeout": 60.0,
    "tiles": [[0, 17], [18, 35]],
}


@pytest.mark.slow(SWARM)
@pytest.mark.parametrize("insider", [False, True], ids=["stranger", "insider_with_the_key"])
def test_a_run_under_attack_equals_the_simulator_and_reports_what_it_refused(tmp_path, insider):
    """A stranger without the run's key: every message it writes is refused for its tag. One
    that has the key file (what keys cannot stop) is refused message by message, by what the
    run checks besides: its sender's host, its columns, the run's backgrounds."""
    key = str(new_key_file(tmp_path / "run.key").path)
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain())}
    env.pop(KEY_FILE_ENV, None)
    if insider:
        env[KEY_FILE_ENV] = key
    # The stranger is there first, waiting for the run's launcher: a run of 120 steps can end
    # before a stranger started after it is heard on a loaded machine (it did, at -n 3).
    attacker = subprocess.Popen(
        [sys.executable, str(ROOT / "tests" / "attacker.py"), "attacked", "60", "0-17", "18-35"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        run = start_run(
            *OPTIONS,
            *["--procs", "2", "--run-id", "attacked", "--out", str(tmp_path / "run")],
            *["--key-file", key],
            domain_id=env["ROS_DOMAIN_ID"],
        )
        wait_for_line(attacker, "ready")
        out, err = finished(run, 240)
    finally:
        attacker.terminate()
        stranger, _ = finished(attacker, 30)
    assert run.returncode == 0, err[-3000:]
    attack = json.loads(stranger)
    assert attack["topics"] >= 20 and attack["sent"] > 1000, attack
    sim = run_camo("sim", *OPTIONS, "--out", str(tmp_path / "sim"))
    assert sim.returncode == 0, sim.stderr
    ran = assert_like_sim(tmp_path / "run", tmp_path / "sim", attacked=True)
    refused = ran["rejected_messages"]
    assert refused["total"] > 0 and sum(refused["by_reason"].values()) == refused["total"]
    assert "received messages refused" in out
    if not insider:
        assert set(refused["by_reason"]) == {NO_TAG}, refused
    else:
        assert "not from the process hosting its sender" in refused["by_reason"]
        assert "columns of different lengths" in refused["by_reason"]  # refused whole, once
        assert "a background that is not the run's next one" in refused["by_reason"]
    # Its writer on the run's recorded topic never reports as a recorder: the run's end does
    # not wait hold's minute for it (it did: 54 s from the last robot done to the results).
    timing = json.loads((tmp_path / "run" / "timing.json").read_text())
    assert timing["done_to_written_s"] < 30, timing


# ---- the pieces, alone ----------------------------------------------------------------------


class Log:
    def __init__(self) -> None:
        self.lines: list[str] = []

    def warning(self, line: str) -> None:
        self.lines.append(line)


A, B = bytes(range(16)), bytes(range(1, 17))  # two writers in two processes


def test_rejections_count_every_message_and_log_each_process_once():
    log = Log()
    rejections = Rejections(log)
    for _ in range(3):
        rejections.refuse("vote out of range", A, "robot 4")
    rejections.refuse("step out of range", A[:12] + b"\x00\x00\x00\x09", "robot 5")
    rejections.refuse("vote out of range", B)
    assert rejections.as_dict() == {
        "total": 5,
        "by_reason": {"step out of range": 1, "vote out of range": 4},
    }
    assert len(log.lines) == 2 and "robot 4" in log.lines[0] and A[:12].hex() in log.lines[0]
    assert merged(rejections.as_dict(), {"by_reason": {"step out of range": 2}})["total"] == 7


def test_a_tile_belongs_to_the_process_that_announced_it_first_and_only_tiles_of_the_run():
    rejections = Rejections(Log())
    hosts = Hosts(36, rejections, RunSetup.from_dict(SETUP))
    assert hosts.learn(Host(name="w1", first=[0], last=[17]), A) == [(0, 17)]
    assert hosts.learn(Host(name="x", first=[0], last=[17]), B) == []
    assert hosts.learn(Host(name="x", first=[0], last=[35]), B) == []
    assert hosts.learn(Host(name="x", first=[30], last=[40]), B) == []
    assert hosts.speaks_for(A[:12] + b"\xff" * 4, 17) and not hosts.speaks_for(B, 17)
    assert not hosts.speaks_for(A, 18)  # nobody hosts 18-35 yet
    assert rejections.counts == {
        "tile already hosted by another process": 1,
        "host announcement of a tile not in the run": 1,
        "host announcement out of range": 1,
    }


def test_a_tile_announced_by_a_process_not_of_the_run_is_a_conflict_first_or_not():
    ours = lambda prefix: prefix == A[:12]  # noqa: E731
    for order in ((A, B), (B, A)):  # which another process heard first, none can tell
        hosts = Hosts(36, Rejections(Log()), RunSetup.from_dict(SETUP))
        assert hosts.held_by_others(((0, 17), (18, 35)), ours) is None
        for gid in order:
            name = "w1" if gid == A else "stranger"
            hosts.learn(Host(name=name, first=[0, 18], last=[17, 35]), gid)
        conflict = hosts.held_by_others(((0, 17), (18, 35)), ours)
        assert conflict.tiles == [(0, 17), (18, 35)] and conflict.cells == "0-17, 18-35"
        assert conflict.process == f"node stranger, GUID prefix {B[:12].hex()}"
    # Cells left to remote workers: a claim of some of a worker's cells is a conflict too.
    setup = RunSetup.from_dict({**SETUP, "tiles": [[0, 17]], "remote": [[18, 35]]})
    hosts = Hosts(36, Rejections(Log()), setup)
    hosts.learn(Host(name="stranger", first=[27], last=[30]), B)
    assert hosts.held_by_others(((0, 17),), ours) is None
    assert hosts.held_by_others(((18, 35),), ours).tiles == [(18, 35)]
    # A tile not of the run's layout is refused by every process of the run: no conflict.
    hosts = Hosts(36, Rejections(Log()), RunSetup.from_dict(SETUP))
    hosts.learn(Host(name="stranger", first=[0], last=[35]), B)
    assert hosts.held_by_others(((0, 17), (18, 35)), ours) is None


def test_cells_left_to_remote_workers_may_be_announced_in_any_tiling():
    setup = RunSetup.from_dict({**SETUP, "tiles": [[0, 17]], "remote": [[18, 35]]})
    hosts = Hosts(36, Rejections(Log()), setup)
    assert hosts.learn(Host(name="far", first=[18, 27], last=[26, 35]), B) == [(18, 26), (27, 35)]


def test_a_background_is_taken_only_as_the_runs_next_one():
    check = BackgroundCheck(RunSetup.from_dict({**SETUP, "background_digests": ["d0", "d1"]}))
    assert check.problem("dx", A) == "a background that is not the run's next one"
    assert check.problem("d1", A) == "a background that is not the run's next one"
    assert check.problem("d0", B) is None
    assert check.problem("d0", A) == BackgroundCheck.REPEAT
    assert check.problem("d1", B) is None
    assert check.problem("d0", B) == "a background that is not the run's next one"


def test_without_the_runs_digests_the_first_writer_of_the_background_is_trusted():
    check = BackgroundCheck(None)
    assert check.problem("anything", A) is None
    assert check.problem("else", A) is None
    assert check.problem("anything", B) == "a background from a second writer"


@pytest.mark.parametrize(
    "text",
    [
        "not json",
        "[]",
        json.dumps({"run": "other", "params": {}, "backgrounds": []}),
        json.dumps({"run": "r", "params": {"rows": -1}, "backgrounds": []}),
        json.dumps({**SETUP, "step_timeout": "soon"}),
        json.dumps({**SETUP, "tiles": [[0]]}),
        json.dumps({**SETUP, "backgrounds": "forest"}),
        json.dumps({**SETUP, "params": {"rows": 6, "cols": 6, "speed": 3}}),
        json.dumps({**SETUP, "tiles": [[0, 40]]}),
    ],
)
def test_a_strangers_parameters_message_is_not_taken_for_the_runs(text):
    assert setup_from(text, "r") is None


def test_the_launchers_parameters_message_is_taken():
    setup = setup_from(json.dumps(SETUP), "r")
    assert setup is not None and setup.params.count == 36 and setup.tiles == ((0, 17), (18, 35))
    watching = {"continuous": False, "sense_period": 0.1, "change_window": 8}
    assert json.loads(setup.to_json()) == {
        **SETUP,
        **watching,
        "change_threshold": 24.0,
        "params": setup.params.as_dict(),
        "remote": [],
        "background_digests": [],
        "bridged": [],
    }
