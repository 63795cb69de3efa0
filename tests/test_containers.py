"""Containers (docker/, docs/containers.md), built here with podman on a Debian 12 made with
debootstrap: the README's apt-get line and its commands on that bare system, camo's image, a
swarm across containers. Images stay in podman's store between sessions: a later session
rebuilds only what changed."""

from __future__ import annotations

import json
import os
import re
import subprocess
import uuid
from pathlib import Path

import pytest
from images import BUILD, CONF, IMAGE, readme_packages, wait_for_images
from support import PROCESS, ROOT, assert_like_sim, path_without, run_camo

BUILDS = "builds images: minutes the first time, seconds when podman has its layers"

pytestmark = pytest.mark.slow(BUILDS)


def podman(
    *args: str, timeout: float = 900, check: bool = True, **env: str
) -> subprocess.CompletedProcess:
    """podman with the tests' settings; `check`: its exit code must be 0."""
    done = subprocess.run(
        ["podman", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, "CONTAINERS_CONF": str(CONF), **env},
    )
    assert done.returncode == 0 or not check, f"podman {' '.join(args[:3])}: {done.stderr[-3000:]}"
    return done


@pytest.fixture(scope="session")
def images(tmp_path_factory):
    """camo's image and its build stage (tests/images.py: built once a session, by the
    session's controller as the session starts where it can)."""
    from conftest import locked, session_folder

    with locked(session_folder(tmp_path_factory) / "images.lock"):
        problem = wait_for_images()
    if problem:
        pytest.fail(problem)
    return IMAGE


def test_the_image_builds_with_the_readmes_apt_get_line_by_default():
    dockerfile = (ROOT / "docker" / "Dockerfile").read_text()
    default = re.search(r'ARG PACKAGES="([^"]*)"', dockerfile)
    assert default and default[1].split() == readme_packages()


def test_on_a_bare_debian_the_readmes_line_and_commands_give_the_demos_results(images):
    # The build stage is the README's apt-get line on debootstrap's minbase, then `./camo
    # setup`; its demo is the README's first command.
    done = podman(
        "run", "--rm", BUILD, "sh", "-c", "./camo demo >/dev/null && cat results/*/summary.json"
    )
    summary = json.loads(done.stdout)
    assert summary["rows"] == summary["cols"] == 8 and len(summary["patterns"]) == 8


def test_camos_image_simulates_and_runs_a_swarm_into_a_mounted_folder(images, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    out.chmod(0o777)  # the image runs as its own user
    for command in (["sim"], ["run"]):
        podman(
            "run", "--rm", "-v", f"{out}:/out", IMAGE, *command, "--rows", "8", "--cols", "8",
            "--out", f"/out/{command[0]}",
        )  # fmt: skip
    assert_like_sim(out / "run", out / "sim")
    image = json.loads(podman("image", "inspect", IMAGE).stdout)[0]
    assert image["Config"]["User"] == "camo"
    files = podman(
        "run", "--rm", "--entrypoint", "sh", IMAGE, "-c", "command -v gcc cc make || true"
    )
    assert files.stdout.strip() == ""  # no compiler, no build tools
    # Every module of src/ is there compiled (`./camo setup`): the image's processes do not
    # compile what they import, whether or not they may write bytecode.
    uncompiled = podman(
        "run", "--rm", "--entrypoint", "/opt/venv/bin/python", IMAGE, "-c",
        "import importlib.util as u, pathlib\n"
        "for p in sorted(pathlib.Path('/opt/camo/src').rglob('*.py')):\n"
        "    if not pathlib.Path(u.cache_from_source(str(p))).exists(): print(p)",
    )  # fmt: skip
    assert uncompiled.stdout == ""


def test_a_folder_the_image_cannot_write_is_one_line_naming_its_user(images, tmp_path):
    out = tmp_path / "out"
    out.mkdir()  # root's, 0755: not the image's user's
    done = podman("run", "--rm", "-v", f"{out}:/out", IMAGE, "sim", "--out", "/out/s", check=False)
    assert done.returncode == 2
    assert done.stderr.strip() == (
        "camo: error: cannot create output folder /out/s: Permission denied (camo's image runs "
        "as uid 1000: mount a folder it may write)"
    )


def test_the_stranger_and_insider_tests_pass_in_the_image_without_a_machine_id(images):
    # Neither debootstrap's minbase nor the image has /etc/machine-id: a run still tells its
    # own processes from a stranger's and an insider's (tests/camo_bringup/test_launcher.py).
    podman("run", "--rm", "--entrypoint", "test", IMAGE, "!", "-s", "/etc/machine-id")
    done = podman(
        "run", "--rm", "--shm-size", "1g", IMAGE, "test", "-n", "0", "-q", "-p",
        "no:cacheprovider", "tests/camo_bringup/test_launcher.py", "-k",
        "stranger_without_the_key or insider_hosting",
    )  # fmt: skip
    assert re.search(r"\b2 passed\b", done.stdout), done.stdout[-2000:]


def test_a_swarm_across_containers_gives_the_simulators_summary(images, tmp_path):
    project = f"camo{uuid.uuid4().hex[:8]}"
    compose = ["podman-compose", "-p", project, "-f", str(ROOT / "docker" / "compose.yaml")]
    env = {**os.environ, "CONTAINERS_CONF": str(CONF), "CAMO_IMAGE": IMAGE}
    log = tmp_path / "compose.log"
    try:
        # Its output to a file: podman-compose 1.0 exits with the launcher but leaves the
        # discovery server's `podman start -a` holding a pipe (`down` stops it).
        with open(log, "w") as out:
            up = subprocess.run(
                [*compose, "up", "--abort-on-container-exit", "--exit-code-from", "launcher"],
                stdout=out,
                stderr=subprocess.STDOUT,
                timeout=600,
                env=env,
            )
        said = log.read_text()
        assert up.returncode == 0, said[-4000:]
        assert "hosting robots 32-47 of compose" in said and "Wrong domain name" not in said
        volume = podman("volume", "inspect", f"{project}_results").stdout
        results = json.loads(volume)[0]["Mountpoint"]
        sim = run_camo("sim", "--rows", "8", "--cols", "8", "--out", str(tmp_path / "sim"))
        assert sim.returncode == 0, sim.stderr
        assert_like_sim(Path(results) / "run", tmp_path / "sim")
    finally:
        subprocess.run([*compose, "down", "-v"], capture_output=True, timeout=300, env=env)
        # podman-compose 1.0 leaves the project's network: one a session would pile up
        subprocess.run(
            ["podman", "network", "rm", "-f", f"{project}_default"],
            capture_output=True,
            timeout=60,
            env=env,
        )


@pytest.mark.slow(PROCESS)
def test_without_podman_or_docker_building_the_image_says_what_to_install(tmp_path):
    done = subprocess.run(
        [str(ROOT / "camo"), "image"],
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "PATH": path_without(tmp_path, "podman", "docker")},
    )
    assert done.returncode == 2
    assert done.stderr.strip() == (
        "camo: error: building camo's image needs podman or docker: sudo apt-get install "
        "podman runc (Debian 12, Ubuntu 24.04)"
    )
