"""`camo run`: robot nodes in several processes agree with the reference simulator, survive
killed robots and Ctrl-C, leave nothing behind a killed launcher, switch backgrounds, and refuse
bad options in one line."""

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import pytest
from support import (
    COMPUTE,
    PROCESS,
    ROOT,
    SWARM,
    TIMED,
    StatusListener,
    assert_like_sim,
    bad_value_outcomes,
    bag_tool,
    camo_run,
    domain,
    finished,
    ros_context,
    run_camo,
    start_run,
    validated,
    value_options,
    wait_for_line,
)

from camo_bringup import launcher, run_config, worker
from camo_core.swarm.keys import KEY_FILE_ENV, NO_TAG, new_key_file
from camo_core.swarm.robot_io import CONSENSUS


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


@pytest.mark.slow(COMPUTE)
@pytest.mark.parametrize("options, procs", CASES)
def test_swarm_equals_reference_simulator(tmp_path, options, procs):
    swarm, sim = summaries(tmp_path, options, procs)
    for key in sim:
        if key != "elapsed_s":
            assert swarm[key] == sim[key], key
    assert (tmp_path / "run" / "figure.png").stat().st_size > 10_000


def composite_scene(tmp_path, seed: int, cells: int):
    """A scene of regions of different textures (tools/scenes.py), as an image file."""
    import cv2

    sys.path.insert(0, str(ROOT / "tools"))
    from scenes import make_scene

    path = tmp_path / f"scene_{seed}.png"
    cv2.imwrite(str(path), make_scene(seed, cells=cells).image)
    return str(path)


@pytest.mark.slow(SWARM)
@pytest.mark.parametrize(
    "options, procs",
    [
        (["--rows", "16", "--cols", "16", "--rho-comm", "0.1", "--seed", "4"], 2),
        (["--rows", "12", "--cols", "12", "--orientation", "any", "--levels", "3"], 1),
    ],
)
def test_a_local_swarm_equals_the_simulator_with_loss_across_processes(tmp_path, options, procs):
    # --scope local's segmentation and segment consensus in the robot nodes: every vote of its
    # phases through the swarm's transport, lost ones too; its bag renders the same.
    from support import bag_tool

    image = composite_scene(tmp_path, 24, int(options[1]))
    args = ["--scope", "local", "--image", image, *options]
    run = camo_run(*args, "--procs", str(procs), "--out", str(tmp_path / "run"),
                   "--record", str(tmp_path / "bag"))  # fmt: skip
    assert run.returncode == 0, run.stderr[-2000:]
    sim = run_camo("sim", *args, "--out", str(tmp_path / "sim"))
    assert sim.returncode == 0, sim.stderr
    swarm = assert_like_sim(tmp_path / "run", tmp_path / "sim")
    assert swarm["scope"] == "local"
    assert len({name for row in swarm["patterns"] for name in row}) > 1  # regions of its own
    rendered = bag_tool("render", str(tmp_path / "bag"), "--out", str(tmp_path / "rendered"))
    assert rendered.returncode == 0, rendered.stderr
    assert_like_sim(tmp_path / "rendered", tmp_path / "sim")


def test_a_run_on_a_named_discovery_server_that_hears_nobody_says_where_to_look():
    server, hint, after = "10.0.0.5:11811", launcher.discovery_hint, launcher.HINT_AFTER
    assert hint(None, 10 * after, False) is None  # no server named: nothing
    assert hint(server, after - 1, False) is None  # not yet
    assert hint(server, 10 * after, True) is None  # a robot heard a neighbour
    said = hint(server, after, False)
    assert said is not None and f"is a discovery server running at {server}?" in said


@pytest.mark.slow(SWARM)
def test_run_rejects_bad_options_in_one_line(tmp_path):
    out = camo_run("--procs", "0", "--out", str(tmp_path))
    assert (
        out.returncode == 2
        and "--procs" in out.stderr
        and len(out.stderr.strip().splitlines()) == 1
    )


@pytest.mark.slow(PROCESS)
@pytest.mark.parametrize(
    "args, said",
    [
        (["--video", "missing.mp4"], "cannot read video missing.mp4: not found"),
        (["--camera", "57"], "camera 57: there is none (OpenCV opened no device 57)"),
        (["--images", "none/*.png", "--period", "1"], "--images none/*.png: no file matches it"),
    ],
)
def test_a_run_whose_stream_is_not_there_is_one_line_before_anything_starts(tmp_path, args, said):
    # The projector found out in a running swarm: its error, the launcher's, a refused status
    # and exit code 1.
    out = camo_run(*args, "--continuous", "--duration", "5", "--out", str(tmp_path / "run"))
    assert out.returncode == 2, out.stderr
    assert out.stderr.strip() == f"camo: error: {said}"
    assert not (tmp_path / "run").exists()


@pytest.mark.slow(SWARM)
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


@pytest.mark.slow(SWARM)
def test_two_runs_on_different_domains_do_not_disturb_each_other(tmp_path):
    runs = []
    for _k, pattern in enumerate(("forest", "desert")):
        runs.append(
            start_run("--pattern", pattern, "--procs", "1", "--out", str(tmp_path / pattern))
        )
    for proc in runs:
        _, err = finished(proc, 240)
        assert proc.returncode == 0, err[-2000:]
    for pattern, expected in (("forest", "vertical"), ("desert", "horizontal")):
        summary = json.loads((tmp_path / pattern / "summary.json").read_text())
        assert summary["pattern"] == expected
        assert sum(summary["votes"].values()) == 64 and "dead" not in summary


# s: the step timeout of the run whose robots are killed. Its process may stall for a second
# or two when they die (seen under CI's load); a stall is not counted against the neighbours
# (protocol.stalled), so the margins below allow one, and a robot that waited two timeouts
# still fails them.
KILLED_TIMEOUT = 4.0
KILLED_MARGIN = 3.0  # s: a stall, and reports' spacing (STATUS_PERIOD)


