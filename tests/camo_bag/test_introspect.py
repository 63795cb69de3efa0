"""`./camo topic` and `./camo node`: ros2cli's conventions over rclpy's graph API."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time

import pytest
from support import COMPUTE, ROOT, SWARM, bag_tool, domain, finished

TALKER = """
import sys, rclpy
from std_msgs.msg import String
rclpy.init()
node = rclpy.create_node("talker", namespace="/lab")
pub = node.create_publisher(String, "/chatter", 10)
node.create_timer(0.1, lambda: pub.publish(String(data="hello")))
print("ready", flush=True)
rclpy.spin(node)
"""


@pytest.fixture
def talker():
    domain_id = str(domain())
    env = {"ROS_DOMAIN_ID": domain_id, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    proc = subprocess.Popen(
        [sys.executable, "-c", TALKER],
        env={**os.environ, **env},
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    assert proc.stdout.readline().strip() == "ready"
    yield domain_id
    proc.kill()
    proc.wait()


def camo(*args: str) -> subprocess.CompletedProcess:
    return bag_tool("introspect", *args)


@pytest.mark.slow(COMPUTE)
def test_topic_list_shows_names_and_types_as_ros2_does(talker):
    out = camo("topic", "list", "-t", "--domain-id", talker)
    assert out.returncode == 0, out.stderr
    assert "/chatter [std_msgs/msg/String]" in out.stdout.splitlines()
    names = camo("topic", "list", "--domain-id", talker).stdout.splitlines()
    assert "/chatter" in names and names == sorted(names)


@pytest.mark.slow(COMPUTE)
def test_topic_echo_once_prints_the_message_as_yaml(talker):
    out = camo("topic", "echo", "/chatter", "--once", "--domain-id", talker)
    assert out.returncode == 0, out.stderr
    assert out.stdout == "data: hello\n---\n"


@pytest.mark.slow(SWARM)
def test_topic_hz_measures_the_rate(talker):
    proc = subprocess.Popen(
        [sys.executable, "-m", "camo_bag.introspect", "topic", "hz", "/chatter"]
        + ["--domain-id", talker],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    time.sleep(5.0)
    proc.send_signal(signal.SIGINT)
    out, err = finished(proc, 30)
    rates = [float(r) for r in re.findall(r"average rate: ([0-9.]+)", out)]
    assert rates, out + err
    assert 7.0 < rates[-1] < 13.0  # the talker publishes at 10 Hz


@pytest.mark.slow(COMPUTE)
def test_node_list_names_nodes_with_their_namespace(talker):
    out = camo("node", "list", "--domain-id", talker)
    assert out.returncode == 0, out.stderr
    assert "/lab/talker" in out.stdout.splitlines()
    assert not any("_camo" in line for line in out.stdout.splitlines())


@pytest.mark.slow(COMPUTE)
def test_a_topic_nobody_publishes_is_one_line():
    out = camo("topic", "echo", "/nothing", "--wait", "1", "--domain-id", str(domain()))
    assert out.returncode == 2
    assert "topic /nothing does not appear to be published yet" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1


# ---- every option with bad values (issue 27) -------------------------------------------------


@pytest.mark.parametrize("verb", ["echo", "hz"])
def test_every_option_of_topic_with_a_bad_value_is_one_line_and_exit_2(
    verb, tmp_path, monkeypatch, capsys
):
    from support import bad_values_of_a_ros_tool

    import camo_bag.introspect as command

    monkeypatch.chdir(tmp_path)
    options, problems = bad_values_of_a_ros_tool(
        command, ["topic", verb, "/x"], monkeypatch, capsys
    )
    assert "--wait" in options
    assert problems == []
