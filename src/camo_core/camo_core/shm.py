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

Every camo process cleans at its start, while other processes (of this run, of
other runs) are creating and opening these files, so no test above may be taken
half-way through another process's steps:
- A port file is reused by name: a process opening port N finds the file a
  process gone left and maps it. Removed meanwhile, that process listens on a
  file nobody else can open, and the writers that come later make a new one:
  one port split in two, which hear nothing of each other (a run stuck in
  discovery). Fast DDS opens, creates and locks a port holding its named mutex
  `sem.fastrtps_port<N>_mutex`, so a port's files are judged and removed only
  while this process holds that mutex (`_PortMutexes`); a port whose mutex is
  busy is left for the next clean.
- A segment's lock file is made, then locked: one younger than ORPHAN_AGE is not
  judged (segment names are never reused, so a lock file's age is its owner's).
"""

from __future__ import annotations

import ctypes
import fcntl
import os
import re
import time
from pathlib import Path

SHM = Path("/dev/shm")
PREFIX = "fastrtps_"
LOCK_SUFFIX = "_el"
# A port's files: the port, its listeners' lock files (_el), its mutex (glibc's file for it)
PORT_FILE = re.compile(r"^(?:sem\.)?(fastrtps_port\d+)(?:_el|_sl|_mutex)?$")


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


def _age(path: Path, now: float) -> float:
    try:
        return now - path.stat().st_mtime
    except OSError:
        return 0.0  # gone meanwhile: nothing to judge


def _unfinished(path: Path, now: float) -> bool:
    """A segment or port file left empty: its creator was killed between creating and sizing it.
    Fast DDS waits for it to be initialised, for ever: a process that opens it hangs (seen in
    participant creation and in publishing)."""
    try:
        info = path.stat()
    except OSError:
        return False
    return info.st_size == 0 and now - info.st_mtime > UNFINISHED_AGE


def port_of(name: str) -> str | None:
    """The port (`fastrtps_port<N>`) a file of /dev/shm belongs to, if it is a port's."""
    match = PORT_FILE.match(name)
    return match.group(1) if match else None


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
        if port_of(lock.name) is None and _age(lock, now) <= ORPHAN_AGE:
            continue  # made a moment ago, perhaps not locked yet
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


def users(root: Path = SHM) -> dict[str, set[int]]:
    """The files in `root` that a process this one can see has open or mapped: name -> pids."""
    used: dict[str, set[int]] = {}
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
                        used.setdefault(name.decode(errors="replace"), set()).add(int(pid))
            for fd in os.listdir(f"/proc/{pid}/fd"):
                target = os.readlink(f"/proc/{pid}/fd/{fd}")
                if target.startswith(prefix):
                    used.setdefault(target[len(prefix) :], set()).add(int(pid))
        except OSError:
            continue  # gone meanwhile, or not ours to look at
    return used


def orphans(root: Path = SHM, used: dict[str, set[int]] | None = None) -> list[Path]:
    """Fast DDS port files and semaphores, and multiprocessing semaphores, of this user that
    no live process has open or mapped (see the module's text)."""
    try:
        names = [n for n in os.listdir(root) if n.startswith(ORPHAN_PREFIXES)]
    except OSError:
        return []
    if not names:
        return []
    used = users(root) if used is None else used
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


class _PortMutexes:
    """Fast DDS's named mutexes of ports (POSIX named semaphores, glibc's files
    /dev/shm/sem.<name>), taken without waiting: a port whose mutex another process holds is
    being opened right now. Only /dev/shm has them: another root (a test's) has no process to
    keep out."""

    def __init__(self, root: Path) -> None:
        self.real = root == SHM
        self.held: dict[str, int] = {}
        if self.real:
            libc = ctypes.CDLL(None, use_errno=True)
            self._open, self._try = libc.sem_open, libc.sem_trywait
            self._post, self._close = libc.sem_post, libc.sem_close
            self._open.restype = ctypes.c_void_p
            self._open.argtypes = [ctypes.c_char_p, ctypes.c_int, ctypes.c_uint, ctypes.c_uint]
            for function in (self._try, self._post, self._close):
                function.argtypes = [ctypes.c_void_p]

    def take(self, port: str) -> bool:
        """Hold `port`'s mutex (made if it is not there, as Fast DDS makes it); False if busy."""
        if not self.real:
            self.held[port] = 0
            return True
        sem = self._open(f"/{port}_mutex".encode(), os.O_CREAT, 0o644, 1)
        if not sem:
            return False  # not ours to open: another user's port
        if self._try(sem) != 0:
            self._close(sem)
            return False  # errno EAGAIN: a process is opening or creating this port
        self.held[port] = sem
        return True

    def release(self) -> None:
        for sem in self.held.values():
            if sem:
                self._post(sem)
                self._close(sem)
        self.held.clear()


def _removable_ports(ports: dict[str, list[Path]], root: Path) -> list[Path]:
    """The files of `ports` still dead now that no process can be opening them (their mutexes
    held by this one). A port whose listeners' lock files are all free has no listener: its
    files go though writers still map them (as `fastdds shm clean` judges); one without lock
    files goes if no process has it open or mapped. A port's mutex goes with its port file but
    for this process's own hold on it (one who waits on it has it mapped)."""
    used = users(root)
    me = os.getpid()
    removable: list[Path] = []
    for port, files in ports.items():
        locks = [root / f"{port}{end}" for end in ("_el", "_sl")]
        locks = [lock for lock in locks if lock.exists()]
        if any(_held(lock) for lock in locks) or (not locks and port in used):
            continue
        mutex = root / f"sem.{port}_mutex"
        removable += [path for path in files if path != mutex]
        removable += [path for path in (root / port, *locks) if path not in removable]
        if mutex.exists() and not used.get(mutex.name, set()) - {me}:
            removable.append(mutex)
    return removable


def remove_stale(root: Path = SHM) -> int:
    """Remove what dead Fast DDS processes left, and files no process uses; how many. A port's
    files only while holding its mutex (see the module's text), but for one left empty: its
    creator was killed holding the mutex."""
    ports: dict[str, list[Path]] = {}
    others: list[Path] = []
    now = time.time()
    for path in dict.fromkeys([*stale_files(root), *orphans(root)]):
        port = port_of(path.name)
        if port is None or _unfinished(path, now):
            others.append(path)
        else:
            ports.setdefault(port, []).append(path)
    mutexes = _PortMutexes(root)
    try:
        taken = {port: files for port, files in ports.items() if mutexes.take(port)}
        removed = 0
        for path in [*others, *(_removable_ports(taken, root) if taken else [])]:
            try:
                path.unlink()
                removed += 1
            except OSError:
                pass  # removed meanwhile, or not ours to remove
        return removed
    finally:
        mutexes.release()
