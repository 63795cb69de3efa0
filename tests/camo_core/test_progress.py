"""The progress bar of long runs: a resumed job starts where it was, and its ETA comes from the
rate of what it does now."""

import io

from camo_core.cli.progress import ProgressBar


def test_a_resumed_bar_starts_where_it_was_and_times_only_the_new_work(monkeypatch):
    clock = iter([100.0, 110.0])
    monkeypatch.setattr("camo_core.cli.progress.time.monotonic", lambda: next(clock))
    stream = io.StringIO()
    bar = ProgressBar(1000, "sweep", stream=stream, already=900)
    bar.update(950)  # 50 done in 10 s: 50 left take 10 s more
    line = stream.getvalue().strip()
    assert line.startswith("sweep 950/1000  95%") and "eta  10.0s" in line, line
