"""The live view: a run served to Foxglove, read by a client built from Foxglove's own libraries
(@foxglove/ws-protocol and @foxglove/rosmsg2-serialization, installed pinned with `npm ci`)."""

from __future__ import annotations

import json
import socket
import subprocess

import pytest
from support import FOXGLOVE_CLIENT as CLIENT
from support import (
    ROOT,
    SWARM,
    assert_like_sim,
    finished,
    run_camo,
    start_run,
    wait_for_line,
)

OPTIONS = ["--pattern", "forest", "--rows", "6", "--cols", "6", "--consensus-steps", "3000"]


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.mark.slow(SWARM)
def test_foxglove_client_lists_subscribes_and_decodes_a_live_run(tmp_path, foxglove_client):
    port = free_port()
    run = start_run(
        *OPTIONS, "--procs", "2", "--foxglove", str(port), "--out", str(tmp_path / "run")
    )
    try:
        wait_for_line(run, f"ws://127.0.0.1:{port}")
        wanted = ["/camo/background", "/swarm/status", "/swarm/params", "/edge/vote"]
        client = subprocess.run(
            [foxglove_client, "client.mjs", f"ws://127.0.0.1:{port}", "60", *wanted],
            cwd=CLIENT,
            capture_output=True,
            text=True,
            timeout=120,
        )
        _, err = finished(run, 240)
    finally:
        run.kill()
    assert client.returncode == 0, client.stdout[-3000:] + client.stderr[-2000:]
    seen = json.loads(client.stdout)
    assert seen["errors"] == []
    channels = {c["topic"]: c for c in seen["channels"]}
    assert all(
        c["encoding"] == "cdr" and c["schemaEncoding"] == "ros2msg" for c in channels.values()
    )
    (background,) = [t for t in channels if t.endswith("/camo/background")]
    assert channels[background]["schemaName"] == "sensor_msgs/msg/Image"
    assert any(c["schemaName"] == "camo_msgs/msg/Votes" for c in channels.values())
    decoded = {topic.split("/", 2)[2]: value for topic, value in seen["decoded"].items()}
    image = decoded["camo/background"]
    assert image["encoding"] in ("mono8", "bgr8") and image["width"] > 0
    assert image["data"]["length"] == image["step"] * image["height"]
    status = decoded["swarm/status"]  # a process's robots' statuses, a column per field
    assert (
        status["sender_id"]["length"] >= 1
        and status["p"]["length"] == 3 * status["sender_id"]["length"]
    )
    assert json.loads(decoded["swarm/params"]["data"])["params"]["rows"] == 6
    votes = [v for topic, v in decoded.items() if topic.endswith("/edge/vote")]  # as columns
    assert votes and all(v["phase"] == 2 and v["sender_id"]["length"] >= 1 for v in votes)
    assert all(v["p"]["length"] == 3 * v["sender_id"]["length"] for v in votes)
    assert all(v["step"] == v["round"] == v["degree"] == v["sender_id"] for v in votes)
    # Watching changed nothing: the run is the simulator's.
    assert run.returncode == 0, err[-2000:]
    assert "camo view: forwarded" in err
    sim = run_camo("sim", *OPTIONS, "--out", str(tmp_path / "sim"))
    assert sim.returncode == 0, sim.stderr
    assert_like_sim(tmp_path / "run", tmp_path / "sim")


