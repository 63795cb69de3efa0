"""The docs cannot drift: every `./camo` command in a code block of README.md and docs/*.md is
run, each file's commands in order in a folder and a ROS domain of their own, and each
per-node command answers --help from a fresh shell (nothing activated).

A command that serves until stopped is run until it says it is up, then stopped with Ctrl-C; a
command that needs what a test machine has not (Droplets on serial ports, a second machine) has
its command line checked by its own parser, and says why here."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest
from support import ROOT, SWARM, domain, finished

DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
FRESH_SHELL = {"HOME": os.environ.get("HOME", "/root"), "PATH": "/usr/local/bin:/usr/bin:/bin"}

# How a command is shown to work, by its start; the first match counts. Anything else is run
# to its end and must exit 0.
SERVES = "serves until stopped: run until it is up, then Ctrl-C"
RULES = [
    ("./camo test", "skip", "the test suite itself"),
    ("./camo image", "skip", "builds camo's image: tests/test_containers.py builds and runs it"),
    ("./camo run --rows 64 --cols 64 --remote-cells", "parse", "waits for a second machine"),
    ("./camo run ... --discovery-server", "parse", "an excerpt of a command"),
    ("./camo run --pattern forest --bridge", "parse", "needs Droplets on serial ports"),
    ("./camo droplet-bridge", "refused", "needs a Droplet: without one, it says so in one line"),
    ("./camo worker", SERVES, "waits for its run on the network"),
    ("./camo discovery-server", SERVES, "the Fast DDS discovery server"),
    ("./camo droplet-emulator", SERVES, "a Droplet on a pseudo-terminal"),
    ("./camo record", "with a run", "records the only run in its domain"),
    ("./camo view", SERVES, "serves runs to Foxglove until stopped"),
    ("./camo dask scheduler", SERVES, "the Dask scheduler of a cluster"),
    ("./camo dask worker tcp://HOST", "skip", "needs the scheduler's host"),
    ("./camo python tools/scope_figure.py", "fewer", "its table of 3 scenes, not of 30"),
]
UP = {  # what a serving command says once it is up
    "./camo worker": "camo worker: waiting for",
    "./camo discovery-server": "listening on",
    "./camo droplet-emulator": "Ctrl-C to stop",
    "./camo view": "camo view: serving on",
    "./camo dask scheduler": "Scheduler at:",
}


def doc_commands(path: Path) -> list[str]:
    """The `./camo` lines of a file's code blocks: continuations joined, comments and optional
    [...] parts removed."""
    commands, inside, pending = [], False, ""
    for line in path.read_text().splitlines():
        if line.startswith("```"):
            inside = not inside
            continue
        if not inside:
            continue
        line = pending + line.strip()
        pending = ""
        if line.endswith("\\"):
            pending = line[:-1] + " "
            continue
        if line.startswith("./camo "):
            line = re.sub(r"\s+#.*$", "", line)
            commands.append(" ".join(re.sub(r"\[[^]]*\]", "", line).split()))
    return commands


def rule_of(command: str) -> tuple[str, str]:
    """How the command is shown to work, and why not by running it to its end."""
    for start, how, why in RULES:
        if command.startswith(start):
            return how, why
    return "run", ""


def parse_run_options(command: str) -> None:
    from camo_bringup.run_config import build_parser

    words = [w for w in command.split()[2:] if w != "..."]
    build_parser().parse_args(words)  # raises the project's UsageError if an option drifted


def shell(command: str, folder: Path, env: dict, text: bool = True) -> subprocess.Popen:
    return subprocess.Popen(
        ["bash", "-c", command.replace("./camo", str(ROOT / "camo"), 1)],
        cwd=folder,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=text,
        start_new_session=True,
    )


def read_now(fd: int) -> str:
    """What a pipe holds now, without waiting."""
    try:
        return os.read(fd, 1 << 20).decode(errors="replace")
    except BlockingIOError:
        return ""


def serve_until_up(command: str, folder: Path, env: dict) -> None:
    """Run a serving command until its stderr says it is up (or, if it says nothing, for 5 s),
    check it still runs, then Ctrl-C it."""
    said = next((text for start, text in UP.items() if command.startswith(start)), "")
    proc = shell(command, folder, env, text=False)
    fd = proc.stderr.fileno()
    os.set_blocking(fd, False)
    seen, deadline = "", time.monotonic() + (30 if said else 5)
    try:
        while time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.25)
            seen += read_now(fd)
            if said and said in seen:
                break
        assert proc.poll() is None, f"{command} exited: {seen[-1500:]}"
        assert not said or said in seen, f"{command} never said {said!r}: {seen[-1500:]}"
    finally:
        os.killpg(proc.pid, signal.SIGINT)
        proc.wait(timeout=30)
    seen += read_now(fd)
    assert "Traceback" not in seen, seen[-2000:]


@pytest.mark.slow(SWARM)
@pytest.mark.parametrize("doc", DOCS, ids=[d.name for d in DOCS])
def test_every_command_of_the_doc_works(doc, tmp_path):
    env = {
        **os.environ,
        "ROS_DOMAIN_ID": str(domain()),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
    }
    background: list[subprocess.Popen] = []
    ran = 0
    # Scripts the docs run, by their path from the clone's root; what they write stays here.
    (tmp_path / "tools").symlink_to(ROOT / "tools")
    (tmp_path / "docs" / "img").mkdir(parents=True)
    (tmp_path / "docs" / "examples").symlink_to(ROOT / "docs" / "examples")
    for command in doc_commands(doc):
        how, _ = rule_of(command)
        if how == "skip":
            continue
        if how == "parse":
            parse_run_options(command)
        elif how == "refused":
            proc = shell(command, tmp_path, env)
            _, err = finished(proc, 120)
            assert proc.returncode == 2 and len(err.strip().splitlines()) == 1, err[-1500:]
        elif how == SERVES:
            serve_until_up(command, tmp_path, env)
        elif how == "with a run":
            recorder = shell(command, tmp_path, env)
            time.sleep(2.0)
            swarm = shell("./camo run --rows 3 --cols 3 --out run_for_recorder", tmp_path, env)
            assert swarm.wait(timeout=240) == 0, swarm.communicate()[1][-1500:]
            _, err = finished(recorder, 120)
            assert recorder.returncode == 0, f"{command}: {err[-1500:]}"
        elif how == "fewer":  # the same command on fewer scenes: minutes less, the same code
            proc = shell(re.sub(r"--scenes \d+", "--scenes 3", command), tmp_path, env)
            _, err = finished(proc, 600)
            assert proc.returncode == 0, f"{command}: {err[-1500:]}"
        elif command.endswith("&"):
            background.append(shell(command[:-1], tmp_path, env))
        else:
            proc = shell(command, tmp_path, env)
            _, err = finished(proc, 600)
            assert proc.returncode == 0, f"{command}: {err[-1500:]}"
        ran += 1
    for proc in background:
        _, err = finished(proc, 300)
        assert proc.returncode == 0, err[-1500:]
    if doc.name in ("README.md", "bags.md", "swarm.md", "hardware.md"):
        assert ran, f"no command found in {doc.name}"


COMMANDS_WITH_HELP = [
    "robot", "projector", "droplet-bridge", "monitor", "record", "view", "worker", "run", "sim",
    "replay", "render", "topic", "node", "droplet-emulator", "discovery-server",
]  # fmt: skip


@pytest.mark.parametrize("command", COMMANDS_WITH_HELP)
def test_each_command_answers_help_from_a_fresh_shell(command):
    out = subprocess.run(
        ["bash", "-c", f"./camo {command} --help"],
        cwd=ROOT,
        env=FRESH_SHELL,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr[-1500:]
    assert out.stdout.startswith("usage:"), out.stdout[:300]


def python_blocks(path: Path) -> list[str]:
    """The ```python code blocks of a file, each as its text."""
    return re.findall(r"```python\n(.*?)```", path.read_text(), flags=re.S)


def test_the_worked_mode_example_shows_the_code_the_docs_test_runs():
    # docs/extending.md's own mode is docs/examples/own_energy_threshold.py, which the docs'
    # command runs (test_every_command_of_the_doc_works): what the page shows is that code.
    page = ROOT / "docs" / "extending.md"
    example = (ROOT / "docs" / "examples" / "own_energy_threshold.py").read_text()
    shown = [b for b in python_blocks(page) if "class OwnEnergyThreshold" in b]
    assert len(shown) == 1 and shown[0] in example
    assert "./camo python docs/examples/own_energy_threshold.py" in doc_commands(page)
