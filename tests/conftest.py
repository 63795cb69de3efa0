"""Fixtures shared by the tests (helpers that are not fixtures live in support.py)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess

import pytest
from hypothesis import HealthCheck, settings
from support import BAG_OPTIONS, FOXGLOVE_CLIENT, camo_run, run_keeping_output

# Fuzz tests: the same inputs on every run (a failure in CI is one a developer can replay), no
# example database written into the clone, and a bounded number of examples each.
settings.register_profile(
    "camo",
    derandomize=True,
    database=None,
    deadline=None,
    max_examples=150,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
# CAMO_FUZZ=explore searches further, with new inputs each time (for a developer, not CI).
settings.register_profile(
    "explore", settings.get_profile("camo"), derandomize=False, max_examples=1500
)
settings.load_profile("explore" if os.environ.get("CAMO_FUZZ") == "explore" else "camo")


def pytest_configure(config):
    config.addinivalue_line(
        "markers",
        "slow(why): a test that takes seconds, with the reason (support.SWARM, PROCESS, CLUSTER, "
        "COMPUTE); ./camo test --fast leaves it out",
    )


def pytest_collection_modifyitems(config, items):
    """A slow test names why it is slow."""
    for item in items:
        for mark in item.iter_markers("slow"):
            if not (mark.args and isinstance(mark.args[0], str) and mark.args[0].strip()):
                raise pytest.UsageError(f"{item.nodeid}: @pytest.mark.slow(WHY) needs its reason")


@pytest.fixture(autouse=True)
def whole_outputs(monkeypatch):
    """Every process a test runs keeps its whole output for the report of a failure
    (support.run_keeping_output; processes started with Popen: support.finished)."""
    monkeypatch.setattr(subprocess, "run", run_keeping_output)


@pytest.fixture
def count_round_records(monkeypatch) -> list[int]:
    """Counts RoundRecord constructions (each allocates traces of consensus steps x robots)."""
    from camo_core.results.record import RoundRecord

    made: list[int] = []
    original = RoundRecord.__post_init__
    monkeypatch.setattr(
        RoundRecord, "__post_init__", lambda self: (made.append(1), original(self))[1]
    )
    return made


@pytest.fixture(scope="session")
def recorded(tmp_path_factory):
    """One recorded run: (bag folder, live summary)."""
    folder = tmp_path_factory.mktemp("recorded")
    out = camo_run(*BAG_OPTIONS, "--out", str(folder / "live"), "--record", str(folder / "bag"))
    assert out.returncode == 0, out.stderr[-2000:]
    assert "lacks" not in out.stderr, out.stderr[-2000:]
    return folder / "bag", json.loads((folder / "live" / "summary.json").read_text())


@pytest.fixture
def emulator(tmp_path):
    """Makes emulated Droplets on pseudo-terminals; stops them after the test."""
    from camo_droplet.emulator import DropletEmulator

    made = []

    def make(rgb=(10, 20, 30), faults=None, droplet_id=0x1A2B):
        em = DropletEmulator(
            tmp_path / f"droplet{len(made)}",
            droplet_id,
            rgb,
            faults,
            led_log=tmp_path / f"led{len(made)}.log",
            seed=len(made),
        ).start()
        made.append(em)
        return em

    yield make
    for em in made:
        em.stop()


@pytest.fixture(scope="session")
def foxglove_client():
    """node and the client's npm packages, exactly as package-lock.json pins them."""
    node, npm = shutil.which("node"), shutil.which("npm")
    assert node and npm, "the Foxglove client test needs Node 20 and npm"
    marker = FOXGLOVE_CLIENT / "node_modules" / ".package-lock.json"
    lock = FOXGLOVE_CLIENT / "package-lock.json"
    if not marker.exists() or marker.stat().st_mtime < lock.stat().st_mtime:
        done = subprocess.run(
            [npm, "ci", "--no-audit", "--no-fund"],
            cwd=FOXGLOVE_CLIENT,
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert done.returncode == 0, done.stderr[-2000:]
    return node


def pytest_sessionstart(session):
    """Shared memory that killed processes of an earlier session left would hang this one's."""
    from camo_nodes.shm import remove_stale

    remove_stale()


def pytest_sessionfinish(session, exitstatus):
    """Tests kill robots, workers and launchers: remove the shared-memory files Fast DDS leaves
    of processes killed (those whose lock nobody holds, as `fastdds shm clean` does)."""
    from camo_nodes.shm import remove_stale

    remove_stale()
