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


def interrupt_on_signals() -> None:
    """Ctrl-C and SIGTERM raise KeyboardInterrupt in the main thread, even in a process that
    inherited SIGINT ignored."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.default_int_handler)
