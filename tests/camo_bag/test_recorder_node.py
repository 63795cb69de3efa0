"""The recorder: complete bags of whole runs, Ctrl-C and SIGKILL mid-run, refused folders."""

import os
import signal
import subprocess
import sys
import time

from support import (
    ROOT,
    bag_tool,
    camo_run,
    domain,
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
    from camo_bag.container import BagError, salvage

    deadline = time.monotonic() + timeout
    while True:
        try:
            _, channels, messages, _ = salvage(bag)
        except BagError:  # not created, or its magic not yet flushed
            channels, messages = [], []
        wanted = {c.id for c in channels if c.topic.endswith(suffix)}
        seen = sum(m.channel_id in wanted for m in messages)
        if seen >= count:
            return seen
        assert writer.poll() is None, "the recording process ended early"
        assert time.monotonic() < deadline, (
            f"fewer than {count} {suffix} messages recorded in {timeout:g} s"
        )
        time.sleep(0.5)


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
    # 2x2 robots do thousands of steps a second: a long run is still going when the recorder is
    # killed.
    swarm = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "camo_nodes.launcher",
            "--rows",
            "2",
            "--cols",
            "2",
            "--consensus-steps",
            "40000",
            "--procs",
            "1",
            "--domain-id",
            str(domain_id),
            "--run-id",
            "k",
            "--out",
            str(tmp_path / "run"),
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        wait_for_line(swarm, "consensus 4")
        seen = recorded_so_far(tmp_path / "killed", "/vote", 200, recorder)
        assert swarm.poll() is None, "the run ended before the recorder was killed"
    finally:
        recorder.send_signal(signal.SIGKILL)
        recorder.wait()
        swarm.send_signal(signal.SIGINT)
        swarm.communicate(timeout=60)
    assert bag_tool("cli", "info", str(tmp_path / "killed")).returncode == 2
    out = bag_tool("cli", "repair", str(tmp_path / "killed"), "--out", str(tmp_path / "fixed"))
    assert out.returncode == 0, out.stderr
    steps: dict[int, list[int]] = {}
    with AnyReader([tmp_path / "fixed"]) as reader:
        votes = [c for c in reader.connections if c.topic.endswith("/vote")]
        assert votes, "no vote topic recovered"
        for connection, _, raw in reader.messages(connections=votes):
            msg = reader.deserialize(raw, connection.msgtype)
            steps.setdefault(msg.sender_id, []).append(msg.step)
    # Each finished chunk holds what arrived before it: a robot's votes from step 0 on, without
    # gaps (the recorder may lag a fast swarm, so not every robot need have reached a finished
    # chunk). A late joiner can get a live sample just before the history that precedes it, so
    # the order of the first few steps is not checked.
    assert set(steps) <= set(range(4)) and steps
    assert all(sorted(s) == list(range(len(s))) for s in steps.values())
    assert sum(map(len, steps.values())) >= seen


def test_ctrl_c_during_a_recorded_run_leaves_a_complete_indexed_bag(tmp_path):
    from camo_bag.container import read_summary

    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "camo_nodes.launcher",
            "--pattern",
            "forest",
            "--procs",
            "1",
            "--rows",
            "4",
            "--cols",
            "4",
            "--consensus-steps",
            "5000",
            "--domain-id",
            str(domain()),
            "--run-id",
            "ctrlc",
            "--out",
            str(tmp_path / "run"),
            "--record",
            str(tmp_path / "bag"),
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    wait_for_line(proc, "consensus 16")
    seen = recorded_so_far(tmp_path / "bag", "/vote", 2, proc)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and "Traceback" not in err, err
    summary = read_summary(tmp_path / "bag")
    counts = {t.name: t.count for t in summary.topics}
    votes = sum(n for name, n in counts.items() if name.endswith("/vote"))
    assert votes >= seen and counts["/ctrlc/swarm/params"] == 1
    assert (tmp_path / "bag" / "metadata.yaml").exists()


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
