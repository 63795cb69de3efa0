"""Ctrl-C and SIGTERM, for ROS processes as a flag the spin loop checks, for the others as
KeyboardInterrupt.

rclpy's own handler shuts the context down under running callbacks, which then
fail mid-publish; a flag lets a process finish its current callback, stop
spinning and clean up in order.

Both install their handlers whatever the process inherited: a job a script starts
in the background inherits SIGINT ignored, and Python then leaves it ignored, so
Ctrl-C (or a launcher's SIGINT) would not stop it.
"""

from __future__ import annotations

import atexit
import faulthandler
import os
import runpy
import signal
import sys


def exit_at_once(code: int) -> None:
    """End a command's process that has done its work: its exit handlers run (multiprocessing's
    ends the daemon processes it started) and its streams are flushed, but the interpreter is
    not torn down. Teardown only frees what exit frees anyway, and after numba's compiler has
    run it takes about 0.25 s (llvmlite's), a tenth of a 1024x1024 `camo sim`. Whatever the
    command wrote it closed itself."""
    atexit._run_exitfuncs()
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except OSError:  # a closed pipe: what was left to say has nowhere to go
        pass
    os._exit(code)


def stacks_on_faults() -> None:
    """A crash (SIGSEGV, SIGABRT, ...) writes every thread's Python stack to stderr before the
    process dies, and SIGUSR1 writes them and goes on: what a process hung or crashed in is
    in its output (the tests send SIGUSR1 to a process that does not end in time)."""
    stderr = sys.__stderr__  # the process's own: sys.stderr may be replaced (pytest's capture)
    if stderr is None:
        return  # no stderr to write to (pythonw, a daemon)
    if not faulthandler.is_enabled():
        faulthandler.enable(stderr, all_threads=True)
    faulthandler.register(signal.SIGUSR1, stderr, all_threads=True)


def quiet_on_a_closed_pipe() -> None:
    """A tool whose output is piped into one that stops reading (`| head`) ends quietly, as
    Unix tools do, instead of a BrokenPipeError traceback."""
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)


class StopFlag:
    def __init__(self) -> None:
        stacks_on_faults()
        self.raised = False
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._set)

    def _set(self, signum, frame) -> None:
        self.raised = True

    def __bool__(self) -> bool:
        return self.raised


def interrupt_on_signals() -> None:
    """Ctrl-C and SIGTERM raise KeyboardInterrupt in the main thread, even in a process that
    inherited SIGINT ignored."""
    stacks_on_faults()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.default_int_handler)


def run_module(module: str, args: list[str]) -> None:
    """`python -m module args`, but a Ctrl-C that reaches the module before it has set its own
    handlers (while it imports rclpy, say) ends it as a SIGINT does, without Python's
    KeyboardInterrupt traceback: a launcher stopping a run whose processes are still starting
    leaves one line of its own, not a stack per process. The exit status stays death by SIGINT
    (what a caller waiting for the process sees)."""
    sys.argv = [module, *args]
    try:
        runpy.run_module(module, run_name="__main__", alter_sys=True)
    except KeyboardInterrupt:
        sys.stderr.flush()
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        os.kill(os.getpid(), signal.SIGINT)


if __name__ == "__main__":
    # python -m camo_core.shutdown MODULE ARGS...: how a launcher starts its processes.
    run_module(sys.argv[1], sys.argv[2:])
