"""The soak benchmark: consecutive runs leave nothing behind, and what would be left is seen."""

from __future__ import annotations

import ctypes
import fcntl
import json
import mmap
import os
import subprocess
import sys
import time

import pytest
from support import MACHINE, PROCESS, ROOT

from camo_bringup.soak import camo_processes
from camo_core.shm import SHM, orphans, remove_stale, stale_files


@pytest.mark.slow(PROCESS)
@pytest.mark.alone(MACHINE)
def test_consecutive_runs_leave_no_process_no_shared_memory_and_the_same_result(tmp_path):
    out = subprocess.run(
        [sys.executable, "-m", "camo_bringup.soak", "--runs", "3", "--side", "3", "--json"]
        + ["--steps", "100", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    report = json.loads(out.stdout)
    assert report["runs"] == 3 and report["failed_runs"] == []
    assert report["leaked_processes"] == [] and report["stale_shm_files"] == []
    # A run leaves its own few files for the next camo process to remove: none pile up.
    entries = report["shm_entries_per_run"]
    assert max(entries) - report["shm_entries_before"] <= 8, entries
    assert report["killed_at_stop"] == 0
    assert report["results_differing_from_the_first"] == []
    assert report["peak_mib_first_last"][0] > 10
    assert "soak 3/3" in out.stderr
    assert json.loads((tmp_path / "soak.json").read_text()) == report


def test_a_camo_process_left_running_is_found(tmp_path):
    script = tmp_path / "camo_nodes.stray.py"
    script.write_text("import time\ntime.sleep(60)\n")
    stray = subprocess.Popen(
        [sys.executable, str(script)], env={**os.environ, "ROS_DOMAIN_ID": "7"}
    )
    try:
        deadline = time.monotonic() + 10
        while stray.pid not in camo_processes(exclude=set()) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert stray.pid in camo_processes(exclude=set())
        assert stray.pid not in camo_processes(exclude={stray.pid})
        assert stray.pid in camo_processes(exclude=set(), domain=7)
        assert stray.pid not in camo_processes(exclude=set(), domain=8)
    finally:
        stray.kill()
        stray.wait()
    assert stray.pid not in camo_processes(exclude=set())


def test_shared_memory_of_a_dead_owner_is_stale_and_of_a_live_one_is_not(tmp_path):
    for name in ("fastrtps_dead", "fastrtps_dead_el", "fastrtps_live", "fastrtps_live_el"):
        (tmp_path / name).write_bytes(b"")
    (tmp_path / "sem.fastrtps_dead_mutex").write_bytes(b"")
    (tmp_path / "unrelated").write_bytes(b"")
    for name in ("fastrtps_dead", "fastrtps_dead_el", "sem.fastrtps_dead_mutex"):
        os.utime(tmp_path / name, (time.time() - 60, time.time() - 60))
    # A lock file made a moment ago by a process that has not locked it yet: not judged.
    for name in ("fastrtps_newborn", "fastrtps_newborn_el"):
        (tmp_path / name).write_bytes(b"")
    # Left empty by a creator killed at birth (Fast DDS would wait for it for ever), and one
    # being created right now.
    (tmp_path / "fastrtps_port7411").write_bytes(b"")
    os.utime(tmp_path / "fastrtps_port7411", (time.time() - 60, time.time() - 60))
    (tmp_path / "fastrtps_port7413").write_bytes(b"")
    holder = os.open(tmp_path / "fastrtps_live_el", os.O_RDONLY)
    fcntl.flock(holder, fcntl.LOCK_EX)  # as a live Fast DDS process holds its lock file
    try:
        stale = sorted(p.name for p in stale_files(tmp_path))
        expected = ["fastrtps_dead", "fastrtps_dead_el", "fastrtps_port7411"]
        assert stale == [*expected, "sem.fastrtps_dead_mutex"]
        assert remove_stale(tmp_path) == 4
    finally:
        os.close(holder)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "fastrtps_live",
        "fastrtps_live_el",
        "fastrtps_newborn",
        "fastrtps_newborn_el",
        "fastrtps_port7413",
        "unrelated",
    ]


def test_shared_memory_no_process_has_open_or_mapped_is_an_orphan_once_old(tmp_path):
    # A port file whose lock file went, and multiprocessing's semaphores of killed workers:
    # no lock tells of them, only that no process has them open or mapped.
    old = time.time() - 3600  # a semaphore is an orphan only after SEMAPHORE_AGE (600 s)
    names = ("fastrtps_port7415", "sem.fastrtps_port7415_mutex", "sem.mp-killed", "sem.mp-open")
    names += ("sem.mp-mapped", "sem.mp-young", "sem.mp-for-a-child", "unrelated")
    for name in names:
        (tmp_path / name).write_bytes(bytes(64))
        if name != "sem.mp-young":
            os.utime(tmp_path / name, (old, old))
    # Let go of by its spawning parent two minutes ago, for a child still starting: kept.
    os.utime(tmp_path / "sem.mp-for-a-child", (time.time() - 120, time.time() - 120))
    opened = os.open(tmp_path / "sem.mp-open", os.O_RDONLY)
    with open(tmp_path / "sem.mp-mapped", "r+b") as file:
        mapped = mmap.mmap(file.fileno(), 64)  # mapped, its file closed: as a live semaphore
    try:
        assert sorted(p.name for p in orphans(tmp_path)) == [
            "fastrtps_port7415",
            "sem.fastrtps_port7415_mutex",
            "sem.mp-killed",
        ]
        assert remove_stale(tmp_path) == 3
    finally:
        os.close(opened)
        mapped.close()
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "sem.mp-for-a-child",
        "sem.mp-mapped",
        "sem.mp-open",
        "sem.mp-young",
        "unrelated",
    ]


