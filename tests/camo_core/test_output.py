"""What a run writes at its end in a forked process of its own (results/output.Parallel)."""

import os
import signal
import time

import pytest

from camo_core.exceptions import CamoError
from camo_core.results.output import Parallel


def test_a_forked_writer_is_waited_for_and_its_file_is_whole(tmp_path):
    path = tmp_path / "out.txt"
    writer = Parallel(lambda: path.write_text("x" * 100_000))
    writer.wait("out.txt")
    assert path.read_text() == "x" * 100_000


def test_forked_works_draw_without_collecting_garbage_and_leave_the_parents_collector_on(
    tmp_path,
):
    import gc

    def says(name: str):
        return lambda: (tmp_path / name).write_text(str(gc.isenabled()))

    Parallel(says("first"), says("second")).wait("both")
    assert [(tmp_path / n).read_text() for n in ("first", "second")] == ["False", "False"]
    assert gc.isenabled()


def test_an_error_in_the_forked_writer_is_one_line_in_its_parent(capfd):
    def fails() -> None:
        raise ValueError("no disk")

    with pytest.raises(CamoError, match=r"writing run.gif failed \(exit code 1\)"):
        Parallel(fails).wait("run.gif")
    assert capfd.readouterr().err.strip() == "camo: error: ValueError: no disk"


def test_a_forked_writer_finishes_through_ctrl_c_and_stop_ends_it(tmp_path):
    # Ctrl-C goes to the whole foreground group: the writer leaves it to its parent (which
    # may wait for it); a writer its parent gives up on (stop) ends at once.
    done = tmp_path / "done"

    def slow() -> None:
        time.sleep(1.0)
        done.write_text("ok")

    writer = Parallel(slow)
    os.kill(writer.process.pid, signal.SIGINT)  # at once: before its handlers, held back
    writer.wait("done")
    assert done.read_text() == "ok"
    hung = Parallel(lambda: time.sleep(60))
    started = time.monotonic()
    hung.stop()
    assert time.monotonic() - started < 10 and hung.process.exitcode < 0  # by a signal


def test_a_forked_writer_that_hangs_is_stopped_after_the_limit_and_said():
    hung = Parallel(lambda: time.sleep(60))
    with pytest.raises(CamoError, match=r"writing run\.gif failed"):
        hung.wait("run.gif", limit=0.5)
    assert not hung.process.is_alive()


def test_works_run_side_by_side_after_one_shared_prepare(tmp_path):
    # figure.png and run.gif: matplotlib imported once (prepare), then each drawn in a process
    # of its own, at the same time.
    def prepare() -> None:
        (tmp_path / "prepared").write_text(str(os.getpid()))

    def work(name: str) -> None:
        assert (tmp_path / "prepared").exists()
        (tmp_path / f"{name}.start").write_text(str(os.getpid()))
        deadline = time.monotonic() + 20
        other = tmp_path / f"{'b' if name == 'a' else 'a'}.start"
        while not other.exists() and time.monotonic() < deadline:
            time.sleep(0.01)  # each waits for the other: neither runs after the other
        (tmp_path / name).write_text(str(other.exists()))

    Parallel(lambda: work("a"), lambda: work("b"), prepare=prepare).wait("a and b")
    pids = {(tmp_path / f"{name}.start").read_text() for name in "ab"}
    assert len(pids) == 2 and str(os.getpid()) not in pids
    assert (tmp_path / "prepared").read_text() in pids  # prepared in the first work's process
    assert (tmp_path / "a").read_text() == (tmp_path / "b").read_text() == "True"


def test_an_error_in_a_forked_work_is_one_line_and_stop_ends_every_work(tmp_path, capfd):
    def fails() -> None:
        raise OSError("disk full")

    with pytest.raises(CamoError, match=r"writing figure\.png and run\.gif failed"):
        Parallel(lambda: None, fails).wait("figure.png and run.gif")
    assert capfd.readouterr().err.strip() == "camo: error: OSError: disk full"
    pid_file, written = tmp_path / "pid", tmp_path / "pid.tmp"  # whole once it is there
    hung = Parallel(
        lambda: time.sleep(60),
        lambda: (written.write_text(str(os.getpid())), written.rename(pid_file), time.sleep(60)),
    )
    deadline = time.monotonic() + 20
    while not pid_file.exists() and time.monotonic() < deadline:
        time.sleep(0.01)
    hung.stop()
    pid = int(pid_file.read_text())
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and os.path.exists(f"/proc/{pid}") and "Z" not in state(pid):
        time.sleep(0.05)
    assert not os.path.exists(f"/proc/{pid}") or "Z" in state(pid)  # ended with its parent


def state(pid: int) -> str:
    try:
        return open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0]
    except OSError:
        return "gone"
