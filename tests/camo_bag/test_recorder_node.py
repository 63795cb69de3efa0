"""The recorder: complete bags of whole runs, Ctrl-C and SIGKILL mid-run, refused folders."""

import json
import os
import signal
import subprocess
import sys
import time

import pytest
from support import (
    ROOT,
    SWARM,
    bag_tool,
    camo_run,
    domain,
    finished,
    robot_messages_in,
    start_run,
    unpacked,
    wait_for_line,
)


def deserialize(data: bytes) -> str:
    from rclpy.serialization import deserialize_message
    from std_msgs.msg import String

    return deserialize_message(data, String).data


def recorded_so_far(
    bag, suffix: str, count: int, writer: subprocess.Popen, timeout: float = 120
) -> int:
    """Wait until the finished chunks of a bag being written hold `count` messages on topics ending
    in
    `suffix` (a loaded machine can take seconds to discover topics); how many they hold."""
    from camo_bag.container import BagError
    from camo_bag.loader import open_bag

    deadline = time.monotonic() + timeout
    while True:
        try:
            topics = open_bag(bag, partial=True, stream=True).summary.topics
        except BagError:  # not created, or its magic not yet flushed
            topics = []
        seen = sum(t.count for t in topics if t.name.endswith(suffix))
        if seen >= count:
            return seen
        assert writer.poll() is None, "the recording process ended early"
        assert time.monotonic() < deadline, (
            f"fewer than {count} {suffix} messages recorded in {timeout:g} s"
        )
        time.sleep(0.5)


@pytest.mark.slow(SWARM)
def test_recorder_killed_with_sigkill_mid_run_leaves_chunks_that_repair_recovers(tmp_path):
    from rosbags.highlevel import AnyReader

    domain_id = domain()
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
    log = tmp_path / "recorder.log"
    recorder = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "camo_bag.recorder_node",
            str(tmp_path / "killed"),
            "--run-id",
            "k",
        ],
        cwd=ROOT,
        env=env,
        stderr=open(log, "w"),
    )
    # The recorder waits for run k to appear, and records it from its start.
    # 4x4 robots do thousands of steps a second: the longest run is still going when the
    # recorder is killed (2x2 robots finished 40000 steps first on a fresh-clone CI run).
    swarm = start_run(
        "--rows",
        "4",
        "--cols",
        "4",
        "--consensus-steps",
        "100000",
        "--procs",
        "1",
        "--run-id",
        "k",
        "--out",
        str(tmp_path / "run"),
        domain_id=domain_id,
    )
    try:
        wait_for_line(swarm, "consensus 16")
        seen = recorded_so_far(tmp_path / "killed", "/vote", 200, recorder)
        assert swarm.poll() is None, "the run ended before the recorder was killed"
    finally:
        recorder.send_signal(signal.SIGKILL)
        recorder.wait()
        swarm.send_signal(signal.SIGINT)
        # It ends even if Fast DDS blocks its last publication on the dead recorder's
        # shared-memory port: its watchdog then exits it (code 1) and names where in stuck.txt.
        finished(swarm, 120)
    stuck = tmp_path / "run" / "stuck.txt"
    assert swarm.returncode == 130 or (swarm.returncode == 1 and stuck.read_text())
    assert bag_tool("cli", "info", str(tmp_path / "killed")).returncode == 2
    out = bag_tool("cli", "repair", str(tmp_path / "killed"), "--out", str(tmp_path / "fixed"))
    assert out.returncode == 0, out.stderr
    steps: dict[int, list[int]] = {}
    with AnyReader([tmp_path / "fixed"]) as reader:
        votes = [c for c in reader.connections if c.topic.endswith("/vote")]
        assert votes, "no vote topic recovered"
        for connection, _, raw in reader.messages(connections=votes):
            for msg in unpacked(reader.deserialize(raw, connection.msgtype), "vote"):
                steps.setdefault(msg.sender_id, []).append(msg.step)
    # Each finished chunk holds what arrived before it: a robot's votes from step 0 on, without
    # gaps (the recorder may lag a fast swarm, so not every robot need have reached a finished
    # chunk). A late joiner can get a live sample just before the history that precedes it, so
    # the order of the first few steps is not checked.
    assert set(steps) <= set(range(16)) and steps
    assert all(sorted(s) == list(range(len(s))) for s in steps.values())
    assert sum(map(len, steps.values())) >= seen
    # What is left is named incomplete, and render will not take it for a result.
    info = bag_tool("cli", "info", str(tmp_path / "fixed"))
    assert "INCOMPLETE" in info.stdout and "the run's result is not in the bag" in info.stdout
    refused = bag_tool("render", str(tmp_path / "fixed"), "--out", str(tmp_path / "r"))
    assert refused.returncode == 1 and "is incomplete" in refused.stderr