@pytest.mark.slow(SWARM)
@pytest.mark.alone(TIMED)
def test_swarm_survives_two_robots_killed_during_consensus(tmp_path):
    out_dir = tmp_path / "run"
    domain_id = domain()
    with StatusListener(domain_id, "killed") as statuses:
        proc = start_run(
            *["--pattern", "forest", "--procs", "1", "--own-process", "2,3"],
            *["--own-process", "5,6", "--step-timeout", str(KILLED_TIMEOUT)],
            *["--discovery-timeout", "20", "--consensus-steps", "4000", "--run-id", "killed"],
            *["--out", str(out_dir)],
            domain_id=domain_id,
        )
        seen = wait_for_line(proc, "consensus 64")  # every robot has voted and is in consensus
        processes = json.loads((out_dir / "processes.json").read_text())
        victims = [int(pid) for pid, cells in processes.items() if cells in ([19], [46])]
        killed = time.time()  # the wall clock: what the robots' processes stamp statuses with
        for pid in victims:
            os.kill(pid, 9)
        assert len(victims) == 2, "".join(seen[-30:])
        statuses.spin_until(lambda: proc.poll() is not None, 240)
        rest, _ = finished(proc, 60)
    assert proc.returncode == 0, rest
    # Found dead within one step timeout: the robots waiting for them at the kill (in
    # consensus) gave up on them, and said so in a status, within one timeout of it; those that
    # came to need them only once those gave up, within two. (Their neighbours in formation
    # only wait a timeout for them once formation begins.) Timed by when their process said so
    # (the status's stamp), not by when this test's listener got to it.
    gave_up = {}
    for row in statuses.got:
        if row.deadlines and row.phase == CONSENSUS:
            gave_up.setdefault(row.sender_id, row.said - killed)
    assert gave_up and not {19, 46} & set(gave_up)
    first, last = min(gave_up.values()), max(gave_up.values())
    assert first < KILLED_TIMEOUT + KILLED_MARGIN, f"the first gave up {first:.1f} s after it"
    assert last < 2 * KILLED_TIMEOUT + KILLED_MARGIN, f"the last gave up {last:.1f} s after it"
    summary = json.loads((out_dir / "summary.json").read_text())
    assert sorted(summary["dead"]) == [[2, 3], [5, 6]]
    assert summary["final"][2][3] is None and summary["final"][5][6] is None
    assert summary["pattern"] == "vertical" and summary["votes"]["vertical"] == 62
    assert "2 dead robots [[2, 3], [5, 6]]" in rest
    # Their neighbours each let a deadline pass once, and the run says so.
    assert json.loads((out_dir / "timing.json").read_text())["deadlines"] > 0
    assert "step deadlines passed" in rest


@pytest.mark.slow(SWARM)
def test_ctrl_c_stops_every_process_and_keeps_what_was_reported(tmp_path):
    out_dir = tmp_path / "run"
    proc = start_run(
        *["--pattern", "forest", "--procs", "2", "--consensus-steps", "10000"],
        *["--record", str(tmp_path / "bag"), "--foxglove", "0", "--out", str(out_dir)],
    )
    wait_for_line(proc, "consensus 64")
    started = children_of(proc.pid)
    assert len(started) == 5, started  # two workers, the projector, the recorder and the view
    time.sleep(1.0)
    proc.send_signal(2)
    _, err = finished(proc, 60)
    assert proc.returncode == 130, err
    assert "interrupted" in err and "Traceback" not in err
    assert not [pid for pid in started if running(pid)]
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


@pytest.mark.slow(SWARM)
def test_run_writes_timing(tmp_path):
    out = camo_run("--rows", "4", "--cols", "4", "--procs", "1", "--out", str(tmp_path))
    assert out.returncode == 0, out.stderr[-2000:]
    timing = json.loads((tmp_path / "timing.json").read_text())
    assert timing["steps"] == 45 and timing["steps_per_s"] > 0 and timing["deadlines"] == 0
    assert 0 < timing["startup_s"] <= timing["launch_to_done_s"]


def test_without_a_projector_the_title_names_the_background_topic_not_the_default(tmp_path):
    from camo_bringup.run_config import build_parser, config_from

    args = ["--no-projector", "--out", str(tmp_path / "a")]
    config = config_from(build_parser().parse_args(args))
    assert config.labels == [f"the background on {config.topics.background}"]
    config = config_from(build_parser().parse_args(["--out", str(tmp_path / "b")]))
    assert config.labels == ["built-in forest"]


@pytest.mark.slow(COMPUTE)
def test_background_switch_waits_for_a_matched_projector_and_names_a_missing_one(tmp_path):
    import rclpy
    from std_msgs.msg import String

    from camo_bringup.failures import RunFailed
    from camo_bringup.run_config import build_parser, config_from
    from camo_bringup.session import Session

    config = config_from(build_parser().parse_args(["--rows", "2", "--out", str(tmp_path)]))
    with ros_context() as context:
        session = Session(config, stop=False, context=context)
        projector = rclpy.create_node("projector", context=context)
        got = []
        try:
            message = f"no projector listens on {config.topics.load} after 0.5 s"
            with pytest.raises(RunFailed, match=message):
                session.switch_background("desert", limit=0.5)
            projector.create_subscription(String, config.topics.load, got.append, 10)
            session.executor.add_node(projector)
            session.switch_background("desert", limit=10.0)
            session.wait(lambda: got, "the projector got nothing", 10.0)
            assert [m.data for m in got] == ["desert"]
        finally:
            session.executor.remove_node(projector)
            projector.destroy_node()
            session.close()


@pytest.mark.slow(SWARM)
def test_two_runs_in_one_domain_each_equal_the_simulator(tmp_path):
    domain_id = str(domain())
    runs = {}
    for pattern in ("forest", "desert"):
        runs[pattern] = start_run(
            *["--pattern", pattern, "--rows", "6", "--cols", "6", "--procs", "1"],
            *["--out", str(tmp_path / pattern)],
            domain_id=domain_id,
        )
    for proc in runs.values():
        _, err = finished(proc, 240)
        assert proc.returncode == 0, err[-2000:]
    for pattern in runs:
        sim = run_camo(
            "sim",
            "--pattern",
            pattern,
            "--rows",
            "6",
            "--cols",
            "6",
            "--out",
            str(tmp_path / f"s{pattern}"),
        )
        assert sim.returncode == 0
        ran = json.loads((tmp_path / pattern / "summary.json").read_text())
        expected = json.loads((tmp_path / f"s{pattern}" / "summary.json").read_text())
        assert ran["final"] == expected["final"] and ran["mean_p"] == expected["mean_p"], pattern


