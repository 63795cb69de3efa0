"""Fixtures shared by the tests (helpers that are not fixtures live in support.py)."""

from __future__ import annotations

import fcntl
import functools
import json
import os
import re
import shutil
import subprocess
from contextlib import contextmanager
from pathlib import Path

import pytest
import warm_cli
from hypothesis import HealthCheck, settings
from support import BAG_OPTIONS, FOXGLOVE_CLIENT, ROOT, camo_run, run_keeping_output

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
    warm_cli.remember_environment()
    if not in_a_worker(config) and runs_container_tests(config):
        import tempfile

        import images

        images.start_in_background(Path(tempfile.gettempdir()))  # the workers inherit its env
    config.addinivalue_line(
        "markers",
        "slow(why): a test that takes seconds, with the reason (support.SWARM, PROCESS, CLUSTER, "
        "COMPUTE); ./camo test --fast leaves it out",
    )
    config.addinivalue_line(
        "markers",
        "alone(why): a test that times a swarm against the wall clock or counts what the whole "
        "machine holds (support.TIMED, MACHINE): under pytest-xdist no other test runs beside it",
    )


def runs_container_tests(config) -> bool:
    """Whether this session runs tests/test_containers.py (a -k or "not slow" selection is not
    looked into: its tests build the images when they need them; --collect-only runs none)."""
    if (
        config.option.collectonly
        or config.option.keyword
        or "not slow" in (config.option.markexpr or "")
    ):
        return False
    wanted = ROOT / "tests" / "test_containers.py"
    paths = [Path(arg.split("::")[0]).resolve() for arg in config.args] or [ROOT / "tests"]
    return any(path == wanted or path in wanted.parents for path in paths)


def pytest_collection_modifyitems(config, items):
    """A slow (or alone) test names why it is. In a pytest-xdist worker, the tests are in the
    order they go out in (`in_parallel_order`)."""
    for item in items:
        for mark in (*item.iter_markers("slow"), *item.iter_markers("alone")):
            if not (mark.args and isinstance(mark.args[0], str) and mark.args[0].strip()):
                raise pytest.UsageError(
                    f"{item.nodeid}: @pytest.mark.{mark.name}(WHY) needs its reason"
                )
    if in_a_worker(config):
        items[:] = in_parallel_order(items)


# ---- tests that must run alone ----------------------------------------------------------------
# A test marked alone times a swarm against the wall clock (a round within 5 s of a switch, no
# false round), or counts what the whole machine holds (stale files in /dev/shm): the other
# worker's swarms, on the same two cores, would slow it, or its killed processes would leave
# files that the test counts as its own. Each
# test of a worker holds the session's lock `alone.lock` shared while it runs; a test marked
# alone holds it exclusively, so it waits for the test the other worker is running and the
# other worker waits for it. A test marked alone first takes `gate.lock` and keeps it until it
# has the lock, and every test goes through that gate: a stream of the other worker's tests
# cannot keep it waiting.


@contextmanager
def locked(path: Path, how: int = fcntl.LOCK_EX):
    """Holds the lock file `path` (flock: exclusively unless told) for the block."""
    with open(path, "a") as handle:
        fcntl.flock(handle, how)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """In a pytest-xdist worker: the test (set-up, call, tear-down) under the session's lock,
    exclusively if it is marked alone."""
    if not in_a_worker(item.config):
        return (yield)
    shared = item.config._tmp_path_factory.getbasetemp().parent
    how = fcntl.LOCK_EX if item.get_closest_marker("alone") else fcntl.LOCK_SH
    with open(shared / "alone.lock", "a") as lock:
        with locked(shared / "gate.lock", fcntl.LOCK_EX):
            fcntl.flock(lock, how)
        try:
            return (yield)
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


# ---- the order of a parallel session ------------------------------------------------------------
# `./camo test` runs the tests in pytest-xdist workers (-n 2), each of which is sent the next
# unit of work as it nearly runs out (`pytest_xdist_make_scheduler`). The units go out longest
# first, so that no long test starts last while the other worker idles. A unit is one test,
# or a whole module that has a fixture of module scope (made once, then used in the module's
# order: tests/camo_sweep/test_sweep.py's sweep, say). A unit's length is the sum of its tests'
# seconds in tests/durations.json (an earlier session's: `CAMO_DURATIONS=write ./camo test`
# rewrites it), or for a test not there SLOW_GUESS s if it is marked slow, else FAST_GUESS.
# (pytest-xdist's --dist loadgroup cannot do this with pytest 9.2: it renames items by setting
# an attribute pytest no longer reads.)
# The tests that use camo's images (tests/images.py, built by the controller as the session
# starts: minutes on a machine whose podman store is empty) go out after the other long units,
# before the tail of short tests: sent early, a worker waited minutes for the build.

DURATIONS = Path(__file__).with_name("durations.json")
SLOW_GUESS, FAST_GUESS = 5.0, 0.1
SHORT = 2.0  # s: a unit shorter is in the tail
MODULE_FIXTURE = re.compile(r"@pytest\.fixture\(scope=\"module\"")


def known_durations() -> dict[str, float]:
    try:
        return json.loads(DURATIONS.read_text())
    except (OSError, ValueError):
        return {}


@functools.cache
def has_module_fixture(path: str) -> bool:
    """Whether the test module at `path` (from the root) defines a fixture of module scope."""
    try:
        return bool(MODULE_FIXTURE.search((ROOT / path).read_text()))
    except OSError:
        return False


def unit_of(nodeid: str) -> str:
    """The unit of work a test belongs to: its module's path, or its own id."""
    path = nodeid.split("::", 1)[0]
    return path if has_module_fixture(path) else nodeid


