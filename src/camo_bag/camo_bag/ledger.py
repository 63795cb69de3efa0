"""What a recording holds of a run, against what the run's parameters say it must hold.

A robot that finished a round sent, in it, one hello, one colour, a vote per
consensus step and a state per formation step, and reported done. The ledger
counts, per round and robot, what was recorded; a round is complete for a
robot once all of it is there. No ROS here: the recorder and `bag info` feed
it decoded fields.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from dataclasses import dataclass, field

from camo_core.params import CamoParams
from camo_core.robot_io import messages_per_round


@dataclass
class Ledger:
    params: CamoParams | None = None
    rounds: int | None = None  # how many backgrounds the run was to camouflage
    counts: Counter = field(default_factory=Counter)  # (round, robot, kind) -> messages
    done: dict[int, set[int]] = field(default_factory=lambda: defaultdict(set))  # round -> robots
    backgrounds: int = 0

    def set_run(self, params: CamoParams, rounds: int) -> None:
        self.params, self.rounds = params, rounds

    def message(self, kind: str, robot: int, round_index: int) -> None:
        self.counts[(round_index, robot, kind)] += 1

    def reported_done(self, robot: int, round_index: int) -> None:
        self.done[round_index].add(robot)

    def complete(self, round_index: int) -> set[int]:
        """Robots whose whole round is recorded (done reported and every message there)."""
        if self.params is None or self.backgrounds <= round_index:
            return set()
        wanted = messages_per_round(self.params)
        return {
            robot
            for robot in self.done.get(round_index, ())
            if all(self.counts[(round_index, robot, k)] >= n for k, n in wanted.items())
        }

    def lacking(self, round_index: int) -> dict[str, int]:
        """Messages missing from robots that reported done in this round, by kind."""
        if self.params is None:
            return {}
        wanted = messages_per_round(self.params)
        short: Counter = Counter()
        for robot in self.done.get(round_index, ()):
            for kind, n in wanted.items():
                short[kind] += max(0, n - self.counts[(round_index, robot, kind)])
        return {kind: n for kind, n in short.items() if n}
