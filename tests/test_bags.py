"""Runs recorded to MCAP as rosbag2 writes them: read back by two independent readers, rendered,
replayed, repaired after a kill, and bad bags refused in one line."""

import json
import os
import re
import signal
import subprocess
import sys
import time

import pytest
from conftest import ROOT, StatusListener, camo_run, count_round_records, domain, wait_for_line

ROWS, COLS = 5, 6
OPTIONS = [
    "--pattern",
    "forest",
    "--profile",
    "droplet",
    "--rows",
    str(ROWS),
    "--cols",
    str(COLS),
    "--rho-comm",
    "0.2",
    "--rho-meas",
    "0.1",
    "--seed",
    "4",
    "--procs",
    "2",
]
STEPS = 10  # droplet consensus steps
FORMATION = 20  # droplet formation steps


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """One recorded run: (bag folder, live summary)."""
    folder = tmp_path_factory.mktemp("recorded")
    out = camo_run(*OPTIONS, "--out", str(folder / "live"), "--record", str(folder / "bag"))
    assert out.returncode == 0, out.stderr[-2000:]
    assert "recorded" in out.stderr and "lacks" not in out.stderr, out.stderr[-2000:]
    return folder / "bag", json.loads((folder / "live" / "summary.json").read_text())


def tool(module: str, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", f"camo_nodes.{module}", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
    )


def test_bag_is_a_rosbag2_folder_with_an_indexed_ros2_mcap(recorded):
    from mcap.reader import make_reader

    bag, _ = recorded
    assert sorted(p.name for p in bag.iterdir()) == ["bag_0.mcap", "metadata.yaml"]
    with open(bag / "bag_0.mcap", "rb") as stream:
        reader = make_reader(stream)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
    assert summary.chunk_indexes and all(c.compression == "zstd" for c in summary.chunk_indexes)
    assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
    vote = next(
        s for s in summary.schemas.values() if s.name == "camo_msgs/msg/Vote"
    ).data.decode()
    assert vote.startswith("# Phase 2 (consensus)")
    assert "\n" + "=" * 80 + "\nMSG: std_msgs/Header\n" in vote
    assert "\nMSG: builtin_interfaces/Time\n" in vote
    for channel in summary.channels.values():
        assert channel.message_encoding == "cdr"
        assert "reliability:" in channel.metadata["offered_qos_profiles"]
    background = next(c for c in summary.channels.values() if c.topic == "/camo/background")
    assert "durability: transient_local" in background.metadata["offered_qos_profiles"]


def test_mcap_ros2_decoder_reads_every_robot_message(recorded):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    bag, live = recorded
    votes, final, publish_before_log = {}, {}, True
    with open(bag / "bag_0.mcap", "rb") as stream:
        for schema, channel, message, msg in make_reader(
            stream, decoder_factories=[DecoderFactory()]
        ).iter_decoded_messages():
            if channel.topic.endswith("/vote"):
                assert channel.topic == f"/camo/robot_{msg.sender_id}/vote"
                assert abs(sum(msg.p) - 1.0) < 1e-9
                votes.setdefault(msg.sender_id, []).append(msg.step)
            elif channel.topic == "/swarm/status" and msg.phase == 4:
                final[(msg.row, msg.col)] = msg.state
            publish_before_log &= message.publish_time <= message.log_time
    # Loss is drawn where a message is received, so every robot publishes every step's vote.
    assert sorted(votes) == list(range(ROWS * COLS))
    assert all(sorted(steps) == list(range(STEPS)) for steps in votes.values())
    assert [[final[(i, j)] for j in range(COLS)] for i in range(ROWS)] == live["final"]
    assert publish_before_log


