"""`camo bag info` and `camo bag repair` on recorded bags."""

import re

import pytest
from support import BAG_STEPS, SWARM, bag_tool, robot_messages_in


@pytest.mark.slow(SWARM)
def test_bag_info_lists_topics_types_and_counts(recorded):
    bag, _ = recorded
    out = bag_tool("cli", "info", str(bag))
    assert out.returncode == 0, out.stderr
    assert "Duration:" in out.stdout and "Storage id:        mcap" in out.stdout
    # The first process's tile holds robots 0-14: its edge and core vote topics hold 15 robots'
    # votes, BAG_STEPS each, several robots' votes in a message (as columns).
    lines = [x for x in out.stdout.splitlines() if "/tile_0_14/" in x and "/vote " in x]
    assert len(lines) == 2 and all("Type: camo_msgs/msg/Votes" in x for x in lines)
    counts = [int(re.search(r"Count: (\d+)", x).group(1)) for x in lines]
    assert sum(counts) < 15 * BAG_STEPS
    votes = sorted((v.sender_id, v.step) for v in robot_messages_in(bag, "/tile_0_14/edge/vote"))
    votes += sorted((v.sender_id, v.step) for v in robot_messages_in(bag, "/tile_0_14/core/vote"))
    votes.sort()
    assert votes == [(robot, step) for robot in range(15) for step in range(BAG_STEPS)]
    robot_messages = int(re.search(r"Robot messages: +(\d+)", out.stdout).group(1))
    assert robot_messages > 30 * BAG_STEPS  # the whole run's, each counted once
