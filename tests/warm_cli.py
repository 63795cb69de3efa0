"""`python -m camo_core.cli ARGS` for the tests, each run in a child forked from a warm process.

A fresh process spends about 2.5 s of CPU around a small `camo sim`'s own work: starting
Python, importing NumPy, OpenCV, numba and camo_core, and matplotlib in each of the two
processes that draw figure.png and run.gif. The tests run such commands a few hundred times a
session, on two cores. Here one process per test process has done those imports once; each
command runs in a child forked from it, which starts where a fresh process stands after its
imports, with the command's own environment, working folder, arguments and output files, and
runs camo_core.cli as `python -m` does (runpy).

Nothing has run in the warm process but imports. numba's compiler is not started there (its
first use starts threads of LLVM's, which a forked child would not have): each child loads
the kernels from their cache itself, as a fresh process does. A command whose environment
differs from the one the warm process started with runs as a fresh process instead: what a
module reads from the environment as it is imported (NUMBA_*, MPL*, ...) would be the warm
process's."""

from __future__ import annotations

import atexit
import json
import os
import runpy
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

IGNORED = {"PYTEST_CURRENT_TEST"}  # pytest changes it test by test: no module's business


def environment() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k not in IGNORED}


# The environment a warm process starts with: the test process's as the session starts
# (`remember_environment`, called by tests/conftest.py: after what its imports change, such
# as OpenCV's LD_LIBRARY_PATH), or as it was when this was imported.
STARTED_WITH = environment()


def remember_environment() -> None:
    global STARTED_WITH
    STARTED_WITH = environment()


class Forked:
    """A command run in a child of the warm process, as far as the tests' `finished` uses a
    subprocess.Popen: args, pid, returncode, communicate(timeout)."""

    def __init__(self, server: Server, args: list[str], pid: int, out: Path, err: Path) -> None:
        self.server, self.args, self.pid = server, args, pid
        self.out, self.err = out, err
        self.returncode: int | None = None

    def communicate(self, timeout: float | None = None) -> tuple[str, str]:
        if self.returncode is None:
            self.returncode = self.server.exit_code(timeout, self.args)
        try:
            return self.out.read_text(errors="replace"), self.err.read_text(errors="replace")
        finally:
            self.out.unlink(missing_ok=True)
            self.err.unlink(missing_ok=True)


class Server:
    """The warm process, started when first needed, one per test process."""

    def __init__(self) -> None:
        self.proc: subprocess.Popen | None = None
        self.folder = Path(tempfile.mkdtemp(prefix="camo-warm-cli-"))
        self.count = 0
        self.reader: threading.Thread | None = None  # waiting for a command's exit code
        self.reply: list[str] = []
        atexit.register(self.close)

    def close(self) -> None:
        """Ends the warm process (its requests end) and removes the output files' folder."""
        if self.proc is not None and self.proc.stdin:
            self.proc.stdin.close()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
        shutil.rmtree(self.folder, ignore_errors=True)

    def start(self, args: list[str], env: dict[str, str], cwd: Path) -> Forked:
        if self.proc is None or self.proc.poll() is not None:
            self.proc = subprocess.Popen(
                [sys.executable, __file__],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                env=STARTED_WITH,
                text=True,
            )
        self.count += 1
        out, err = (self.folder / f"{self.count}.{name}" for name in ("out", "err"))
        request = {"args": args, "env": env, "cwd": str(cwd), "out": str(out), "err": str(err)}
        assert self.proc.stdin and self.proc.stdout
        self.proc.stdin.write(json.dumps(request) + "\n")
        self.proc.stdin.flush()
        pid = json.loads(self.proc.stdout.readline())["pid"]
        return Forked(self, ["python", "-m", "camo_core.cli", *args], pid, out, err)

    def exit_code(self, timeout: float | None, args: list[str]) -> int:
        """The running command's exit code (as subprocess gives it: -N for a signal N), once it
        has ended; subprocess.TimeoutExpired if it has not in `timeout` s (it runs on, and a
        later call waits for it again)."""
        if self.reader is None:
            assert self.proc and self.proc.stdout
            stdout = self.proc.stdout
            self.reply.clear()
            self.reader = threading.Thread(target=lambda: self.reply.append(stdout.readline()))
            self.reader.start()
        self.reader.join(timeout)
        if self.reader.is_alive():
            raise subprocess.TimeoutExpired(args, timeout or 0.0)
        self.reader = None
        if not self.reply[0]:
            raise RuntimeError("the warm process (tests/warm_cli.py) ended: see its stderr")
        return json.loads(self.reply[0])["code"]


_server: Server | None = None


def run(args: list[str], cwd: Path):
    """A Forked child running `python -m camo_core.cli *args`, or None where a fresh process
    must run it (an environment other than the warm process's)."""
    global _server
    if environment() != STARTED_WITH:
        return None
    if _server is None:
        _server = Server()
    return _server.start(args, dict(os.environ), cwd)


# ---- the warm process ---------------------------------------------------------------------


def warm() -> None:
    """What every `camo` command's process imports, done once (numba's kernels excepted)."""
    import camo_core.algorithm.jit  # numba, as camo loads it; its compiler starts in the child
    import camo_core.cli.commands
    import camo_core.results.animation  # matplotlib
    import camo_core.results.figures  # noqa: F401

    assert "camo_core.algorithm.kernels" not in sys.modules, "numba's compiler would start"
    assert threading.active_count() == 1, "a thread in the warm process: forking would lose it"


def child(request: dict) -> None:
    """In the forked child: the command's environment, folder, files and arguments, then
    camo_core.cli as `python -m` runs it (its SystemExit, or a traceback, ends the process)."""
    os.environ.clear()
    os.environ.update(request["env"])
    os.chdir(request["cwd"])
    for fd, path, flags in (
        (0, os.devnull, os.O_RDONLY),
        (1, request["out"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC),
        (2, request["err"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC),
    ):
        opened = os.open(path, flags, 0o644)
        os.dup2(opened, fd)
        os.close(opened)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    sys.argv = ["-m", *request["args"]]
    runpy.run_module("camo_core.cli", run_name="__main__", alter_sys=True)


def serve() -> None:
    """Requests (a JSON line each) on stdin; for each, the child's pid, then its exit code."""
    requests = os.fdopen(os.dup(0), "r")
    replies = os.fdopen(os.dup(1), "w")
    null = os.open(os.devnull, os.O_RDWR)
    os.dup2(null, 0)
    os.dup2(null, 1)
    warm()
    for line in requests:
        request = json.loads(line)
        pid = os.fork()
        if pid == 0:
            requests.close()
            replies.close()
            child(request)
            return  # the command ended without SystemExit: exit code 0, as python -m
        replies.write(json.dumps({"pid": pid}) + "\n")
        replies.flush()
        _, status = os.waitpid(pid, 0)
        replies.write(json.dumps({"code": os.waitstatus_to_exitcode(status)}) + "\n")
        replies.flush()


if __name__ == "__main__":
    serve()
