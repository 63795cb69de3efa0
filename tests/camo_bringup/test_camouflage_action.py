"""The run's Camouflage action, driven by the client docs/ros.md shows: a goal without an image
gets the round the swarm has done, one with an image makes a continuous swarm camouflage it.
Driven without ROS: how many goals it keeps open, and what it does for them in a turn."""

import json
import os
import re
import subprocess
import sys
import time
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
from support import ROOT, SWARM, domain, finished, start_run, wait_for_line

from camo_bringup.camouflage_action import MAX_OPEN, CamouflageAction, OpenGoal
from camo_core.algorithm.backgrounds import background
from camo_core.results.record import Backgrounds
from camo_core.swarm.keys import KEY_FILE_ENV, NO_TAG, new_key_file
from camo_nodes.topics import keyed
from camo_nodes.topics.images import image_to_msg


def client_script(tmp_path) -> str:
    """The client of docs/ros.md, as a file."""
    text = (ROOT / "docs" / "ros.md").read_text()
    code = re.search(r"<!-- camouflage_client\.py.*?-->\n```python\n(.*?)```", text, re.S)
    assert code, "docs/ros.md has no camouflage_client.py block"
    path = tmp_path / "camouflage_client.py"
    path.write_text(code.group(1))
    return str(path)


def client(script: str, domain_id: int, key, *args: str) -> subprocess.CompletedProcess:
    """The docs client, with the run's `key` file (None: without one)."""
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
    env.pop(KEY_FILE_ENV, None)
    if key is not None:
        env[KEY_FILE_ENV] = str(key)
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
        key = tmp_path / "run" / "run.key"  # the run's own, made as it started
        stranger = client(script, domain_id, None, "goals", str(desert))
        assert stranger.returncode == 1 and "refused the goal" in stranger.stderr
        now = client(script, domain_id, key, "goals")  # no image: the round under way, or done
        assert now.returncode == 0, now.stderr
        assert re.search(r"^round 0 \(frame 0\): vertical \(", now.stdout, re.M), now.stdout
        assert "robots per phase" in now.stdout  # feedback while it waited
        goal = client(script, domain_id, key, "goals", str(desert))
        assert goal.returncode == 0, goal.stderr
        assert re.search(r"^round 1 \(frame [1-9]\d*\): horizontal \(", goal.stdout, re.M)
        _, err = finished(proc, 120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err[-2000:]
    assert (tmp_path / "run" / "goals" / "goal_0.png").exists()
    refused = json.loads((tmp_path / "run" / "round_0" / "summary.json").read_text())
    assert refused["rejected_messages"]["by_reason"].get(NO_TAG) == 1, refused


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
        goal = client(script, domain_id, tmp_path / "run" / "run.key", "fixed", str(desert))
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
    action.keys = keyed.GoalCheck("r")  # no key in this process: every goal passes it
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


def test_the_action_keeps_a_bounded_number_of_rounds_however_many_are_written(tmp_path):
    # Every round's summary (grids of every robot's values) was kept for as long as the run went.
    from types import SimpleNamespace

    import numpy as np
    import rclpy
    from support import ros_context

    from camo_bringup.camouflage_action import DONE_KEPT, CamouflageAction, OpenGoal
    from camo_core.algorithm.params import CamoParams
    from camo_core.results.record import Backgrounds
    from camo_nodes.topics.names import RunTopics

    with ros_context() as context:
        node = rclpy.create_node("launcher", context=context)
        config = SimpleNamespace(
            continuous=True,
            folder=tmp_path,
            topics=RunTopics("bounded"),
            params=CamoParams(rows=4, cols=4),
        )
        monitor = SimpleNamespace(images=Backgrounds(), heard=set(), closed=set())
        session = SimpleNamespace(config=config, node=node, monitor=monitor)
        action = CamouflageAction(session)
        for frame in range(500):
            monitor.images.add((frame, 0), lambda: np.zeros((8, 8), np.uint8), frame)
            action.written(frame, frame, {"pattern": "vertical", "sensed": [[0.0] * 4] * 4})
        assert len(action.done) == DONE_KEPT and len(action._grids) <= DONE_KEPT
        late = OpenGoal(handle=None, future=None, image=None)  # no image: the latest round
        assert action._round_for(late)[:2] == (499, 499)
        action.close()
        node.destroy_node()


@pytest.mark.slow(SWARM)
def test_a_goal_showing_the_scene_camouflaged_already_gets_its_round(tmp_path):
    # No robot notices a frame that reads as its round's: the goal was aborted after 120 s.
    domain_id = domain()
    script = client_script(tmp_path)
    forest = tmp_path / "forest.png"
    cv2.imwrite(str(forest), background("forest"))  # the run's own scene, as bgr8
    proc = start_run(
        "--continuous", "--duration", "60", "--run-id", "same", "--out", str(tmp_path / "run"),
        domain_id=domain_id,
    )  # fmt: skip
    try:
        rounds = tmp_path / "run" / "rounds.csv"
        deadline = time.monotonic() + 90
        while not rounds.exists():  # round 0 written
            assert time.monotonic() < deadline and proc.poll() is None, "no round 0"
            time.sleep(0.2)
        sent = time.monotonic()
        key = tmp_path / "run" / "run.key"
        goal = client(script, domain_id, key, "same", str(forest))
        assert goal.returncode == 0, goal.stderr
        assert re.search(r"^round 0 \(frame 0\): vertical \(", goal.stdout, re.M), goal.stdout
        now = client(script, domain_id, key, "same")  # no image: the round of the scene shown
        assert re.search(r"^round 0 \(frame 0\): vertical \(", now.stdout, re.M), now.stdout
        assert time.monotonic() - sent < 30
    finally:
        proc.send_signal(2)
        _, err = finished(proc, 60)
    assert "superseded" not in err and "round 1" not in err


def test_a_keyed_server_takes_a_goal_tagged_with_its_key_once(tmp_path, monkeypatch):
    from camo_msgs.action import Camouflage

    monkeypatch.setenv(KEY_FILE_ENV, str(new_key_file(tmp_path / "k").path))
    keyed.process_key.cache_clear()
    try:
        check = keyed.GoalCheck("lab")
        goal = keyed.tag_goal(Camouflage.Goal(image=image_to_msg(background("desert"))), "lab")
        assert len(goal.key_tag) == 32 and check.problem(goal) is None
        assert check.problem(goal) == "a goal sent again (its key tag was taken once)"
        assert check.problem(Camouflage.Goal()) == NO_TAG  # no tag
        other = keyed.tag_goal(Camouflage.Goal(), "another_run")
        assert check.problem(other) == NO_TAG
        changed = keyed.tag_goal(Camouflage.Goal(), "lab")
        changed.image.width = 4  # the tag covers the whole goal
        assert check.problem(changed) == NO_TAG
    finally:
        keyed.process_key.cache_clear()