@pytest.mark.slow(SWARM)
def test_a_recorder_started_before_a_run_records_all_of_it_and_stops_at_its_end(tmp_path):
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain())}
    options = ["--rows", "4", "--cols", "5", "--pattern", "forest", "--seed", "3"]
    recorder = subprocess.Popen(
        [sys.executable, "-m", "camo_bag.recorder_node", str(tmp_path / "bag")],
        cwd=ROOT,
        env=env,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        time.sleep(4)  # the recorder waits for a run to appear
        run = subprocess.run(
            [sys.executable, "-m", "camo_bringup.launcher", *options, "--procs", "2"]
            + ["--out", str(tmp_path / "live")],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            timeout=240,
        )
        assert run.returncode == 0, run.stderr[-2000:]
        _, said = finished(recorder, 60)  # it ends by itself
    finally:
        if recorder.poll() is None:
            recorder.kill()
    assert recorder.returncode == 0 and "is complete" in said, said[-2000:] + run.stderr[-3000:]
    rendered = bag_tool("render", str(tmp_path / "bag"), "--out", str(tmp_path / "again"))
    assert rendered.returncode == 0, rendered.stderr
    live = json.loads((tmp_path / "live" / "summary.json").read_text())
    again = json.loads((tmp_path / "again" / "summary.json").read_text())
    assert {k: v for k, v in again.items() if k != "elapsed_s"} == {
        k: v for k, v in live.items() if k != "elapsed_s"
    }


@pytest.mark.slow(SWARM)
def test_ctrl_c_during_a_recorded_run_leaves_a_complete_indexed_bag(tmp_path):
    from camo_bag.loader import read_summary

    proc = start_run(
        "--pattern",
        "forest",
        "--procs",
        "1",
        "--rows",
        "4",
        "--cols",
        "4",
        "--consensus-steps",
        "30000",  # long enough to be seen in consensus: 16 robots take thousands a second
        "--run-id",
        "ctrlc",
        "--out",
        str(tmp_path / "run"),
        "--record",
        str(tmp_path / "bag"),
    )
    wait_for_line(proc, "consensus 16")
    seen = recorded_so_far(tmp_path / "bag", "/vote", 2, proc)
    proc.send_signal(signal.SIGINT)
    _, err = finished(proc, 60)
    assert proc.returncode == 130 and "Traceback" not in err, err
    summary = read_summary(tmp_path / "bag")
    counts = {t.name: t.count for t in summary.topics}
    votes = sum(n for name, n in counts.items() if name.endswith("/vote"))
    assert votes >= seen and counts["/ctrlc/swarm/params"] == 1
    assert len(robot_messages_in(tmp_path / "bag", "/vote")) >= votes
    assert (tmp_path / "bag" / "metadata.yaml").exists()


@pytest.mark.slow(SWARM)
def test_recording_into_an_existing_bag_is_refused_before_anything_starts(tmp_path):
    (tmp_path / "bag").mkdir()
    (tmp_path / "bag" / "x").write_text("keep me")
    out = camo_run(
        "--rows",
        "3",
        "--cols",
        "3",
        "--record",
        str(tmp_path / "bag"),
        "--out",
        str(tmp_path / "o"),
    )
    assert out.returncode == 2 and "already exists" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1
    assert (tmp_path / "bag" / "x").read_text() == "keep me"
    for args in ([str(tmp_path / "bag")], []):
        out = bag_tool("recorder_node", *args)
        assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert (tmp_path / "bag" / "x").read_text() == "keep me"


# ---- every option with bad values (issue 27) -------------------------------------------------


def test_every_option_of_record_with_a_bad_value_is_one_line_and_exit_2(
    tmp_path, monkeypatch, capsys
):
    from support import bad_values_of_a_ros_tool

    import camo_bag.recorder_node as command

    monkeypatch.chdir(tmp_path)
    options, problems = bad_values_of_a_ros_tool(command, ["bag"], monkeypatch, capsys)
    assert len(options) >= 4
    assert problems == []


@pytest.mark.slow(SWARM)
def test_recording_named_topics_without_a_run_records_them_and_ends_on_ctrl_c(tmp_path):
    import rclpy
    from std_msgs.msg import String
    from support import ros_context

    from camo_bag.loader import open_bag

    bag = tmp_path / "bag"
    domain_id = domain()
    proc = subprocess.Popen(
        [sys.executable, "-m", "camo_bag.recorder_node", str(bag), "--topics", "/lab/note"],
        env={**os.environ, "ROS_DOMAIN_ID": str(domain_id)},
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        wait_for_line(proc, "recording", timeout=60)
        with ros_context(domain_id) as context:
            node = rclpy.create_node("noter", context=context)
            publisher = node.create_publisher(String, "/lab/note", 10)
            for _ in range(30):  # while the recorder finds the topic
                publisher.publish(String(data="hello"))
                time.sleep(0.2)
            node.destroy_node()
    finally:
        proc.send_signal(signal.SIGINT)
        _, err = finished(proc, 60)
    assert proc.returncode == 0, err[-2000:]
    counts = {t.name: t.count for t in open_bag(bag).summary.topics}
    assert counts.get("/lab/note", 0) >= 1, counts
    bad = bag_tool("recorder_node", str(tmp_path / "b2"), "--topics", "{run}/x")
    assert bad.returncode == 2 and bad.stderr.strip().splitlines() == [
        "recorder_node: error: --topics '{run}/x' is not a ROS topic name: unknown "
        "substitution: {run}"
    ]


def test_stop_signals_after_the_bag_is_closed_leave_the_recorders_exit_status_zero(tmp_path):
    """A launcher stops its recorder as the run ends, when the recorder may be ending by
    itself: a SIGINT that reaches it while the interpreter tears down must not turn a
    complete bag into a recording that failed (exit status: killed by SIGINT)."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "camo_bag.recorder_node", str(tmp_path / "bag"), "--topics", "/x"],
        env={**os.environ, "ROS_DOMAIN_ID": str(domain())},
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        wait_for_line(proc, "recording", timeout=60)
        while proc.poll() is None:  # Ctrl-C, then again and again until it has exited
            proc.send_signal(signal.SIGINT)
            time.sleep(0.001)
    finally:
        _, err = finished(proc, 60)
    assert proc.returncode == 0, err[-2000:]
    assert "recorder_node: wrote 0 messages on 0 topics" in err


def test_a_recorder_names_its_run_in_the_bag_before_discovery_shows_any_topic(tmp_path):
    """Killed before discovery showed the run's topics (a loaded machine), the recorder still
    leaves a bag that `bag info` calls the run's and incomplete, not a stranger's."""
    from support import ros_context

    from camo_bag.recorder_node import RecorderNode
    from camo_nodes.topics.names import RunTopics

    run = RunTopics("run_abc123")
    with ros_context() as context:
        node = RecorderNode(str(tmp_path / "bag"), run, context=context)
        assert run.params in node.bag.topics  # nobody publishes: discovery shows nothing
        node.close()
        node.destroy_node()
    info = bag_tool("cli", "info", str(tmp_path / "bag"))
    assert info.returncode == 0, info.stderr
    assert "INCOMPLETE" in info.stdout and "parameters" in info.stdout, info.stdout