@pytest.mark.slow(SWARM)
def test_a_run_id_in_use_is_refused_in_one_line(tmp_path):
    domain_id = str(domain())
    first = start_run(
        *["--rows", "3", "--cols", "3", "--consensus-steps", "100000", "--run-id", "taken"],
        *["--procs", "1", "--out", str(tmp_path / "first")],
        domain_id=domain_id,
    )
    try:
        wait_for_line(first, "consensus 9")
        second = subprocess.run(
            [sys.executable, "-m", "camo_bringup.launcher", "--rows", "3", "--cols", "3"]
            + ["--run-id", "taken", "--domain-id", domain_id, "--out", str(tmp_path / "second")],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=60,
        )
    finally:
        first.send_signal(2)
        finished(first, 60)
    assert second.returncode == 2, second.stderr
    assert "a run named taken is already running" in second.stderr
    assert len(second.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "second" / "summary.json").exists()


@pytest.mark.slow(SWARM)
def test_remote_cells_whose_worker_never_comes_are_dead_and_named(tmp_path):
    out = camo_run(
        "--rows", "4", "--cols", "4", "--remote-cells", "12-15", "--discovery-timeout", "3",
        "--procs", "1", "--out", str(tmp_path),
    )  # fmt: skip
    assert out.returncode == 0, out.stderr[-2000:]
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert sorted(summary["dead"]) == [[3, 0], [3, 1], [3, 2], [3, 3]]
    assert "remote cells 12-15 never joined" in out.stdout


@pytest.mark.slow(PROCESS)
def test_a_worker_with_no_run_to_join_says_so_in_one_line():
    out = subprocess.run(
        [sys.executable, "-m", "camo_bringup.worker", "--cells", "0-3", "--wait", "2"],
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "ROS_DOMAIN_ID": str(domain())},
    )
    assert out.returncode == 2 and "no run found in 2 s" in out.stderr
    errors = [line for line in out.stderr.splitlines() if "error" in line]
    assert len(errors) == 1 and "Traceback" not in out.stderr  # after the line saying it waits


@pytest.mark.parametrize(
    "cells, said",
    [
        ("5-2", "--cells 5-2: robot ids run from 0 to 67108863, first <= last"),
        ("0-99999999", "--cells 0-99999999: robot ids run from 0 to 67108863"),
        ("1_0-20", "--cells takes FIRST-LAST"),
        ("\uff10-3", "--cells takes FIRST-LAST"),
    ],
)
def test_a_worker_refuses_a_backward_or_too_large_range_before_looking_for_a_run(
    cells, said, capsys
):
    assert worker.main(["--cells", cells, "--wait", "0.01"]) == 2
    err = capsys.readouterr().err
    assert said in err and len(err.strip().splitlines()) == 1, err


def _config(tmp_path, *options):
    return run_config.config_from(
        run_config.build_parser().parse_args(
            ["--rows", "4", "--cols", "4", "--out", str(tmp_path / "o"), *options]
        ),
        {},
    )


@pytest.mark.parametrize(
    "options, said",
    [
        (
            ["--own-process", "0,0", "--own-process", "0,0"],
            "--own-process 0,0: that cell is given",
        ),
        (["--own-process", "0,0", "--own-process", "00,+0"], "that cell is given twice"),
        (["--own-process", "1_0,0"], "--own-process takes ROW,COL (got '1_0,0')"),
        (["--own-process", "0,"], "--own-process takes ROW,COL"),
        (["--remote-cells", "1_0-12"], "--remote-cells takes FIRST-LAST"),
        (["--bridge", "0,0=REGULAR"], "--bridge 0,0=REGULAR: not a serial port"),
        (["--bridge", "0,0=MISSING"], "--bridge 0,0=MISSING: no such port"),
        (["--bridge", "0,0=FOLDER"], "not a serial port"),
        (["--bridge", "\uff10,0=/dev/null"], "--bridge takes ROW,COL"),
    ],
)
def test_run_refuses_a_cell_given_twice_or_a_port_that_is_no_serial_port(tmp_path, options, said):
    from camo_core.exceptions import UsageError

    (tmp_path / "regular").write_text("")
    where = {"REGULAR": tmp_path / "regular", "MISSING": tmp_path / "gone", "FOLDER": tmp_path}
    options = [
        next((o.replace(k, str(v)) for k, v in where.items() if k in o), o) for o in options
    ]
    said = next((said.replace(k, str(v)) for k, v in where.items() if k in said), said)
    with pytest.raises(UsageError) as caught:
        _config(tmp_path, *options)
    assert said in str(caught.value) and "\n" not in str(caught.value)


def test_a_bridge_port_is_a_character_device_and_a_regular_file_is_not(tmp_path):
    from camo_core.exceptions import UsageError

    assert _config(tmp_path, "--bridge", "1,1=/dev/null").bridges == {5: "/dev/null"}
    (tmp_path / "regfile").write_text("")
    with pytest.raises(UsageError, match="not a serial port"):
        _config(tmp_path, "--bridge", f"1,1={tmp_path / 'regfile'}")


def children_of(pid: int) -> list[int]:
    """The processes whose parent is `pid` (from /proc)."""
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                stat = open(f"/proc/{entry}/stat").read()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                found.append(int(entry))
    return found


def running(pid: int) -> bool:
    try:
        return "zombie" not in open(f"/proc/{pid}/status").read().lower()
    except OSError:
        return False


