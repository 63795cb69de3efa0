"""`./camo COMMAND --help`: the committed texts are what the parsers print, and the script
answers from them before any set-up."""

import os
import shutil
import subprocess
import sys

import pytest
from support import PROCESS, ROOT

sys.path.insert(0, str(ROOT / "tools"))
import write_help


@pytest.mark.slow(PROCESS)
@pytest.mark.parametrize("key", sorted([*write_help.HELP, *write_help.STATIC]))
def test_the_committed_help_text_is_what_the_parser_prints(key):
    committed = (write_help.FOLDER / f"{key}.txt").read_text()
    assert committed == write_help.expected(key), (
        f"docs/cli/{key}.txt is stale: run python tools/write_help.py"
    )


def test_no_help_text_is_left_for_a_command_that_is_gone():
    files = {path.stem for path in write_help.FOLDER.glob("*.txt")}
    assert files == set(write_help.HELP) | set(write_help.STATIC)


def test_every_command_with_options_has_a_help_text():
    script = (ROOT / "camo").read_text()
    commands = {"sim", "errors", "bench", "run", "demo", "worker", "record", "view", "replay"}
    commands |= {"render", "bag", "topic", "node", "robot", "projector", "monitor"}
    commands |= {"discovery-server", "droplet-emulator", "droplet-bridge", "sweep"}
    for command in commands:
        assert f"{command})" in script or f"|{command}" in script or f"{command}|" in script
        assert command in write_help.HELP, command


@pytest.mark.parametrize(
    "argv, key",
    [
        (["run", "--rows", "4", "--help"], "run"),
        (["bench", "ros", "-h"], "bench-ros"),
        (["bag", "info", "--help"], "bag-info"),
        (["sim", "--help"], "sim"),
        (["sweep", "plot", "--help"], "sweep-plot"),
        (["setup", "--help"], "setup"),
        (["test", "--help"], "test"),
        (["dask", "--help"], "dask"),
        (["demo", "-h"], "demo"),
        (["sweep", "my.yaml", "--out", "x", "--help"], "sweep"),
    ],
)
def test_help_answers_from_the_texts_without_any_set_up(tmp_path, argv, key):
    # A bare copy of the script and its texts: no .venv/, no workspace, and no python3 on the
    # PATH, so that answering at all shows that nothing was set up or imported.
    shutil.copy(ROOT / "camo", tmp_path / "camo")
    shutil.copytree(ROOT / "docs" / "cli", tmp_path / "docs" / "cli")
    env = {"PATH": "/usr/bin:/bin", "CAMO_PYTHON": "/nonexistent/python3"}
    out = subprocess.run(
        [str(tmp_path / "camo"), *argv], capture_output=True, text=True, env=env, timeout=10
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout == (write_help.FOLDER / f"{key}.txt").read_text()
    assert sorted(os.listdir(tmp_path)) == ["camo", "docs"]


def test_a_help_after_ros_args_goes_to_the_node(tmp_path):
    shutil.copy(ROOT / "camo", tmp_path / "camo")
    shutil.copytree(ROOT / "docs" / "cli", tmp_path / "docs" / "cli")
    env = {"PATH": "/usr/bin:/bin", "CAMO_PYTHON": "/nonexistent/python3"}
    out = subprocess.run(
        [str(tmp_path / "camo"), "robot", "--ros-args", "--help"],
        capture_output=True,
        text=True,
        env=env,
        timeout=10,
    )
    assert out.returncode != 0 and "usage: robot_node" not in out.stdout  # it tried to set up
