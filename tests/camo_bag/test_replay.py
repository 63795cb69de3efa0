"""`camo replay`: recorded messages published again, with their QoS and timing."""

import json
import subprocess
import sys

import pytest
from support import (
    BAG_COLS,
    BAG_OPTIONS,
    BAG_ROWS,
    BAG_RUN,
    ROOT,
    SWARM,
    StatusListener,
    bag_tool,
    domain,
    finished,
    start_run,
)

from camo_core.swarm.keys import new_key_file


@pytest.mark.slow(SWARM)
def test_replaying_the_background_into_a_fresh_swarm_reproduces_the_run(recorded, tmp_path):
    bag, live = recorded
    domain_id = domain()
    key = str(new_key_file(tmp_path / "again.key").path)  # the fresh run's, given to the replay
    swarm = start_run(
        *BAG_OPTIONS,
        "--run-id",
        "again",  # the last --run-id counts: a run of its own, driven by the bag
        "--key-file",
        key,
        "--no-projector",
        "--out",
        str(tmp_path / "again"),
        domain_id=domain_id,
    )
    replay = bag_tool(
        "replay",
        str(bag),
        "--topics",
        f"/{BAG_RUN}/camo/background",
        "--run-id",
        "again",
        "--linger",
        "15",
        "--domain-id",
        str(domain_id),
        "--key-file",
        key,
    )
    assert replay.returncode == 0, replay.stderr
    assert "published 1 messages on 1 topics" in replay.stderr
    _, err = finished(swarm, 120)
    assert swarm.returncode == 0, err[-2000:]
    again = json.loads((tmp_path / "again" / "summary.json").read_text())
    for key in ("final", "initial", "sensed", "mean_p", "consensus_trace", "votes"):
        assert again[key] == live[key], key


@pytest.mark.slow(SWARM)
def test_replay_publishes_recorded_messages_with_their_qos(recorded):
    bag, live = recorded
    domain_id = domain()
    with StatusListener(domain_id, BAG_RUN) as listener:
        replay = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "camo_bag.replay",
                str(bag),
                "--rate",
                "20",
                "--linger",  # the statuses are latched: a listener discovered late gets them
                "6",
                "--topics",
                f"/{BAG_RUN}/swarm/status",
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
    assert [[done[i * BAG_COLS + j] for j in range(BAG_COLS)] for i in range(BAG_ROWS)] == live[
        "final"
    ]