def stranger_hosting(run: str, domain_id: str, *tiles: str, key: str = "") -> subprocess.Popen:
    """tests/attacker.py announcing `tiles` of run `run` as its own (and beating), once ready;
    with the run's `key` file, or without one."""
    env = {**os.environ, "ROS_DOMAIN_ID": domain_id}
    env.pop(KEY_FILE_ENV, None)
    if key:
        env[KEY_FILE_ENV] = key
    stranger = subprocess.Popen(
        [sys.executable, str(ROOT / "tests" / "attacker.py"), run, "300", "--hijack", *tiles],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    wait_for_line(stranger, "ready")
    return stranger


DISCOVERY = 5.0  # s: the runs below wait this long for a robot's neighbours at most


@pytest.mark.slow(SWARM)
def test_a_stranger_without_the_key_hosting_the_runs_cells_first_changes_nothing(tmp_path):
    """A process without the run's key announces cells 4-8 of run lab before its workers do,
    and beats: its announcements and heartbeats are refused, and the run is the simulator's."""
    domain_id = str(domain())
    key = str(new_key_file(tmp_path / "lab.key").path)
    stranger = stranger_hosting("lab", domain_id, "4-8")
    try:
        options = ["--rows", "3", "--cols", "3", "--seed", "4", "--pattern", "forest"]
        # Seconds of steps: the run's processes hear the stranger (under load, discovery can
        # miss its first announcements and wait for the next) and report what they refused.
        options += ["--consensus-steps", "3000"]
        run = start_run(
            *options,
            *["--run-id", "lab", "--procs", "2", "--key-file", key],
            *["--discovery-timeout", str(DISCOVERY), "--out", str(tmp_path / "run")],
            domain_id=domain_id,
        )
        _, err = finished(run, 120)
    finally:
        stranger.terminate()
        finished(stranger, 30)
    assert run.returncode == 0, err[-3000:]
    sim = run_camo("sim", *options, "--out", str(tmp_path / "sim"))
    ran = assert_like_sim(tmp_path / "run", tmp_path / "sim", attacked=True)
    assert sim.returncode == 0 and ran["rejected_messages"]["by_reason"][NO_TAG] > 0, ran


@pytest.mark.slow(SWARM)
def test_an_insider_hosting_the_runs_cells_first_ends_it_in_one_line(tmp_path):
    """A process with the run's key that the launcher did not start announces cells 4-8 of
    run lab before its workers do: the run ends (code 2) within its discovery timeout, says
    who took what in one line, and leaves none of its processes behind. The run goes on until
    its processes have discovered that one (a continuous run of 30 s): under load a 3x3 round
    can end, rightly with code 0, before any of them hears it."""
    domain_id = str(domain())
    key = str(new_key_file(tmp_path / "lab.key").path)
    stranger = stranger_hosting("lab", domain_id, "4-8", key=key)
    err_path = tmp_path / "stderr"
    started, children = time.monotonic(), set()
    try:
        with open(err_path, "w") as err:
            run = subprocess.Popen(
                [sys.executable, "-m", "camo_bringup.launcher", "--rows", "3", "--cols", "3"]
                + ["--run-id", "lab", "--domain-id", domain_id, "--procs", "2"]
                + ["--key-file", key, "--continuous", "--duration", "30"]
                + ["--discovery-timeout", str(DISCOVERY), "--out", str(tmp_path / "run")],
                cwd=ROOT,
                stdout=subprocess.DEVNULL,
                stderr=err,
            )
            while run.poll() is None and time.monotonic() - started < DISCOVERY + 60:
                children.update(children_of(run.pid))
                time.sleep(0.1)
            took = time.monotonic() - started
            if run.poll() is None:  # it hangs: as it did before the conflict was decided
                run.send_signal(signal.SIGINT)
                run.wait(60)
    finally:
        stranger.terminate()
        finished(stranger, 30)
    stderr = err_path.read_text()
    assert run.returncode == 2 and took < DISCOVERY + 25, (took, stderr[-3000:])
    errors = [line for line in stderr.splitlines() if "error" in line]
    assert len(errors) == 1 and "Traceback" not in stderr, stderr[-3000:]
    line = errors[0]
    assert "run lab" in line and "cells 4-8" in line and "node stranger" in line, line
    assert "GUID prefix 010f" in line and "0-3" not in line, line
    assert len(children) >= 2 and not [pid for pid in children if running(pid)], children


@pytest.mark.slow(SWARM)
def test_a_worker_for_cells_hosted_already_or_not_left_to_it_says_so_in_one_line(tmp_path):
    """A worker started by hand for run lab: for cells another process announced first, or for
    cells the run hosts itself, it exits 2 at once with one line saying why."""
    domain_id = str(domain())
    env = {**os.environ, "ROS_DOMAIN_ID": domain_id}
    key = str(new_key_file(tmp_path / "lab.key").path)  # the run's, given to its workers
    run = subprocess.Popen(
        [sys.executable, "-m", "camo_bringup.launcher", "--rows", "3", "--cols", "3"]
        + ["--run-id", "lab", "--domain-id", domain_id, "--procs", "1", "--remote-cells", "6-8"]
        + ["--discovery-timeout", "120", "--out", str(tmp_path / "run"), "--key-file", key],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    stranger = None
    try:
        wait_for_line(run, "topics under")
        stranger = stranger_hosting("lab", domain_id, "6-8", key=key)
        workers = {}
        for cells in ("6-8", "0-2"):
            started = time.monotonic()
            workers[cells] = subprocess.run(
                [sys.executable, "-m", "camo_bringup.worker", "--cells", cells]
                + ["--run-id", "lab", "--wait", "30", "--key-file", key],
                capture_output=True,
                text=True,
                timeout=60,
                env=env,
            )
            assert time.monotonic() - started < 20, (cells, workers[cells].stderr)
    finally:
        if stranger is not None:
            stranger.terminate()
            finished(stranger, 30)
        run.send_signal(signal.SIGINT)
        finished(run, 60)
    for refused in workers.values():
        errors = [line for line in refused.stderr.splitlines() if "error" in line]
        assert refused.returncode == 2 and len(errors) == 1, refused.stderr
        assert "Traceback" not in refused.stderr and "run lab" in errors[0], refused.stderr
    # Said before it hosts anything if it heard the stranger in time, else once it does.
    hosted = workers["6-8"].stderr
    assert "cells 6-8 are hosted already" in hosted or "cells 6-8 were announced" in hosted
    assert "node stranger" in hosted, hosted
    assert "cells 0-2 are not left to remote workers" in workers["0-2"].stderr


@pytest.mark.slow(SWARM)
def test_nothing_the_launcher_started_outlives_its_sigkill(tmp_path):
    """Workers, a robot of its own process, the projector and the recorder all exit within
    10 s of the launcher's SIGKILL, and the bag they leave is readable and named incomplete."""
    out_dir = tmp_path / "run"
    proc = start_run(
        *["--pattern", "forest", "--procs", "2", "--own-process", "2,3"],
        *["--consensus-steps", "10000", "--record", str(tmp_path / "bag"), "--out", str(out_dir)],
    )
    wait_for_line(proc, "consensus 64")
    started = children_of(proc.pid)
    # two workers, the robot of its own, the projector and the recorder
    assert len(started) == 5, started
    proc.kill()
    finished(proc, 30)
    deadline = time.monotonic() + 10.0
    while any(running(pid) for pid in started) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not [pid for pid in started if running(pid)]
    info = bag_tool("cli", "info", str(tmp_path / "bag"))
    assert info.returncode == 0, info.stderr
    assert "INCOMPLETE" in info.stdout


@pytest.mark.slow(SWARM)
def test_a_robot_stopped_for_seconds_is_waited_for_not_marked_dead(tmp_path):
    """SIGSTOP a robot's process for 5 s mid-consensus, then SIGCONT: its neighbours wait (their
    deadline is longer), nobody reports it silent, and the run equals the simulator."""
    options = ["--pattern", "forest", "--seed", "3", "--consensus-steps", "6000"]
    out_dir = tmp_path / "run"
    proc = start_run(
        *options,
        "--procs",
        "1",
        "--own-process",
        "4,4",
        "--step-timeout",
        "20",
        "--out",
        str(out_dir),
    )
    wait_for_line(proc, "consensus 64")
    processes = json.loads((out_dir / "processes.json").read_text())
    (slow,) = [int(pid) for pid, cells in processes.items() if cells == [36]]
    os.kill(slow, signal.SIGSTOP)
    time.sleep(5.0)
    os.kill(slow, signal.SIGCONT)
    _, err = finished(proc, 240)
    assert proc.returncode == 0, err[-2000:]
    assert "dead" not in err and "deadlines passed" not in err
    sim = run_camo("sim", *options, "--out", str(tmp_path / "sim"))
    assert sim.returncode == 0, sim.stderr
    ran = assert_like_sim(out_dir, tmp_path / "sim")
    assert "dead" not in ran
    assert ran["elapsed_s"] > 5.0  # the swarm did wait for it


@pytest.mark.slow(SWARM)
def test_a_process_slower_than_the_step_timeout_is_waited_for_and_the_run_equals_the_simulator(
    tmp_path,
):
    """One of two workers sleeps 1.5 s before every turn of its loop, with a step timeout of
    1 s: every step its neighbours wait longer than the timeout. Its process beats all along,
    so nobody is given up on, and the swarm computes what the simulator does."""
    options = ["--pattern", "forest", "--seed", "4", "--consensus-steps", "6"]
    options += ["--formation-steps", "4"]
    env = dict(os.environ, CAMO_SLOW_CELLS="--cells=32-63", CAMO_SLOW_SECONDS="1.5")
    env["PYTHONPATH"] = f"{ROOT / 'tests' / 'slow_process'}:{env.get('PYTHONPATH', '')}"
    out_dir = tmp_path / "run"
    ran = subprocess.run(
        [sys.executable, "-m", "camo_bringup.launcher", *options, "--procs", "2"]
        + ["--step-timeout", "1", "--domain-id", str(domain()), "--out", str(out_dir)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert ran.returncode == 0, ran.stderr[-2000:]
    processes = json.loads((out_dir / "processes.json").read_text())
    assert list(range(32, 64)) in processes.values()  # the slowed worker was there
    assert "deadlines passed" not in ran.stderr and "dead" not in ran.stderr
    timing = json.loads((out_dir / "timing.json").read_text())
    assert timing["deadlines"] == 0
    sim = run_camo("sim", *options, "--out", str(tmp_path / "sim"))
    assert sim.returncode == 0, sim.stderr
    summary = assert_like_sim(out_dir, tmp_path / "sim")
    assert summary["elapsed_s"] > 5 * 1.5  # it was slow: turns of 1.5 s, each past the timeout


@pytest.mark.slow(SWARM)
def test_a_runs_params_yaml_repeats_it_bit_for_bit(tmp_path):
    import yaml

    first = camo_run(
        "--pattern",
        "desert",
        "--rows",
        "4",
        "--cols",
        "5",
        "--seed",
        "7",
        "--rho-comm",
        "0.2",
        "--out",
        str(tmp_path / "a"),
    )
    assert first.returncode == 0, first.stderr[-2000:]
    params = tmp_path / "a" / "params.yaml"
    written = yaml.safe_load(params.read_text())["/**"]["ros__parameters"]
    assert written["rows"] == 4 and written["rho_comm"] == 0.2 and "out" not in written
    again = camo_run("--params-file", str(params), "--out", str(tmp_path / "b"))
    assert again.returncode == 0, again.stderr[-2000:]
    load = lambda run: json.loads((tmp_path / run / "summary.json").read_text())  # noqa: E731
    a, b = load("a"), load("b")
    assert {k: v for k, v in a.items() if k != "elapsed_s"} == {
        k: v for k, v in b.items() if k != "elapsed_s"
    }
    rewritten = yaml.safe_load((tmp_path / "b" / "params.yaml").read_text())["/**"]
    written.pop("domain_id")  # each test run has a domain of its own, given on the command line
    assert rewritten["ros__parameters"].pop("domain_id") != first
    assert rewritten["ros__parameters"] == written


@pytest.mark.slow(PROCESS)
def test_the_demo_writes_an_animation_of_the_swarm_at_work(tmp_path):
    from PIL import Image

    out = subprocess.run(
        ["bash", str(ROOT / "camo"), "demo", "--domain-id", str(domain()), "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert "look at run.gif" in out.stderr + out.stdout
    gif = tmp_path / "run.gif"
    assert gif.stat().st_size < 2 * 1024 * 1024
    frames = set()
    with Image.open(gif) as image:
        for k in range(image.n_frames):
            image.seek(k)
            frames.add(image.convert("RGB").tobytes())
    assert len(frames) >= 10  # consensus and formation change over many steps


@pytest.mark.slow(SWARM)
def test_the_runs_own_recorder_is_waited_for_before_discovery_shows_it(tmp_path, capfd):
    """A loaded machine can take longer to show the recorder it started than a short round
    lasts: the robots must not stop before the recorder has said it holds their round."""
    import rclpy
    from std_msgs.msg import String

    from camo_bringup.run_config import build_parser, config_from
    from camo_bringup.session import Session
    from camo_nodes.topics.qos import LATCHED

    class NothingFailed:
        def failed(self):
            return None

    options = ["--rows", "2", "--out", str(tmp_path / "run"), "--record", str(tmp_path / "bag")]
    config = config_from(build_parser().parse_args(options))
    with ros_context() as context:
        session = Session(config, stop=False, context=context)
        recorder = rclpy.create_node("recorder", context=context)
        try:
            assert session.recorders.present()  # at once: no discovery to wait for
            start = time.monotonic()
            session.recorders.hold(0, NothingFailed(), limit=1.0)  # no recorder has spoken
            assert time.monotonic() - start >= 1.0
            assert "1 recordings lack round 0" in capfd.readouterr().err
            report = {"recorder": "r", "result": False, "complete": [0], "lacking": [[]]}
            publisher = recorder.create_publisher(String, config.topics.recorded, LATCHED)
            publisher.publish(String(data=json.dumps(report)))
            session.executor.add_node(recorder)
            session.recorders.hold(0, NothingFailed(), limit=30.0)
            assert "lack" not in capfd.readouterr().err
            # Once the run's own recorder is known, another's report does not stand for it.
            session.recorders.own = "here:1"
            session.recorders.hold(0, NothingFailed(), limit=1.0)
            assert "1 recordings lack round 0" in capfd.readouterr().err
            publisher.publish(String(data=json.dumps({**report, "recorder": "here:1"})))
            session.recorders.hold(0, NothingFailed(), limit=30.0)
            assert "lack" not in capfd.readouterr().err
        finally:
            session.executor.remove_node(recorder)
            recorder.destroy_node()
            session.close()


def test_the_swarm_resolves_auto_before_its_robots_get_the_parameters(tmp_path):
    from camo_bringup.run_config import build_parser, config_from

    args = ["--rows", "16", "--cols", "16", "--consensus-steps", "auto", "--out", str(tmp_path)]
    config = config_from(build_parser().parse_args(args))
    assert config.params.consensus_steps == 161
    assert config.setup().to_dict()["params"]["consensus_steps"] == 161  # what /swarm/params says


@pytest.mark.slow(SWARM)
def test_the_swarm_with_threshold_auto_equals_the_simulator_and_its_bag_holds_the_energies(
    tmp_path,
):
    import cv2
    from support import bag_tool, brick_courses

    image = tmp_path / "courses.png"
    cv2.imwrite(str(image), brick_courses())
    args = ["--image", str(image), "--rows", "16", "--cols", "16", "--rho-comm", "0.1"]
    run = camo_run(*args, "--threshold", "auto", "--procs", "2", "--out", str(tmp_path / "run"),
                   "--record", str(tmp_path / "bag"))  # fmt: skip
    assert run.returncode == 0, run.stderr[-2000:]
    assert "lacks" not in run.stderr
    sim = run_camo("sim", *args, "--threshold", "auto", "--out", str(tmp_path / "sim"))
    assert sim.returncode == 0, sim.stderr
    ran = assert_like_sim(tmp_path / "run", tmp_path / "sim")
    assert ran["pattern"] == "horizontal"  # faint courses: a fixed threshold sees none
    fixed = run_camo("sim", *args, "--out", str(tmp_path / "fixed"))
    assert fixed.returncode == 0, fixed.stderr
    assert json.loads((tmp_path / "fixed" / "summary.json").read_text())["pattern"] == "mottled"
    info = bag_tool("cli", "info", str(tmp_path / "bag"))
    energies = [x for x in info.stdout.splitlines() if "/energy " in x]
    assert energies and all("Type: camo_msgs/msg/Energies" in x for x in energies)
    rendered = bag_tool("render", str(tmp_path / "bag"), "--out", str(tmp_path / "rendered"))
    assert rendered.returncode == 0, rendered.stderr
    assert_like_sim(tmp_path / "rendered", tmp_path / "sim")


@pytest.mark.slow(SWARM)
def test_the_swarm_with_orientation_any_threshold_auto_and_levels_equals_the_simulator(tmp_path):
    import cv2
    from rclpy.serialization import deserialize_message
    from support import bag_tool, unpacked

    from camo_bag.loader import read_messages
    from camo_core.algorithm.backgrounds import stripes
    from camo_msgs.msg import Relays

    image = tmp_path / "stripes.png"
    cv2.imwrite(str(image), stripes(30, period=64))
    args = ["--image", str(image), "--rows", "16", "--cols", "16", "--rho-comm", "0.2",
            "--orientation", "any", "--threshold", "auto", "--levels", "3"]  # fmt: skip
    run = camo_run(*args, "--procs", "2", "--out", str(tmp_path / "run"),
                   "--record", str(tmp_path / "bag"))  # fmt: skip
    assert run.returncode == 0, run.stderr[-2000:]
    assert "lacks" not in run.stderr
    sim = run_camo("sim", *args, "--out", str(tmp_path / "sim"))
    assert sim.returncode == 0, sim.stderr
    ran = assert_like_sim(tmp_path / "run", tmp_path / "sim")
    assert ran["pattern"] == "stripes" and abs(ran["orientation_deg"] - 30) <= 15
    assert len({g for row in ran["display"] for g in row}) > 2  # more than black and white
    assert "pattern: stripes at" in run.stdout
    info = bag_tool("cli", "info", str(tmp_path / "bag"))
    relays = [x for x in info.stdout.splitlines() if "/relay " in x]
    assert relays and all("camo_msgs/msg/Relays" in x for x in relays)
    bag = tmp_path / "bag"
    rendered = bag_tool("render", str(bag), "--out", str(tmp_path / "rendered"))
    assert rendered.returncode == 0, rendered.stderr
    assert_like_sim(tmp_path / "rendered", tmp_path / "sim")
    # The bag holds every relay (16 x 16 robots, 10 steps each), packed as columns, and replay
    # publishes those messages again, typed from the bag.
    topics = [next(w for w in x.split() if w.endswith("/relay")) for x in relays]
    arrays = [deserialize_message(m.data, Relays) for m in read_messages(bag, topics)]
    sent = {(r.sender_id, r.step) for array in arrays for r in unpacked(array, "relay")}
    assert sent == {(robot, step) for robot in range(16 * 16) for step in range(10)}
    assert len(arrays) < len(sent) / 4  # several robots' relays in one DDS message
    replay = bag_tool("replay", str(bag), "--rate", "50", "--topics", *topics,
                      "--domain-id", str(domain()))  # fmt: skip
    assert replay.returncode == 0, replay.stderr
    assert f"published {len(arrays)} messages on {len(topics)} topics" in replay.stderr


@pytest.mark.slow(SWARM)
def test_the_swarm_with_colours_and_loss_equals_the_simulator_live_and_rendered(tmp_path):
    import cv2
    from skimage import data
    from support import bag_tool

    image = tmp_path / "coffee.png"
    cv2.imwrite(str(image), cv2.cvtColor(data.coffee(), cv2.COLOR_RGB2BGR))
    args = ["--image", str(image), "--rows", "10", "--cols", "12", "--colours", "4",
            "--rho-comm", "0.2", "--rho-meas", "0.1", "--seed", "4"]  # fmt: skip
    run = camo_run(*args, "--procs", "2", "--out", str(tmp_path / "run"),
                   "--record", str(tmp_path / "bag"))  # fmt: skip
    assert run.returncode == 0, run.stderr[-2000:]
    sim = run_camo("sim", *args, "--out", str(tmp_path / "sim"))
    assert sim.returncode == 0, sim.stderr
    ran = assert_like_sim(tmp_path / "run", tmp_path / "sim")
    shown = {tuple(c) for row in ran["display"] for c in row}
    assert len(shown) > 2 and any(len(set(c)) > 1 for c in shown)  # colours, not greys
    rendered = bag_tool("render", str(tmp_path / "bag"), "--out", str(tmp_path / "rendered"))
    assert rendered.returncode == 0, rendered.stderr
    assert_like_sim(tmp_path / "rendered", tmp_path / "sim")


@pytest.mark.slow(SWARM)
def test_the_swarm_on_a_hexagonal_layout_with_levels_equals_the_simulator(tmp_path):
    from support import bag_tool

    args = ["--layout", "hex", "--levels", "3", "--orientation", "any", "--rows", "12",
            "--cols", "12", "--rho-comm", "0.2", "--pattern", "forest"]  # fmt: skip
    run = camo_run(*args, "--procs", "2", "--out", str(tmp_path / "run"),
                   "--record", str(tmp_path / "bag"))  # fmt: skip
    assert run.returncode == 0, run.stderr[-2000:]
    sim = run_camo("sim", *args, "--out", str(tmp_path / "sim"))
    assert sim.returncode == 0, sim.stderr
    ran = assert_like_sim(tmp_path / "run", tmp_path / "sim")
    assert ran["layout"] == "hex" and ran["pattern"] == "stripes"
    rendered = bag_tool("render", str(tmp_path / "bag"), "--out", str(tmp_path / "rendered"))
    assert rendered.returncode == 0, rendered.stderr
    assert_like_sim(tmp_path / "rendered", tmp_path / "sim")


def test_a_file_layout_reaches_robot_nodes_of_their_own_as_a_csv(tmp_path):
    from pathlib import Path

    from camo_bringup.processes import robot_parameters
    from camo_bringup.run_config import build_parser, config_from

    layout = tmp_path / "swarm.csv"
    layout.write_text("0,0\n1,0\n0.5,0.87\n1.5,0.87\n")
    args = ["--layout", str(layout), "--orientation", "any", "--out", str(tmp_path / "o")]
    config = config_from(build_parser().parse_args(args))
    assert (config.params.rows, config.params.cols, config.params.layout) == (1, 4, "file")
    given = dict(x.split(":=", 1) for x in robot_parameters(config, 2) if ":=" in x)
    written = Path(given["layout"])
    assert written.parent == config.folder and written.read_text().splitlines()[2] == "0.5,0.87"


def test_a_large_swarm_on_this_machine_defers_discovery_to_a_server_of_its_own(tmp_path):
    from camo_bringup.run_config import DEFER_FROM, build_parser, config_from

    side = 65  # 4225 robots
    assert side * side >= DEFER_FROM
    large = ["--rows", str(side), "--cols", str(side), "--out", str(tmp_path / "a")]
    config = config_from(build_parser().parse_args(large), environ={})
    host, _, port = config.deferred.rpartition(":")
    assert host == "127.0.0.1" and 0 < int(port) < 65536
    assert config.env["ROS_DISCOVERY_SERVER"] == config.deferred
    assert config.env["ROS_SUPER_CLIENT"] == "TRUE"
    small = ["--rows", "64", "--cols", "64", "--out", str(tmp_path / "b")]
    assert config_from(build_parser().parse_args(small), environ={}).deferred is None
    # Not when the user chose how processes find each other, nor with workers elsewhere.
    for k, extra in enumerate((["--network", "subnet"], ["--discovery-server", "10.0.0.1:11811"])):
        args = build_parser().parse_args([*large[:-1], str(tmp_path / f"c{k}"), *extra])
        assert config_from(args, environ={}).deferred is None
    remote = [*large[:-1], str(tmp_path / "d"), "--remote-cells", "0-9"]
    assert config_from(build_parser().parse_args(remote), environ={}).deferred is None


@pytest.mark.slow(SWARM)
def test_a_swarm_whose_discovery_was_deferred_equals_the_simulator(tmp_path):
    """65 x 65 robots: the workers create their robot nodes hearing nobody, then find each other
    through the run's own discovery server; the result is the simulator's."""
    options = ["--rows", "65", "--cols", "65", "--consensus-steps", "6", "--formation-steps", "3"]
    out = camo_run(*options, "--procs", "2", "--out", str(tmp_path / "run"), timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "robot nodes created" in out.stderr and "discovery server at 127.0.0.1:" in out.stderr
    assert "did not stop" not in out.stderr  # the workers exit at once
    sim = run_camo("sim", *options, "--out", str(tmp_path / "sim"))
    assert sim.returncode == 0, sim.stderr
    assert_like_sim(tmp_path / "run", tmp_path / "sim")


@pytest.mark.slow(SWARM)
def test_ctrl_c_stops_thousands_of_robots_within_seconds_and_keeps_what_they_reported(tmp_path):
    out_dir = tmp_path / "run"
    proc = start_run(
        *["--rows", "64", "--cols", "64", "--procs", "2", "--consensus-steps", "5000"],
        *["--out", str(out_dir)],
    )
    wait_for_line(proc, "consensus 4096")
    started = children_of(proc.pid)
    assert len(started) == 3, started  # two workers and the projector
    # A few steps: as they stop, robots report what they did since their last report.
    time.sleep(1.0)
    interrupted = time.monotonic()
    proc.send_signal(2)
    _, err = finished(proc, 60)
    stopped = time.monotonic() - interrupted
    assert proc.returncode == 130, err[-2000:]
    assert stopped < 10, f"{stopped:.1f} s from Ctrl-C to exit"
    assert "did not stop" not in err and "Traceback" not in err
    assert not [pid for pid in started if running(pid)]
    for pid in json.loads((out_dir / "processes.json").read_text()):
        assert (
            not os.path.exists(f"/proc/{pid}")
            or "zombie" in open(f"/proc/{pid}/status").read().lower()
        )
    summary = json.loads((out_dir / "summary.json").read_text())
    assert "incomplete" in summary and "dead" not in summary
    assert len(summary["consensus_trace"]) >= 2


@contextlib.contextmanager
def full_filesystem(tmp_path, size: str = "200k"):
    """A tmpfs of `size` mounted in tmp_path (root only; the test is skipped elsewhere)."""
    mount = tmp_path / "small"
    mount.mkdir()
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("mounting a small tmpfs needs root")
    made = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(mount)],
        capture_output=True,
        text=True,
    )
    if made.returncode:
        pytest.skip(f"cannot mount a tmpfs here: {made.stderr.strip()[-120:]}")
    try:
        yield mount
    finally:
        subprocess.run(["umount", "-l", str(mount)], capture_output=True)


@pytest.mark.slow(SWARM)
def test_a_recording_onto_a_full_disk_costs_the_bag_and_never_the_run(tmp_path):
    options = ["--pattern", "leopard", "--rows", "16", "--cols", "16", "--seed", "4"]
    options += ["--rho-comm", "0.1"]
    with full_filesystem(tmp_path) as small:
        bag = small / "bag"
        run = camo_run(*options, "--record", str(bag), "--out", str(tmp_path / "run"))
        assert run.returncode == 3, run.stderr[-3000:]
        assert "Traceback" not in run.stderr, run.stderr[-3000:]
        said = [line for line in run.stderr.splitlines() if "error" in line]
        assert len(said) == 1, said
        assert f"cannot write the bag {bag}" in said[0] and "No space left" in said[0]
        assert "messages" in said[0] and "incomplete" in said[0]
        info = bag_tool("cli", "info", str(bag))
        assert info.returncode != 0 and "truncated or was not closed" in info.stderr
        assert len(info.stderr.strip().splitlines()) == 1 and "Traceback" not in info.stderr
        repaired = bag_tool("cli", "repair", str(bag), "--out", str(tmp_path / "repaired"))
        assert repaired.returncode == 0, repaired.stderr
    again = bag_tool("cli", "info", str(tmp_path / "repaired"))
    assert again.returncode == 0 and "Messages:" in again.stdout, again.stderr
    sim = run_camo("sim", *options, "--out", str(tmp_path / "sim"))
    assert sim.returncode == 0, sim.stderr
    assert_like_sim(tmp_path / "run", tmp_path / "sim")


# ---- every option with bad values (issue 27) -------------------------------------------------


@pytest.mark.parametrize("option", value_options(run_config.build_parser()))
def test_every_option_of_run_with_a_bad_value_is_one_line_and_exit_2(
    option, tmp_path, monkeypatch, capsys
):
    # Only the command line and the run's set-up are checked: starting the swarm is replaced.
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(launcher, "run", validated)
    argv = ["--rows", "2", "--cols", "2"]
    if option != "--out":
        argv += ["--out", str(tmp_path / "out"), "--force"]
    assert bad_value_outcomes(launcher.main, argv, option, capsys, run_config.build_parser()) == []


@pytest.mark.parametrize("option", ["--step-timeout", "--discovery-timeout"])
def test_a_timeout_beyond_a_day_is_refused(option, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(launcher, "run", validated)
    argv = ["--rows", "2", "--cols", "2", "--out", str(tmp_path / "o"), option, "1e300"]
    assert launcher.main(argv) == 2
    assert "86400" in capsys.readouterr().err


@pytest.mark.parametrize("option", value_options(worker.build_parser()))
def test_every_option_of_worker_with_a_bad_value_is_one_line_and_exit_2(
    option, tmp_path, monkeypatch, capsys
):
    # Only the command line and the network it asks for are checked: joining is replaced
    # (and the environment it would set is this test's own copy).
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(os, "environ", dict(os.environ))
    monkeypatch.setattr(worker, "start_ros", validated)
    argv = [] if option == "--cells" else ["--cells", "0-3"]
    assert bad_value_outcomes(worker.main, argv, option, capsys, worker.build_parser()) == []
