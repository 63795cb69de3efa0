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
