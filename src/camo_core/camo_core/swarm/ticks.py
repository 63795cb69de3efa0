"""Which of a process's robots to tick: those whose deadline is due, not all of them.

A tick lets a robot's deadline pass (`protocol.py`); most robots are not near
one. Ticking every robot every TICK costs a process of 16384 robots more than
its messages do, so a host keeps the robots in a heap by `due()` and ticks
only those due, a bounded number per turn. A robot that stepped since it was
queued is due later: it is ticked once for nothing and queued again, which
costs far less than keeping the heap exact on every step.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Sequence
from typing import Protocol

from camo_core.swarm.protocol import RECHECK, STALL, TICK


class Ticked(Protocol):
    def due(self) -> float: ...

    def stalled(self, seconds: float) -> None: ...


class Ticks:
    """A heap of (due, robot index) over a host's robots' protocols."""

    def __init__(self, protocols: Sequence[Ticked]) -> None:
        self.protocols = protocols
        self._heap: list[tuple[float, int]] = []
        self._queued: dict[int, float] = {}  # robot index -> its due in the heap
        self.last: float | None = None

    def add(self, index: int, now: float) -> None:
        """Queue a robot at its due (no sooner than now + TICK past a deadline that did not let
        it step: its neighbours are alive, it asks again every RECHECK)."""
        due = self.protocols[index].due()
        if due == math.inf:
            return
        if due <= now:
            due = now + (TICK if due == -math.inf else RECHECK)
        queued = self._queued.get(index)
        if queued is not None and queued <= due:
            return
        self._queued[index] = due
        heapq.heappush(self._heap, (due, index))

    def add_all(self, now: float) -> None:
        """Every robot, at its due (after a start or a new background)."""
        for index in range(len(self.protocols)):
            self.add(index, now)

    def due(self, now: float, limit: int) -> list[int]:
        """Up to `limit` robots whose due has come (taken out of the heap: `add` them back)."""
        heap, queued = self._heap, self._queued
        out: list[int] = []
        while heap and heap[0][0] <= now and len(out) < limit:
            due, index = heapq.heappop(heap)
            if queued.get(index) == due:
                del queued[index]
                out.append(index)
        return out

    def stall(self, now: float) -> float:
        """How long the process stalled before this tick (0 if it did not), discounted from
        every robot's deadline: a late tick is this process's fault, not its neighbours'."""
        last, self.last = self.last, now
        if last is None:
            return 0.0
        stalled = now - last - TICK
        if stalled <= STALL:
            return 0.0
        for protocol in self.protocols:
            protocol.stalled(stalled)
        # The heap's dues moved with them: queue everyone again at the new ones.
        self._heap.clear()
        self._queued.clear()
        self.add_all(now)
        return stalled
