"""Keyed runs whole: a run's traffic played back into it, a stranger's projector commands, an
encrypted run's bag read with its key and refused without it."""

import json
import os
import subprocess
import sys

import cv2
import pytest
from support import (
    ROOT,
    SWARM,
    assert_like_sim,
    bag_tool,
    domain,
    finished,
    run_camo,
    start_run,
    wait_for_line,
)

from camo_bag.loader import open_bag
from camo_core.algorithm.backgrounds import background
from camo_core.swarm.keys import KEY_FILE_ENV, NO_TAG, REPLAYED, sealed


def _attacker(run_id: str, domain_id: int, *args: str) -> subprocess.Popen:
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
    env.pop(KEY_FILE_ENV, None)  # a stranger: no key
    return subprocess.Popen(
        [sys.executable, str(ROOT / "tests" / "attacker.py"), run_id, *args],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


@pytest.mark.slow(SWARM)
def test_a_keyed_run_refuses_its_own_traffic_played_again_and_a_strangers_projector_path(
    tmp_path,
):
    """A stranger records every message of a keyed 16x16 run, tags and all, and plays them
    all again into it, then tells its projector to load an image file of this machine: the
    run is the simulator's, counts what was played again, and projects nothing new."""
    secret = tmp_path / "secret.png"
    cv2.imwrite(str(secret), background("desert"))
    options = ["--rows", "16", "--cols", "16", "--pattern", "forest", "--seed", "3"]
    options += ["--rho-comm", "0.1", "--consensus-steps", "1500"]
    domain_id = domain()
    run = start_run(
        *options,
        *["--run-id", "keyed", "--record", str(tmp_path / "bag"), "--out", str(tmp_path / "run")],
        domain_id=domain_id,
    )
    attacker = None
    try:
        wait_for_line(run, "consensus 256")  # every robot votes: its traffic is flowing
        attacker = _attacker("keyed", domain_id, "4", "--replay", str(secret))
        said, err = finished(attacker, 180)
        still_running = run.poll() is None
        _, run_err = finished(run, 300)
    finally:
        if attacker is not None and attacker.poll() is None:
            attacker.kill()
    assert attacker.returncode == 0, err[-2000:]
    replay = json.loads(said)
    assert still_running and replay["replayed"] > 500 and replay["topics"] >= 8, replay
    assert run.returncode == 0, run_err[-3000:]
    sim = run_camo("sim", *options, "--out", str(tmp_path / "sim"))
    assert sim.returncode == 0, sim.stderr
    ran = assert_like_sim(tmp_path / "run", tmp_path / "sim", attacked=True)
    refused = ran["rejected_messages"]["by_reason"]
    assert refused.get(REPLAYED, 0) > 10, refused
    # The projector projected the run's own background only: one frame in the bag.
    backgrounds = list(open_bag(tmp_path / "bag").messages(["/keyed/camo/background"]))
    assert len(backgrounds) == 1


@pytest.mark.slow(SWARM)
def test_an_encrypted_runs_bag_holds_ciphertext_that_render_reads_with_its_key(tmp_path):
    options = ["--rows", "4", "--cols", "4", "--pattern", "forest", "--seed", "1"]
    run = start_run(
        *options,
        *["--encrypt", "--record", str(tmp_path / "bag"), "--out", str(tmp_path / "run")],
    )
    _, err = finished(run, 180)
    assert run.returncode == 0, err[-3000:]
    sim = run_camo("sim", *options, "--out", str(tmp_path / "sim"))
    live = assert_like_sim(tmp_path / "run", tmp_path / "sim")
    bag = open_bag(tmp_path / "bag")
    kinds: dict[str, set[bool]] = {}
    for message in bag.raw_messages():
        kind = message.topic.rsplit("/", 1)[-1]
        kinds.setdefault(kind, set()).add(sealed(message.data))
    # The robots' messages and the background are ciphertext; statuses and the run's
    # parameters are not (what the swarm does, not what it sees).
    assert kinds["vote"] == kinds["background"] == {True}, kinds
    assert kinds["status"] == kinds["params"] == {False}, kinds
    refused = bag_tool("render", str(tmp_path / "bag"), "--out", str(tmp_path / "no_key"))
    assert refused.returncode == 2 and refused.stderr.count("\n") == 1, refused.stderr
    assert "encrypted" in refused.stderr and "--key-file" in refused.stderr
    key = str(tmp_path / "run" / "run.key")
    rendered = bag_tool(
        "render", str(tmp_path / "bag"), "--out", str(tmp_path / "r"), "--key-file", key
    )
    assert rendered.returncode == 0, rendered.stderr
    again = json.loads((tmp_path / "r" / "summary.json").read_text())
    for name in ("final", "initial", "sensed", "votes", "mean_p"):
        assert again[name] == live[name], name
    assert sim.returncode == 0


@pytest.mark.slow(SWARM)
def test_a_keyed_16x16_run_under_a_flood_and_a_hijack_without_the_key_is_the_simulators(
    tmp_path,
):
    """Two strangers without the key at once: one writes forged robot messages, statuses,
    hosts, heartbeats, parameters and backgrounds on every topic of the run; the other
    announces the first half of the grid as its own before the workers do, and beats. Every
    message of theirs is refused for its tag, and the run is `./camo sim`'s."""
    options = ["--rows", "16", "--cols", "16", "--pattern", "forest", "--seed", "5"]
    options += ["--rho-comm", "0.1", "--consensus-steps", "300"]
    domain_id = domain()
    hijacker = _attacker("flooded", domain_id, "600", "--hijack", "0-127")
    flooder = None
    try:
        wait_for_line(hijacker, "ready")
        run = start_run(
            *options,
            *["--procs", "2", "--run-id", "flooded", "--out", str(tmp_path / "run")],
            domain_id=domain_id,
        )
        wait_for_line(run, "topics under")
        flooder = _attacker("flooded", domain_id, "600", "0-127", "128-255")
        wait_for_line(flooder, "ready")
        _, err = finished(run, 300)
    finally:
        for stranger in (hijacker, flooder):
            if stranger is not None:
                stranger.terminate()
                finished(stranger, 30)
    assert run.returncode == 0, err[-3000:]
    sim = run_camo("sim", *options, "--out", str(tmp_path / "sim"))
    assert sim.returncode == 0, sim.stderr
    ran = assert_like_sim(tmp_path / "run", tmp_path / "sim", attacked=True)
    assert set(ran["rejected_messages"]["by_reason"]) == {NO_TAG}, ran["rejected_messages"]
    assert ran["rejected_messages"]["total"] > 100


def test_a_run_takes_its_key_and_encryption_from_the_environment_as_its_processes_do(tmp_path):
    """CAMO_KEY_FILE and CAMO_ENCRYPT=1, exported for a lab's hand-started workers, hold for
    `./camo run` too (its --key-file's help says so; it made a key of its own and its workers
    were strangers to it): --key-file still wins, --no-key takes none; unset, a new key."""
    from pathlib import Path

    from camo_bringup.run_config import build_parser, config_from
    from camo_core.swarm.keys import ENCRYPT_ENV, new_key_file

    def config(tag: str, *args: str, env: dict):
        argv = [*args, "--out", str(tmp_path / tag)]
        return config_from(build_parser().parse_args(argv), env).env

    lab = new_key_file(tmp_path / "lab.key").path
    plain = {k: v for k, v in os.environ.items() if k not in (KEY_FILE_ENV, ENCRYPT_ENV)}
    exported = {**plain, KEY_FILE_ENV: str(lab), ENCRYPT_ENV: "1"}
    ran = config("a", env=exported)
    assert ran[KEY_FILE_ENV] == str(lab.resolve()) and ran[ENCRYPT_ENV] == "1"
    given = new_key_file(tmp_path / "given.key").path
    assert config("b", "--key-file", str(given), env=exported)[KEY_FILE_ENV] == str(given)
    ran = config("c", "--no-key", env={**exported, ENCRYPT_ENV: "0"})
    assert KEY_FILE_ENV not in ran and ENCRYPT_ENV not in ran
    ran = config("d", env=plain)
    assert Path(ran[KEY_FILE_ENV]) == (tmp_path / "d" / "run.key").resolve()
    assert ENCRYPT_ENV not in ran
