"""`camo bag info` and `camo bag repair` on recorded bags."""

import re

from support import BAG_STEPS, bag_tool


def test_bag_info_lists_topics_types_and_counts(recorded):
    bag, _ = recorded
    out = bag_tool("cli", "info", str(bag))
    assert out.returncode == 0, out.stderr
    assert "Duration:" in out.stdout and "Storage id:        mcap" in out.stdout
    # The first process's tile holds robots 0-14: its edge and core vote topics hold 15 robots'
    # votes, BAG_STEPS each.
    lines = [x for x in out.stdout.splitlines() if "/tile_0_14/" in x and "/vote " in x]
    assert len(lines) == 2 and all("Type: camo_msgs/msg/Vote" in x for x in lines)
    counts = [int(re.search(r"Count: (\d+)", x).group(1)) for x in lines]
    assert sum(counts) == 15 * BAG_STEPS
