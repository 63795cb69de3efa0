"""Fast DDS's shared-memory files in /dev/shm: which are left by processes that died.

Fast DDS's shared-memory transport keeps, per process, a segment file
`fastrtps_<id>` and per port `fastrtps_port<N>`, each with a lock file `..._el`
that its owner holds (flock) while it lives, and ports a `sem.<name>_mutex`. A
process that exits cleanly removes its files; one that is killed cannot, so its
files stay until removed. A lock file nobody holds marks them stale: that is the
test `fastdds shm clean` applies (the wheels do not ship that tool). A file left
empty by a process killed as it created it is worse than stale: Fast DDS waits
for it to be initialised for ever, so every camo process removes such files
before it starts (`topics.start_ros`).
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


def remove_stale(root: Path = SHM) -> int:
    """Remove what dead Fast DDS processes left; how many files."""
    removed = 0
    for path in stale_files(root):
        try:
            path.unlink()
            removed += 1
        except OSError:
            pass  # removed meanwhile, or not ours to remove
    return removed
