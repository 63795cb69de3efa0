"""Fast DDS's shared-memory files in /dev/shm: which are left by processes that died.

Fast DDS's shared-memory transport keeps, per process, a segment file
`fastrtps_<id>` and per port `fastrtps_port<N>`, each with a lock file `..._el`
that its owner holds (flock) while it lives, and ports a `sem.<name>_mutex`. A
process that exits cleanly removes its files; one that is killed cannot, so its
files stay until removed. A lock file nobody holds marks them stale: that is the
test `fastdds shm clean` applies (the wheels do not ship that tool).
"""

from __future__ import annotations

import fcntl
import os
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


def stale_files(root: Path = SHM) -> list[Path]:
    """Fast DDS files whose owner is gone: each unheld lock file, its segment or port, and a
    port's semaphore."""
    stale: list[Path] = []
    try:
        locks = sorted(root.glob(f"{PREFIX}*{LOCK_SUFFIX}"))
    except OSError:
        return stale
    for lock in locks:
        if _held(lock):
            continue
        base = lock.name[: -len(LOCK_SUFFIX)]
        for name in (base, lock.name, f"sem.{base}_mutex"):
            if (root / name).exists():
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