def _sem(name: str, create: bool = False):
    """A POSIX named semaphore as Fast DDS's port mutexes are (glibc: /dev/shm/sem.<name>)."""
    libc = ctypes.CDLL(None, use_errno=True)
    libc.sem_open.restype = ctypes.c_void_p
    libc.sem_open.argtypes = [ctypes.c_char_p, ctypes.c_int, ctypes.c_uint, ctypes.c_uint]
    return libc, libc.sem_open(f"/{name}".encode(), os.O_CREAT if create else 0, 0o644, 1)


def test_a_port_being_opened_is_never_removed_and_a_dead_one_goes_with_its_mutex():
    # A port file a process gone left (its listener's lock free, old): the next process of that
    # port number opens it, holding the port's mutex as Fast DDS does. Removed meanwhile, it
    # would listen on a file nobody else can open: so nothing of a port goes while its mutex
    # is held by another, and all of it goes once the mutex is free.
    port = f"fastrtps_port{9_000_000 + os.getpid()}"  # no real port is numbered so
    files = [SHM / port, SHM / f"{port}_el"]
    for path in files:
        path.write_bytes(bytes(64))
        os.utime(path, (time.time() - 60, time.time() - 60))
    libc, mutex = _sem(f"{port}_mutex", create=True)
    try:
        assert mutex and libc.sem_trywait(ctypes.c_void_p(mutex)) == 0  # opening the port
        assert {SHM / port, SHM / f"{port}_el"} <= set(stale_files())
        remove_stale()
        assert all(path.exists() for path in files)
        assert (SHM / f"sem.{port}_mutex").exists()
        libc.sem_post(ctypes.c_void_p(mutex))  # opened, or gave up: the port is free to judge
        libc.sem_close(ctypes.c_void_p(mutex))
        mutex = None
        remove_stale()
        assert not any(path.exists() for path in files)
        assert not (SHM / f"sem.{port}_mutex").exists()
    finally:
        if mutex:
            libc.sem_close(ctypes.c_void_p(mutex))
        for path in [*files, SHM / f"sem.{port}_mutex"]:
            path.unlink(missing_ok=True)
