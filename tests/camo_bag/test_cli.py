"""`camo bag info` and `camo bag repair` on recorded bags."""

import subprocess
import sys

from support import BAG_STEPS, ROOT


def tool(module: str, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", f"camo_bag.{module}", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
    )


def test_bag_info_lists_topics_types_and_counts(recorded):
    bag, _ = recorded
    out = tool("cli", "info", str(bag))
    assert out.returncode == 0, out.stderr
    assert "Duration:" in out.stdout and "Storage id:        mcap" in out.stdout
    line = next(x for x in out.stdout.splitlines() if "/camo/robot_3/vote " in x)
    assert "Type: camo_msgs/msg/Vote" in line and f"Count: {BAG_STEPS} " in line