def test_rosbags_anyreader_reads_the_bag_folder(recorded):
    from rosbags.highlevel import AnyReader

    bag, live = recorded
    with AnyReader([bag]) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        counts = {c.topic: c.msgcount for c in reader.connections}
        assert types["/camo/background"] == "sensor_msgs/msg/Image"
        assert types["/camo/robot_0/state"] == "camo_msgs/msg/State"
        assert counts["/camo/robot_7/state"] == FORMATION and counts["/camo/robot_7/hello"] == 1
        colors = [c for c in reader.connections if c.topic.endswith("/color")]
        sensed = {}
        for connection, _, raw in reader.messages(connections=colors):
            msg = reader.deserialize(raw, connection.msgtype)
            sensed[msg.sender_id] = msg.value
    assert [[sensed[i * COLS + j] for j in range(COLS)] for i in range(ROWS)] == live["sensed"]


def test_bag_info_lists_topics_types_and_counts(recorded):
    bag, _ = recorded
    out = tool("bag_cli", "info", str(bag))
    assert out.returncode == 0, out.stderr
    assert "Duration:" in out.stdout and "Storage id:        mcap" in out.stdout
    line = next(x for x in out.stdout.splitlines() if "/camo/robot_3/vote " in x)
    assert "Type: camo_msgs/msg/Vote" in line and f"Count: {STEPS} " in line


def test_render_reads_a_bag_into_one_record_per_round(recorded, monkeypatch):
    from camo_nodes.render import load_run

    made = count_round_records(monkeypatch)
    run = load_run(recorded[0])
    assert list(run.rounds) == [0] and len(made) == 1
    assert run.rounds[0].finished.all()


def test_render_rebuilds_the_live_summary_from_the_bag_alone(recorded, tmp_path):
    bag, live = recorded
    out = tool("render", str(bag), "--out", str(tmp_path))
    assert out.returncode == 0, out.stderr
    rendered = json.loads((tmp_path / "summary.json").read_text())
    assert {k: v for k, v in rendered.items() if k != "elapsed_s"} == {
        k: v for k, v in live.items() if k != "elapsed_s"
    }
    assert (tmp_path / "figure.png").stat().st_size > 10_000
    assert (tmp_path / "timeline.png").stat().st_size > 10_000


def test_render_of_a_run_with_three_backgrounds_writes_each_round_from_a_complete_bag(tmp_path):
    # A small swarm finishes a round in a fraction of a second, before the recorder may have
    # discovered its topics; each round must still be in the bag whole.
    out = camo_run(
        "--rows",
        "4",
        "--cols",
        "5",
        "--pattern",
        "forest",
        "--then",
        "desert",
        "--then",
        "forest",
        "--procs",
        "1",
        "--out",
        str(tmp_path / "live"),
        "--record",
        str(tmp_path / "bag"),
    )
    assert out.returncode == 0 and "lacks" not in out.stderr, out.stderr[-2000:]
    rendered = tool("render", str(tmp_path / "bag"), "--out", str(tmp_path / "rendered"))
    assert rendered.returncode == 0, rendered.stderr
    for k in (0, 1, 2):
        live = json.loads((tmp_path / "live" / f"round_{k}" / "summary.json").read_text())
        again = json.loads((tmp_path / "rendered" / f"round_{k}" / "summary.json").read_text())
        assert {x: v for x, v in again.items() if x != "elapsed_s"} == {
            x: v for x, v in live.items() if x != "elapsed_s"
        }
        assert (tmp_path / "rendered" / f"round_{k}" / "timeline.png").exists()
    assert "round 2: pattern" in rendered.stdout
    info = tool("bag_cli", "info", str(tmp_path / "bag"))
    assert info.returncode == 0, info.stderr
    consensus_steps = len(live["consensus_trace"]) - 1
    votes = sum(
        int(count)
        for count in re.findall(r"/vote +\| Type: camo_msgs/msg/Vote \| Count: (\d+)", info.stdout)
    )
    assert votes == 3 * 4 * 5 * consensus_steps