def in_parallel_order(items: list) -> list:
    """The items by unit, longest unit first (a unit's tests in their own order)."""
    seconds = known_durations()
    units: dict[str, list] = {}
    for item in items:
        units.setdefault(unit_of(item.nodeid), []).append(item)

    def guess(item) -> float:
        fallback = SLOW_GUESS if item.get_closest_marker("slow") else FAST_GUESS
        return seconds.get(item.nodeid, fallback)

    longest_first = sorted(units.values(), key=lambda unit: -sum(map(guess, unit)))
    needs_images = [any("images" in i.fixturenames for i in unit) for unit in longest_first]
    built = [unit for unit, needs in zip(longest_first, needs_images, strict=True) if needs]
    others = [unit for unit, needs in zip(longest_first, needs_images, strict=True) if not needs]
    tail = next((k for k, unit in enumerate(others) if sum(map(guess, unit)) < SHORT), len(others))
    ordered = others[:tail] + built + others[tail:]
    return [item for unit in ordered for item in unit]


@pytest.hookimpl(tryfirst=True)
def pytest_xdist_make_scheduler(config, log):
    """-n N (pytest-xdist's --dist load): units of work in the workers' order (longest first),
    each sent whole to the first worker that is down to its last tests. Other --dist modes
    are pytest-xdist's own."""
    if config.getvalue("dist") != "load":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class Units(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return unit_of(nodeid)

    config.option.loadscopereorder = False  # the workers' order is the one wanted
    return Units(config, log)


_took: dict[str, float] = {}


def pytest_runtest_logreport(report):
    """With CAMO_DURATIONS=write, each test's seconds (set-up, call and tear-down), for
    tests/durations.json."""
    if os.environ.get("CAMO_DURATIONS") == "write":
        nodeid = report.nodeid
        if nodeid.rfind("@") > nodeid.rfind("]"):  # pytest-xdist's group suffix
            nodeid = nodeid.rsplit("@", 1)[0]
        _took[nodeid] = _took.get(nodeid, 0.0) + report.duration


def write_durations() -> None:
    """tests/durations.json: those of its tests that take a second or more, as this session
    timed them (the others as an earlier one did)."""
    took = {**known_durations(), **{k: round(v, 1) for k, v in _took.items()}}
    slow = {k: v for k, v in sorted(took.items()) if v >= 1.0}
    DURATIONS.write_text(json.dumps(slow, indent=0) + "\n")


@pytest.fixture(autouse=True)
def leaves_the_environment_as_it_found_it():
    """A test that changes os.environ (in this process: a command's main run here, say) and
    leaves it so changes the tests after it in this worker: what their processes inherit, and
    whether tests/warm_cli.py may run their commands (`mock.patch.dict(os.environ)` around code
    that sets it restores it). Its teardown fails, naming the names."""
    before = warm_cli.environment()
    yield
    after = warm_cli.environment()
    changed = sorted(k for k in before.keys() | after.keys() if before.get(k) != after.get(k))
    assert not changed, f"the test left os.environ changed: {', '.join(changed)}"


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


def in_a_worker(config) -> bool:
    """Whether this process is a pytest-xdist worker (not the session's controller)."""
    return hasattr(config, "workerinput")


def session_folder(tmp_path_factory) -> Path:
    """A folder every process of this session shares: pytest's temporary root, or with
    pytest-xdist the folder that holds each worker's root (gw0/, gw1/, ...)."""
    base = tmp_path_factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


@pytest.fixture(scope="session")
def recorded(tmp_path_factory):
    """One recorded run: (bag folder, live summary). Made once a session, by the first test
    process (pytest-xdist worker) that needs it, while the others wait for it; tests only
    read it (they copy it before changing it)."""
    shared = session_folder(tmp_path_factory)
    folder = shared / "recorded"
    with locked(shared / "recorded.lock"):
        if not (folder / "made").exists():  # or an earlier attempt failed half-way
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir()
            out = camo_run(
                *BAG_OPTIONS, "--out", str(folder / "live"), "--record", str(folder / "bag")
            )
            assert out.returncode == 0, out.stderr[-2000:]
            assert "lacks" not in out.stderr, out.stderr[-2000:]
            (folder / "made").write_text(out.stderr)
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
def foxglove_client(tmp_path_factory):
    """node and the client's npm packages, exactly as package-lock.json pins them (installed by
    one test process at a time: two `npm ci` in one folder would undo each other's work)."""
    node, npm = shutil.which("node"), shutil.which("npm")
    assert node and npm, "the Foxglove client test needs Node 20 and npm"
    marker = FOXGLOVE_CLIENT / "node_modules" / ".package-lock.json"
    lock = FOXGLOVE_CLIENT / "package-lock.json"
    with locked(session_folder(tmp_path_factory) / "foxglove_client.lock"):
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


# With pytest-xdist, /dev/shm is cleaned by the session's controller alone: before it starts its
# workers and after they have finished, never while a worker's test has processes of its own
# half-way through creating their files (a lock file made but not yet locked looks stale).


def pytest_sessionstart(session):
    """Shared memory that killed processes of an earlier session left would hang this one's."""
    from camo_core.shm import remove_stale

    if not in_a_worker(session.config):
        remove_stale()


def pytest_sessionfinish(session, exitstatus):
    """Tests kill robots, workers and launchers: remove the shared-memory files Fast DDS leaves
    of processes killed (those whose lock nobody holds, as `fastdds shm clean` does)."""
    from camo_core.shm import remove_stale

    if not in_a_worker(session.config):
        remove_stale()
        if _took:
            write_durations()
