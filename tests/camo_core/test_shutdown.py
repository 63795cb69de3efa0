"""What a camo process does on signals: Ctrl-C as a flag, and on a crash or SIGUSR1 every
thread's stack on stderr (what a hung or crashed process was doing is in its output)."""

import os
import signal
import subprocess
import sys
import time

import pytest
from support import PROCESS

SLEEPER = """
import sys, time
from camo_core.shutdown import StopFlag
stop = StopFlag()
print("ready", flush=True)
def waiting_for_the_test():
    while not stop:
        time.sleep(0.05)
waiting_for_the_test()
print("stopped", flush=True)
"""


def sleeper() -> subprocess.Popen:
    proc = subprocess.Popen(
        [sys.executable, "-c", SLEEPER], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    assert proc.stdout.readline() == "ready\n"
    return proc


@pytest.mark.slow(PROCESS)
def test_sigusr1_writes_every_threads_stack_and_the_process_goes_on():
    proc = sleeper()
    time.sleep(0.3)  # in its loop
    proc.send_signal(signal.SIGUSR1)
    time.sleep(0.3)
    assert proc.poll() is None
    proc.send_signal(signal.SIGINT)  # the stop flag: it ends by itself
    out, err = proc.communicate(timeout=10)
    assert proc.returncode == 0 and out == "stopped\n"
    assert "waiting_for_the_test" in err and "most recent call first" in err


@pytest.mark.slow(PROCESS)
def test_a_crash_writes_the_stack_it_crashed_in():
    crash = SLEEPER.replace("time.sleep(0.05)", "import ctypes; ctypes.string_at(0)")
    argv = [sys.executable, "-c", crash]
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=10)
    assert proc.returncode == -signal.SIGSEGV
    assert "Segmentation fault" in proc.stderr and "waiting_for_the_test" in proc.stderr


@pytest.mark.slow(PROCESS)
def test_a_module_interrupted_while_it_imports_ends_as_sigint_does_without_a_traceback(tmp_path):
    """How a launcher starts its processes: one stopped before it set its own handlers (still
    importing rclpy, say) says nothing and dies by SIGINT, as its launcher expects."""
    (tmp_path / "slow_import.py").write_text(
        "import sys, time\nprint('importing', flush=True)\ntime.sleep(30)\n"
    )
    proc = subprocess.Popen(
        [sys.executable, "-m", "camo_core.shutdown", "slow_import", "--an-argument"],
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": f"{tmp_path}:{os.environ.get('PYTHONPATH', '')}"},
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout.readline() == "importing\n"
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=10)
    assert proc.returncode == -signal.SIGINT
    assert "Traceback" not in err and "KeyboardInterrupt" not in err


@pytest.mark.slow(PROCESS)
def test_a_module_run_through_shutdown_gets_its_arguments_and_exit_code(tmp_path):
    (tmp_path / "echo_args.py").write_text(
        "import sys\nif __name__ == '__main__':\n    print(sys.argv[1:])\n    sys.exit(3)\n"
    )
    proc = subprocess.run(
        [sys.executable, "-m", "camo_core.shutdown", "echo_args", "a", "--b"],
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": f"{tmp_path}:{os.environ.get('PYTHONPATH', '')}"},
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert proc.returncode == 3 and proc.stdout == "['a', '--b']\n"


EXITING = """
import atexit, multiprocessing, os, sys, time
from camo_core.shutdown import exit_at_once
atexit.register(lambda: print("exit handler ran", file=sys.stderr))
child = multiprocessing.get_context("fork").Process(target=time.sleep, args=(60,), daemon=True)
child.start()
print(child.pid)
sys.stdout.write("unflushed")
exit_at_once(4)
"""


def test_exiting_at_once_keeps_the_exit_code_the_output_the_exit_handlers_and_ends_daemons():
    """A command that ends without the interpreter's teardown still says all it wrote, runs the
    exit handlers (multiprocessing's ends its daemon processes) and exits with its code."""
    proc = subprocess.run(
        [sys.executable, "-c", EXITING], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 4
    pid, rest = proc.stdout.split("\n")
    assert rest == "unflushed"
    assert proc.stderr == "exit handler ran\n"
    with pytest.raises(ProcessLookupError):  # the daemon ended with it, reaped by multiprocessing
        os.kill(int(pid), 0)