def test_replaying_the_background_into_a_fresh_swarm_reproduces_the_run(recorded, tmp_path):
    bag, live = recorded
    domain_id = domain()
    swarm = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "camo_nodes.launcher",
            *OPTIONS,
            "--no-projector",
            "--domain-id",
            str(domain_id),
            "--out",
            str(tmp_path / "again"),
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    replay = tool(
        "replay",
        str(bag),
        "--topics",
        "/camo/background",
        "--linger",
        "15",
        "--domain-id",
        str(domain_id),
    )
    assert replay.returncode == 0, replay.stderr
    assert "published 1 messages on 1 topics" in replay.stderr
    _, err = swarm.communicate(timeout=120)
    assert swarm.returncode == 0, err[-2000:]
    again = json.loads((tmp_path / "again" / "summary.json").read_text())
    for key in ("final", "initial", "sensed", "mean_p", "consensus_trace", "votes"):
        assert again[key] == live[key], key


def test_replay_publishes_recorded_messages_with_their_qos(recorded):
    bag, live = recorded
    domain_id = domain()
    with StatusListener(domain_id) as listener:
        replay = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "camo_nodes.replay",
                str(bag),
                "--rate",
                "20",
                "--topics",
                "/swarm/status",
                "--domain-id",
                str(domain_id),
            ],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        listener.spin_until(lambda: replay.poll() is not None, timeout=120)
        listener.spin_until(lambda: False, timeout=1.0)  # what is still on its way
        assert replay.wait(timeout=30) == 0, replay.stderr.read()
    done = listener.final_states()
    assert [[done[i * COLS + j] for j in range(COLS)] for i in range(ROWS)] == live["final"]


