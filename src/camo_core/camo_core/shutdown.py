"""Ctrl-C and SIGTERM as a flag the spin loop checks, instead of an exception inside a callback.

rclpy's own handler shuts the context down under running callbacks, which then
fail mid-publish; a flag lets a process finish its current callback, stop
spinning and clean up in order.
"""

from __future__ import annotations

import signal


class StopFlag:
    def __init__(self) -> None:
        self.raised = False
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._set)

    def _set(self, signum, frame) -> None:
        self.raised = True

    def __bool__(self) -> bool:
        return self.raised
