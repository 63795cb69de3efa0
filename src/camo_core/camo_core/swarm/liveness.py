"""Whether a process hosting robots is alive: a phi-accrual failure detector over its heartbeats.

Every process that hosts robots sends a heartbeat a few times a second, from a
thread of its own, however busy its robots keep it (one per process, not per
robot). A robot whose neighbour is late asks whether that neighbour's process
is alive; it gives up on the neighbour only when it is not. So a slow process
(overloaded, throttled, its loop seconds late) keeps its robots in the run,
and the run still computes what the simulator does; a killed process's robots
are given up on within one step timeout.

The detector is Hayashibara et al.'s phi accrual, as Akka and Cassandra use
it: from the intervals between a process's recent heartbeats (their mean and
spread, plus a pause it may take unannounced), phi says how unlikely the
silence so far is: phi 8 means a heartbeat this late would come once in 10^8
intervals of that process's own rhythm. A process that always beats slowly is
not suspected for beating slowly; one that falls silent is, sooner the more
regular it was. A silence as long as the step timeout is suspected whatever
the rhythm, so that a dead process costs its neighbours one timeout at most.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Hashable

HEARTBEAT_PERIOD = 0.25  # s between a process's heartbeats
PHI_THRESHOLD = 8.0  # suspected from this phi on
MIN_STD = 0.1  # s: the least spread assumed of a process's intervals (a too regular one)
WINDOW = 100  # intervals remembered per process


def phi(silence: float, mean: float, std: float) -> float:
    """-log10 of the probability that a heartbeat comes later than `silence` after the last
    one, the intervals being normal with this mean and deviation."""
    later = 0.5 * math.erfc((silence - mean) / (std * math.sqrt(2.0)))
    return -math.log10(later) if later > 0.0 else math.inf


class PhiAccrual:
    """One process's heartbeats, as one observer heard them (its own monotonic clock)."""

    def __init__(self, acceptable_pause: float, window: int = WINDOW) -> None:
        self.acceptable_pause = acceptable_pause
        self.intervals: deque[float] = deque(maxlen=window)
        self.last: float | None = None
        # The first interval is not yet known: assume the nominal period.
        self.intervals.append(HEARTBEAT_PERIOD)
        self.mean, self.std = HEARTBEAT_PERIOD, MIN_STD

    def heard(self, now: float) -> None:
        if self.last is not None and now >= self.last:
            self.intervals.append(now - self.last)
            # Once a heartbeat, not once a question: robots ask far more often.
            n = len(self.intervals)
            self.mean = sum(self.intervals) / n
            spread = math.sqrt(sum((x - self.mean) ** 2 for x in self.intervals) / n)
            self.std = max(spread, MIN_STD)
        self.last = now

    def phi(self, now: float) -> float:
        if self.last is None:
            return math.inf
        return phi(now - self.last, self.mean + self.acceptable_pause, self.std)

    def silence(self, now: float) -> float:
        return math.inf if self.last is None else now - self.last


class Liveness:
    """The processes of a run, by a key (a DDS participant's GUID prefix, say), and which robots
    each hosts. A robot is alive while its process is: heard, and not suspected."""

    def __init__(
        self,
        step_timeout: float,
        owner: Callable[[int], Hashable | None],
        clock: Callable[[], float],
        limit: int = 4096,
    ) -> None:
        """`owner(robot)`: the key of the process hosting it, or None if none announced it.
        A process may pause a third of the step timeout beyond its rhythm unsuspected; one
        silent for the whole timeout is suspected whatever its rhythm."""
        self.step_timeout = step_timeout
        self.acceptable_pause = step_timeout / 3.0
        self.owner = owner
        self.clock = clock
        self.limit = limit  # processes remembered at most: strangers cannot grow it for ever
        self.processes: dict[Hashable, PhiAccrual] = {}
        self.offline: dict[Hashable, frozenset[int]] = {}  # robots whose hardware is off

    def heard(self, process: Hashable, offline: frozenset[int] = frozenset()) -> bool:
        """A heartbeat of `process`, naming its robots whose hardware is offline; False if it is
        one process too many to remember."""
        detector = self.processes.get(process)
        if detector is None:
            if len(self.processes) >= self.limit:
                return False
            detector = self.processes[process] = PhiAccrual(self.acceptable_pause)
        detector.heard(self.clock())
        self.offline[process] = offline
        return True

    def process_alive(self, process: Hashable | None) -> bool:
        detector = self.processes.get(process) if process is not None else None
        if detector is None:
            return False
        now = self.clock()
        if detector.silence(now) >= self.step_timeout:
            return False
        return detector.phi(now) < PHI_THRESHOLD

    def robot_alive(self, robot: int) -> bool:
        process = self.owner(robot)
        return self.process_alive(process) and robot not in self.offline.get(process, ())
