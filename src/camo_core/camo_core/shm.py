"""Shared-memory files in /dev/shm left by processes that are gone: Fast DDS's and Python's.

Fast DDS's shared-memory transport keeps, per process, a segment file
`fastrtps_<id>` and per port `fastrtps_port<N>`, each with a lock file `..._el`
that its owner holds (flock) while it lives, and ports a `sem.<name>_mutex`. A
process that exits cleanly removes its files; one that is killed cannot, so its
files stay until removed. A lock file nobody holds marks them stale: that is the
test `fastdds shm clean` applies (the wheels do not ship that tool). A file left
empty by a process killed as it created it is worse than stale: Fast DDS waits
for it to be initialised for ever, so every camo process removes such files
before it starts (`topics.start_ros`).

That test misses two kinds of file that pile up run after run (about 2.5 a run):
port files whose lock file is gone (a port's last user closes it and leaves the
segment and its semaphore), and the named semaphores (`sem.mp-*`) of Python's
multiprocessing in processes killed before they could unlink them (Dask's
workers, spawned). Neither is of any use once no process has it open or mapped:
a live listener maps its port, a live semaphore is mapped by its users (but for
a spawned child's start: SEMAPHORE_AGE). So `orphans` are the files of those
kinds, this user's, older than ORPHAN_AGE (semaphores SEMAPHORE_AGE), that
no process this one can see (/proc) has open or mapped. Processes in another PID
namespace sharing this /dev/shm are not seen: a container shares its /dev/shm
with no other by default, and should not share it with another run's.
"""

from __future__ import annotations

import fcntl
import os
import time
from pathlib import Path

SHM = Path("/dev/shm")
PREFIX = "fastrtps_"
LOCK_SUFFIX = "_el"


def _held(lock_file: Path) -> bool:
    try:
        fd = os.open(lock_file, os.O_RDONLY)
    except OSError:
        return False  # gone already
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return True
    else:
        fcntl.flock(fd, fcntl.LOCK_UN)
        return False
    finally:
        os.close(fd)


UNFINISHED_AGE = 10.0  # s: an empty segment this old was never going to be finished


def _unfinished(path: Path, now: float) -> bool:
    """A segment or port file left empty: its creator was killed between creating and sizing it.
    Fast DDS waits for it to be initialised, for ever: a process that opens it hangs (seen in
    participant creation and in publishing)."""
    try:
        info = path.stat()
    except OSError:
        return False
    return info.st_size == 0 and now - info.st_mtime > UNFINISHED_AGE


def stale_files(root: Path = SHM) -> list[Path]:
    """Fast DDS files whose owner is gone: each unheld lock file, its segment or port, and a
    port's semaphore; and segments or ports left empty by a creator killed at birth."""
    stale: list[Path] = []
    try:
        locks = sorted(root.glob(f"{PREFIX}*{LOCK_SUFFIX}"))
        segments = sorted(p for p in root.glob(f"{PREFIX}*") if not p.name.endswith(LOCK_SUFFIX))
    except OSError:
        return stale
    now = time.time()
    for segment in segments:
        lock = segment.with_name(segment.name + LOCK_SUFFIX)
        if _unfinished(segment, now) and not (lock.exists() and _held(lock)):
            stale.append(segment)
    for lock in locks:
        if _held(lock):
            continue
        base = lock.name[: -len(LOCK_SUFFIX)]
        for name in (base, lock.name, f"sem.{base}_mutex"):
            if (root / name).exists() and root / name not in stale:
                stale.append(root / name)
    return stale


ORPHAN_PREFIXES = ("fastrtps_", "sem.fastrtps_", "sem.mp-")
# s: a file younger may be one whose creator is about to map it (it has the file open from
# the start, so the window is one /proc scan long: milliseconds)
ORPHAN_AGE = 1.0
# s: a multiprocessing semaphore may be mapped by nobody for a while and still be wanted: a
# spawning parent can let go of it before the child, still starting, opens it by name.
SEMAPHORE_AGE = 600.0


def in_use(root: Path = SHM) -> set[str]:
    """Names of the files in `root` that a process this one can see has open or mapped."""
    used: set[str] = set()
    prefix = str(root) + "/"
    mark = prefix.encode()
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            with open(f"/proc/{pid}/maps", "rb") as maps:
                for line in maps:
                    at = line.find(mark)
                    if at >= 0:
                        name = line[at + len(mark) :].rstrip(b"\n").removesuffix(b" (deleted)")
                        used.add(name.decode(errors="replace"))
            for fd in os.listdir(f"/proc/{pid}/fd"):
                target = os.readlink(f"/proc/{pid}/fd/{fd}")
                if target.startswith(prefix):
                    used.add(target[len(prefix) :])
        except OSError:
            continue  # gone meanwhile, or not ours to look at
    return used


def orphans(root: Path = SHM) -> list[Path]:
    """Fast DDS port files and semaphores, and multiprocessing semaphores, of this user that
    no live process has open or mapped (see the module's text)."""
    try:
        names = [n for n in os.listdir(root) if n.startswith(ORPHAN_PREFIXES)]
    except OSError:
        return []
    if not names:
        return []
    used = in_use(root)
    now, uid = time.time(), os.geteuid()
    found = []
    for name in names:
        if name in used:
            continue
        try:
            info = (root / name).stat()
        except OSError:
            continue
        age = SEMAPHORE_AGE if name.startswith("sem.mp-") else ORPHAN_AGE
        if info.st_uid == uid and now - info.st_mtime > age:
            found.append(root / name)
    return found


def remove_stale(root: Path = SHM) -> int:
    """Remove what dead Fast DDS processes left, and files no process uses; how many."""
    removed = 0
    for path in [*stale_files(root), *orphans(root)]:
        try:
            path.unlink()
            removed += 1
        except OSError:
            pass  # removed meanwhile, or not ours to remove
    return removed
