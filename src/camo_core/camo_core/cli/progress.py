"""A small progress bar on stderr for long runs (a plain line per 10 % when not a terminal)."""

from __future__ import annotations

import sys
import time


class ProgressBar:
    def __init__(self, total: int, label: str, stream=None, already: int = 0) -> None:
        """already: of `total`, what was done before (a resumed sweep's): the bar starts there
        and the ETA counts from the rate of what is done now."""
        self.total = max(1, total)
        self.label = label
        self.stream = stream or sys.stderr
        self.done = self.already = already
        self.start = time.monotonic()
        self._last_decile = -1
        self._tty = self.stream.isatty()

    def update(self, done: int | None = None, note: str = "") -> None:
        self.done = self.done + 1 if done is None else done
        fraction = min(1.0, self.done / self.total)
        elapsed = time.monotonic() - self.start
        now = self.done - self.already
        eta = elapsed / now * (self.total - self.done) if now > 0 else 0.0
        text = (
            f"{self.label} {self.done}/{self.total} {fraction:4.0%} elapsed {elapsed:5.1f}s "
            f"eta {eta:5.1f}s {note}"
        )
        if self._tty:
            filled = int(30 * fraction)
            self.stream.write(f"\r[{'#' * filled}{'.' * (30 - filled)}] {text}\x1b[K")
            if self.done >= self.total:
                self.stream.write("\n")
        else:
            decile = int(fraction * 10)
            if decile != self._last_decile:
                self._last_decile = decile
                self.stream.write(text + "\n")
        self.stream.flush()