@pytest.mark.slow(SWARM)
def test_a_view_started_first_serves_at_once_and_follows_runs_as_they_come(
    tmp_path, foxglove_client
):
    import os
    import sys

    from support import domain

    domain_id = domain()
    port = free_port()
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
    view = subprocess.Popen(
        [sys.executable, "-m", "camo_bag.view_node", "--port", str(port)],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        wait_for_line(view, f"serving on ws://127.0.0.1:{port}", timeout=30)
        for run_id in ("first", "second"):
            # Connected before the run starts: its channels are advertised as they appear.
            client = subprocess.Popen(
                [foxglove_client, "client.mjs", f"ws://127.0.0.1:{port}", "90",
                 f"/{run_id}/swarm/params", f"/{run_id}/swarm/status"],
                cwd=CLIENT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            )  # fmt: skip
            run = start_run(
                *OPTIONS, "--run-id", run_id, "--out", str(tmp_path / run_id),
                domain_id=domain_id,
            )  # fmt: skip
            seen_out, _ = client.communicate(timeout=120)
            _, err = finished(run, 240)
            assert run.returncode == 0, err[-2000:]
            assert client.returncode == 0, seen_out[-2000:]
            decoded = json.loads(seen_out)["decoded"]
            assert json.loads(decoded[f"/{run_id}/swarm/params"]["data"])["run"] == run_id
        assert view.poll() is None  # still serving, for the next run
    finally:
        view.send_signal(2)
        _, err = finished(view, 30)
    assert "Traceback" not in err


@pytest.mark.slow(SWARM)
def test_clients_subscription_changes_are_taken_a_bounded_number_a_turn():
    from camo_bag.view_node import CHANGES_PER_TURN, Subscribers, ViewNode

    view = object.__new__(ViewNode)  # no server: what follow_clients reads, a topic not offered
    view.listener, view.watchers, view.taken, view.offered = Subscribers(), {}, {}, {}
    channel = type("Channel", (), {"topic": "/run/swarm/status"})()
    for _ in range(2 * CHANGES_PER_TURN + 3):
        view.listener.on_subscribe(None, channel)
    counted = []
    for _ in range(4):
        view.follow_clients()
        counted.append(view.watchers["/run/swarm/status"])
    assert counted == [CHANGES_PER_TURN, 2 * CHANGES_PER_TURN, *[2 * CHANGES_PER_TURN + 3] * 2]


def test_a_port_in_use_is_one_line(tmp_path):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        run = start_run(
            *OPTIONS, "--procs", "1", "--foxglove", str(port), "--out", str(tmp_path / "run")
        )
        _, err = finished(run, 240)
    assert run.returncode != 0
    assert "Traceback" not in err
    assert f"camo view: error: cannot serve Foxglove on 127.0.0.1:{port}" in err


def test_the_foxglove_layout_opens_topics_a_run_called_demo_has():
    import re

    from camo_nodes.topics.names import RunTopics

    layout = json.loads((ROOT / "docs" / "foxglove" / "camo_layout.json").read_text())
    run = RunTopics("demo")
    published = {run.background, run.pattern, run.markers, run.status, run.diagnostics}
    named = set()

    def walk(value):
        if isinstance(value, dict):
            for key, inner in value.items():
                walk(key)
                walk(inner)
        elif isinstance(value, list):
            for inner in value:
                walk(inner)
        elif isinstance(value, str) and value.startswith("/demo/"):
            named.add(re.split(r"[{.]", value)[0])  # a message path's topic

    walk(layout["configById"])
    assert named == published
    panels = set()

    def tiles(node):
        if isinstance(node, str):
            panels.add(node)
        else:
            tiles(node["first"])
            tiles(node["second"])

    tiles(layout["layout"])
    assert panels == set(layout["configById"])


# ---- every option with bad values (issue 27) -------------------------------------------------


def test_every_option_of_view_with_a_bad_value_is_one_line_and_exit_2(
    tmp_path, monkeypatch, capsys
):
    from support import bad_values_of_a_ros_tool

    import camo_bag.view_node as command

    monkeypatch.chdir(tmp_path)
    options, problems = bad_values_of_a_ros_tool(command, [], monkeypatch, capsys)
    assert len(options) >= 4
    assert problems == []


def test_exit_with_run_without_a_run_id_is_one_line(capsys):
    from camo_bag import view_node

    assert view_node.main(["--exit-with-run"]) == 2
    err = capsys.readouterr().err
    assert err.strip() == "camo view: error: --exit-with-run needs --run-id: the run to end with"