def test_truncated_and_foreign_files_get_one_line_errors(recorded, tmp_path):
    bag, _ = recorded
    data = (bag / "bag_0.mcap").read_bytes()
    cut = tmp_path / "cut"
    cut.mkdir()
    (cut / "cut_0.mcap").write_bytes(data[: len(data) * 2 // 3])
    foreign = tmp_path / "foreign.mcap"
    foreign.write_bytes(b"this is not a bag\n" * 50)
    for path, words in (
        (cut, "truncated"),
        (foreign, "not an MCAP file"),
        (tmp_path / "missing", "no such bag"),
    ):
        for command in (
            ["bag_cli", "info", str(path)],
            ["render", str(path), "--out", str(tmp_path / "r")],
            ["replay", str(path)],
        ):
            out = tool(*command)
            assert out.returncode == 2, (command, out.stderr)
            assert words in out.stderr and len(out.stderr.strip().splitlines()) == 1, (
                command,
                out.stderr,
            )
    out = tool("bag_cli", "repair", str(foreign))
    assert out.returncode == 2 and "not an MCAP file" in out.stderr


def test_render_refuses_a_bag_whose_messages_do_not_decode(tmp_path):
    from camo_nodes.bag import BagWriter, TopicInfo
    from camo_nodes.msgdefs import message_definition

    writer = BagWriter(tmp_path / "odd")
    for topic, kind in (
        ("/swarm/params", "std_msgs/msg/String"),
        ("/swarm/status", "camo_msgs/msg/RobotStatus"),
    ):
        writer.add_topic(TopicInfo(topic, kind), message_definition(kind))
        writer.write(topic, b"\x00\x01\x00\x00\xff\xff", 10**9, 10**9)
    writer.close()
    out = tool("render", str(tmp_path / "odd"), "--out", str(tmp_path / "r"))
    assert out.returncode == 2 and "does not decode" in out.stderr, out.stderr
    assert len(out.stderr.strip().splitlines()) == 1


def test_repair_keeps_every_complete_chunk_of_a_cut_file(tmp_path):
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from camo_nodes.bag import BagWriter, TopicInfo, read_messages
    from camo_nodes.msgdefs import message_definition

    writer = BagWriter(tmp_path / "whole")
    writer.add_topic(
        TopicInfo("/chatter", "std_msgs/msg/String"), message_definition("std_msgs/msg/String")
    )
    ends = []
    for chunk in range(6):
        for k in range(50):
            writer.write(
                "/chatter",
                serialize_message(String(data=f"{chunk}-{k}")),
                10**9 + chunk * 100 + k,
                0,
            )
        writer.flush()
        ends.append(writer.file.stat().st_size)
    writer.close()
    cut = tmp_path / "cut"
    cut.mkdir()
    (cut / "cut_0.mcap").write_bytes(
        (tmp_path / "whole" / "whole_0.mcap").read_bytes()[: ends[2] + 10]
    )
    out = tool("bag_cli", "repair", str(cut), "--out", str(tmp_path / "fixed"))
    assert out.returncode == 0, out.stderr
    assert "cut short" in out.stdout and "wrote 150 messages" in out.stdout
    texts = [deserialize(m.data) for m in read_messages(tmp_path / "fixed")]
    assert texts == [f"{c}-{k}" for c in range(3) for k in range(50)]


def deserialize(data: bytes) -> str:
    from rclpy.serialization import deserialize_message
    from std_msgs.msg import String

    return deserialize_message(data, String).data


def recorded_so_far(
    bag, suffix: str, count: int, writer: subprocess.Popen, timeout: float = 120
) -> int:
    """Wait until the finished chunks of a bag being written hold `count` messages on topics ending in
    `suffix` (a loaded machine can take seconds to discover topics); how many they hold."""
    from camo_nodes.bag import BagError, salvage

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
        [sys.executable, "-m", "camo_nodes.recorder_node", str(tmp_path / "killed")],
        cwd=ROOT,
        env=env,
        stderr=open(log, "w"),
    )
    while "recording to" not in log.read_text():
        assert recorder.poll() is None, log.read_text()
        time.sleep(0.1)
    # 2x2 robots do thousands of steps a second: a long run is still going when the recorder is killed.
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
    assert tool("bag_cli", "info", str(tmp_path / "killed")).returncode == 2
    out = tool("bag_cli", "repair", str(tmp_path / "killed"), "--out", str(tmp_path / "fixed"))
    assert out.returncode == 0, out.stderr
    steps: dict[int, list[int]] = {}
    with AnyReader([tmp_path / "fixed"]) as reader:
        votes = [c for c in reader.connections if c.topic.endswith("/vote")]
        assert votes, "no vote topic recovered"
        for connection, _, raw in reader.messages(connections=votes):
            msg = reader.deserialize(raw, connection.msgtype)
            steps.setdefault(msg.sender_id, []).append(msg.step)
    # Each finished chunk holds what arrived before it, in order: a robot's votes from step 0 on, without
    # gaps (the recorder may lag a fast swarm, so not every robot need have reached a finished chunk).
    assert set(steps) <= set(range(4)) and steps
    assert all(s == list(range(len(s))) for s in steps.values())
    assert sum(map(len, steps.values())) >= seen


def test_ctrl_c_during_a_recorded_run_leaves_a_complete_indexed_bag(tmp_path):
    from camo_nodes.bag import read_summary

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
    seen = recorded_so_far(tmp_path / "bag", "/camo/robot_0/vote", 2, proc)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and "Traceback" not in err, err
    summary = read_summary(tmp_path / "bag")
    counts = {t.name: t.count for t in summary.topics}
    assert counts["/camo/robot_0/vote"] >= seen and counts["/swarm/params"] == 1
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
        out = tool("recorder_node", *args)
        assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert (tmp_path / "bag" / "x").read_text() == "keep me"


def test_dockerfile_builds_on_ros_jazzy_and_copies_files_that_exist():
    dockerfile = ROOT / "docker" / "Dockerfile"
    lines = [line.strip() for line in dockerfile.read_text().splitlines()]
    assert lines[[line.startswith("FROM") for line in lines].index(True)].startswith(
        "FROM ros:jazzy"
    )
    assert "ros-jazzy-rosbag2-storage-mcap" in dockerfile.read_text()
    copies = [line.split()[1:-1] for line in lines if line.startswith("COPY")]
    assert copies
    for sources in copies:
        for source in sources:
            assert (ROOT / source).exists(), source
    for requirement in ("colcon build", "camo_nodes"):
        assert requirement in dockerfile.read_text()
