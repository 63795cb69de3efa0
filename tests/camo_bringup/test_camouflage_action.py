"""The run's Camouflage action, driven by the client docs/ros.md shows: a goal without an image
gets the round the swarm has done, one with an image makes a continuous swarm camouflage it.
Driven without ROS: how many goals it keeps open, and what it does for them in a turn."""

import os
import re
import subprocess
import sys
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
from support import ROOT, SWARM, domain, finished, start_run, wait_for_line

from camo_bringup.camouflage_action import MAX_OPEN, CamouflageAction, OpenGoal
from camo_core.algorithm.backgrounds import background
from camo_core.results.record import Backgrounds
from camo_nodes.topics.images import image_to_msg


def client_script(tmp_path) -> str:
    """The client of docs/ros.md, as a file."""
    text = (ROOT / "docs" / "ros.md").read_text()
    code = re.search(r"<!-- camouflage_client\.py.*?-->\n```python\n(.*?)```", text, re.S)
    assert code, "docs/ros.md has no camouflage_client.py block"
    path = tmp_path / "camouflage_client.py"
    path.write_text(code.group(1))
    return str(path)


def client(script: str, domain_id: int, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
    return subprocess.run(
        [sys.executable, script, *args], env=env, capture_output=True, text=True, timeout=120
    )


@pytest.mark.slow(SWARM)
def test_the_docs_client_follows_a_goal_of_a_continuous_run_to_its_result(tmp_path):
    domain_id = domain()
    script = client_script(tmp_path)
    desert = tmp_path / "desert.png"
    cv2.imwrite(str(desert), background("desert"))
    proc = start_run(
        "--continuous", "--rounds", "2", "--consensus-steps", "400", "--run-id", "goals",
        "--out", str(tmp_path / "run"), domain_id=domain_id,
    )  # fmt: skip
    try:
        wait_for_line(proc, "topics under")
        now = client(script, domain_id, "goals")  # no image: the round under way, or done
        assert now.returncode == 0, now.stderr
        assert re.search(r"^round 0 \(frame 0\): vertical \(", now.stdout, re.M), now.stdout
        assert "robots per phase" in now.stdout  # feedback while it waited
        goal = client(script, domain_id, "goals", str(desert))
        assert goal.returncode == 0, goal.stderr
        assert re.search(r"^round 1 \(frame [1-9]\d*\): horizontal \(", goal.stdout, re.M)
        _, err = finished(proc, 120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err[-2000:]
    assert (tmp_path / "run" / "goals" / "goal_0.png").exists()


@pytest.mark.slow(SWARM)
def test_a_run_without_continuous_refuses_a_goal_with_an_image(tmp_path):
    domain_id = domain()
    script = client_script(tmp_path)
    desert = tmp_path / "desert.png"
    cv2.imwrite(str(desert), background("desert"))
    proc = start_run(
        "--consensus-steps", "20000", "--run-id", "fixed", "--out", str(tmp_path / "run"),
        domain_id=domain_id,
    )  # fmt: skip
    try:
        wait_for_line(proc, "topics under")
        goal = client(script, domain_id, "fixed", str(desert))
        assert goal.returncode == 1 and "refused the goal" in goal.stderr, goal.stderr
    finally:
        proc.send_signal(2)
        _, err = finished(proc, 60)
    assert "no --continuous" in err


class Handle:
    """rclpy's ServerGoalHandle, as far as the action uses it."""

    def __init__(self, image=None) -> None:
        from sensor_msgs.msg import Image

        self.request = SimpleNamespace(image=image or Image())
        self.is_cancel_requested = False
        self.ended = None

    def abort(self) -> None:
        self.ended = "aborted"

    def publish_feedback(self, feedback) -> None:
        pass


def action_of(tmp_path) -> CamouflageAction:
    """The action with what its callbacks and update() use: a projector listening on the load
    topic (the paths it was sent in `loaded`), a monitor that has heard no round."""
    action = object.__new__(CamouflageAction)
    action.loaded = []
    loader = SimpleNamespace(get_subscription_count=lambda: 1, publish=action.loaded.append)
    monitor = SimpleNamespace(images=Backgrounds(), heard=set(), closed=set())
    node = SimpleNamespace(get_logger=lambda: SimpleNamespace(warning=lambda text: None))
    action.session = SimpleNamespace(loader=loader, monitor=monitor, node=node)
    action.executor = SimpleNamespace(spin_once=lambda timeout_sec: None)
    action.folder, action.open, action.done = tmp_path / "goals", [], []
    action._numbers = iter(range(100))
    return action


def test_a_goal_beyond_the_open_ones_is_aborted_at_once_saying_why(tmp_path):
    from rclpy.action import GoalResponse

    action = action_of(tmp_path)
    action.open = [OpenGoal(Handle(), None, None) for _ in range(MAX_OPEN)]
    handle = Handle(image=image_to_msg(np.full((16, 16), 90, np.uint8)))
    action.continuous = False  # a goal with an image would be refused, which says nothing
    assert action._goal(handle.request) == GoalResponse.ACCEPT  # to be aborted with a message
    execution = action._execute(handle)
    with pytest.raises(StopIteration) as ended:  # it never waits: its result is there at once
        execution.send(None)
    result = ended.value.value
    assert handle.ended == "aborted" and not result.success
    assert f"{MAX_OPEN} goals are open already" in result.message
    assert len(action.open) == MAX_OPEN


def test_goals_images_are_written_and_projected_one_a_turn(tmp_path):
    action = action_of(tmp_path)
    image = np.full((16, 16), 90, np.uint8)
    action.open = [OpenGoal(Handle(), None, image) for _ in range(3)]
    sent = []
    for _ in range(4):
        action.update()
        sent.append(len(action.loaded))
    assert sent == [1, 2, 3, 3]
    assert sorted(p.name for p in action.folder.iterdir()) == [f"goal_{k}.png" for k in range(3)]
    assert len(action.open) == 3 and all(goal.sent is not None for goal in action.open)
