"""The launcher's process group: how it stops what it started."""

from __future__ import annotations

import os
import subprocess
import sys
import time

from camo_bringup.processes import ProcessGroup

# Like a worker: on SIGINT it does not exit until its last words are taken (here: a file appears).
WAITS_TO_BE_TAKEN = """
import os, signal, sys, time
taken = sys.argv[1]
def last_words(*_):
    while not os.path.exists(taken):
        time.sleep(0.01)
    sys.exit(0)
signal.signal(signal.SIGINT, last_words)
print("ready", flush=True)
while True:
    time.sleep(0.1)
"""


def start(group: ProcessGroup, taken) -> subprocess.Popen:
    proc = subprocess.Popen(
        [sys.executable, "-c", WAITS_TO_BE_TAKEN, str(taken)], stdout=subprocess.PIPE, text=True
    )
    group.procs.append(proc)
    assert proc.stdout.readline().strip() == "ready"
    return proc


def test_stopping_processes_keeps_taking_their_last_words_so_none_is_killed(tmp_path):
    group = ProcessGroup(dict(os.environ))
    proc = start(group, tmp_path / "taken")
    turns = []

    def take():  # what the monitor's turn does: take what came, here the worker's last words
        turns.append(time.monotonic())
        if len(turns) == 3:
            (tmp_path / "taken").touch()
        return True

    group.stop(grace=5.0, meanwhile=take)
    assert proc.returncode == 0 and group.killed == []
    assert len(turns) >= 3


def test_a_process_nobody_takes_from_is_killed_after_the_grace(tmp_path):
    group = ProcessGroup(dict(os.environ))
    proc = start(group, tmp_path / "never")
    began = time.monotonic()
    group.stop(grace=0.5)
    assert proc.returncode == -9 and len(group.killed) == 1
    assert time.monotonic() - began < 5
