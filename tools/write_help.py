"""Write docs/cli/COMMAND.txt, the --help text of every ./camo command, from the parsers.

`./camo COMMAND --help` prints these files, so that it answers at once and before any set-up
(a command's parser sits in modules that import NumPy, OpenCV, numba or rclpy).
tests/test_help.py fails when a file differs from what its parser prints: after changing an
option, run `.venv/bin/python tools/write_help.py` (with the workspace sourced, as ./camo test
has it) and commit the texts.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FOLDER = ROOT / "docs" / "cli"
COLUMNS = "100"  # the width the texts are written at, whatever the terminal

# The file a `./camo` command line's help comes from (the command, and for commands with
# subcommands the subcommand), and the module call that prints it.
HELP = {
    "sim": ["camo_core.cli", "sim"],
    "key": ["camo_core.cli", "key"],
    "errors": ["camo_sweep.errors"],
    "sweep": ["camo_sweep.cli"],
    "sweep-plot": ["camo_sweep.cli", "plot"],
    "bench": ["camo_core.cli", "bench"],
    "bench-sim": ["camo_core.cli", "bench"],
    "bench-ros": ["camo_bringup.bench"],
    "bench-soak": ["camo_bringup.soak"],
    "bench-sweep": ["camo_sweep.bench"],
    "run": ["camo_bringup.launcher"],
    "demo": ["camo_bringup.launcher"],  # after DEMO below
    "worker": ["camo_bringup.worker"],
    "discovery-server": ["camo_nodes.discovery_server"],
    "record": ["camo_bag.recorder_node"],
    "view": ["camo_bag.view_node"],
    "replay": ["camo_bag.replay"],
    "render": ["camo_bag.render"],
    "bag": ["camo_bag.cli"],
    "bag-info": ["camo_bag.cli", "info"],
    "bag-repair": ["camo_bag.cli", "repair"],
    "droplet-emulator": ["camo_droplet.emulator"],
    "droplet-bridge": ["camo_droplet.bridge_node"],
    "topic": ["camo_bag.introspect", "topic"],
    "topic-list": ["camo_bag.introspect", "topic", "list"],
    "topic-echo": ["camo_bag.introspect", "topic", "echo"],
    "topic-hz": ["camo_bag.introspect", "topic", "hz"],
    "node": ["camo_bag.introspect", "node"],
    "node-list": ["camo_bag.introspect", "node", "list"],
    "robot": ["camo_nodes.robot_node"],
    "projector": ["camo_projector.projector_node"],
    "monitor": ["camo_nodes.monitor_node"],
}


DEMO = """\
./camo demo [options of ./camo run]: the main job. ./camo run on the built-in forest at 8x8
with 15% sensor noise and 10% message loss (--pattern forest --rows 8 --cols 8 --rho-meas 0.15
--rho-comm 0.1); options given here override those. Results in results/<timestamp>/: run.gif
(the swarm at work), figure.png, summary.json, timing.json, params.yaml.

"""
# Commands with no parser of their own.
STATIC = {
    "setup": """\
usage: ./camo setup

Create .venv/ with the pinned dependencies of requirements.txt (ROS 2 Jazzy wheels among them)
and build src/ into ros2_ws/ with colcon. Every other command does this first, and skips what
is already up to date.
""",
    "test": """\
usage: ./camo test [pytest arguments]

Set up (as ./camo setup), then run the test suite with pytest in the project's environment;
the arguments go to pytest (./camo test tests/camo_sweep -k resume, ./camo test -q). The tests
run in two worker processes (pytest-xdist's -n 2); -n 0 runs them in one, -n N in N. --fast:
only the tests not marked slow. For pytest's own options: .venv/bin/python -m pytest --help.
""",
    "dask": """\
usage: ./camo dask scheduler [Dask's options] | ./camo dask worker tcp://HOST:8786 [options]

Dask's own command, run in this clone's environment (its processes import camo's modules; one
thread each for numba and BLAS): the cluster of a sweep across machines (docs/sweeps.md).
  ./camo dask scheduler --port 8786
  ./camo dask worker tcp://HOST:8786 --nworkers 2 --nthreads 1 [--resources ros=1]
Dask's help: ./camo dask scheduler --help, ./camo dask worker --help.
""",
}


def expected(key: str) -> str:
    """What docs/cli/KEY.txt holds."""
    if key in STATIC:
        return STATIC[key]
    return (DEMO if key == "demo" else "") + live_help(key)


def live_help(key: str) -> str:
    """What the parser behind `key` prints for --help, at the texts' width."""
    env = {**os.environ, "COLUMNS": COLUMNS}
    done = subprocess.run(
        [sys.executable, "-m", *HELP[key], "--help"],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    if done.returncode != 0:
        raise RuntimeError(f"{key}: --help exited {done.returncode}: {done.stderr.strip()}")
    return done.stdout


def main() -> int:
    FOLDER.mkdir(parents=True, exist_ok=True)
    keys = [*HELP, *STATIC]
    for stale in set(FOLDER.glob("*.txt")) - {FOLDER / f"{key}.txt" for key in keys}:
        stale.unlink()
    for key in keys:
        (FOLDER / f"{key}.txt").write_text(expected(key))
    print(f"wrote {len(keys)} help texts into {FOLDER.relative_to(ROOT)}/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
