"""What a recording holds of a run, against what the run says it must hold.

A robot that finished a round sent, in it, one hello, one colour, (with
--threshold auto) an energy per averaging step, a vote per consensus step and a
state per formation step, and reported done. The ledger
counts, per round and robot, the distinct steps recorded of each kind (a
message heard twice, or a stranger's copy, counts once); a round is complete
for a robot once all of it is there. What a bag must hold comes from the run's
result (`/<run>/swarm/result`, published by the launcher at the end: the
rounds it ran and which robots finished each) or, for a bag without one, from
the run's parameters (every robot, every background). No ROS here: the
recorder and `bag info` feed it decoded fields.
"""

from __future__ import annotations

import bisect
import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from camo_core.algorithm.params import CamoParams
from camo_core.swarm.robot_io import messages_per_round
from camo_core.swarm.run_setup import contiguous
from camo_nodes.topics.robot_messages import ARRAY_TYPES, COLUMN_TYPES, MESSAGE_TYPES

MAX_STEP = 1_000_000  # before the run's parameters are known: no step of a run is beyond this


def _kinds(types: dict) -> dict[str, str]:
    return {f"camo_msgs/msg/{cls.__name__}": kind for kind, cls in types.items()}


# The robots' message types, and the kind of message each carries. A tile topic carries a
# tile's messages as columns (one DDS message for what its robots sent since the last write);
# bags of older camo hold arrays of robot messages, or one robot message per bag message.
COLUMN_KINDS = _kinds(COLUMN_TYPES)
ARRAY_KINDS = _kinds(ARRAY_TYPES)
SINGLE_KINDS = _kinds(MESSAGE_TYPES)
ROBOT_KINDS = {**COLUMN_KINDS, **ARRAY_KINDS, **SINGLE_KINDS}


ACTIVE_ROUNDS = 8  # a continuous run's rounds whose messages are counted robot by robot


class Frames:
    """Frame numbers as ranges of consecutive ones: a stream's frames, ten a second for as long
    as a run goes, take a few numbers (a set of them took 60 MB a day)."""

    def __init__(self) -> None:
        self._ranges: list[list[int]] = []  # [first, last], in order
        self._count = 0

    def add(self, number: int) -> None:
        if number in self:
            return
        self._count += 1
        at = bisect.bisect(self._ranges, [number, math.inf])
        before = self._ranges[at - 1] if at else None
        after = self._ranges[at] if at < len(self._ranges) else None
        if before is not None and before[1] == number - 1:
            before[1] = number
            if after is not None and after[0] == number + 1:
                before[1] = after[1]
                del self._ranges[at]
        elif after is not None and after[0] == number + 1:
            after[0] = number
        else:
            self._ranges.insert(at, [number, number])

    def __contains__(self, number: object) -> bool:
        if not isinstance(number, int):
            return False
        at = bisect.bisect(self._ranges, [number, math.inf])
        return bool(at) and self._ranges[at - 1][1] >= number

    def __len__(self) -> int:
        return self._count


@dataclass
class Ledger:
    params: CamoParams | None = None
    rounds: int | None = None  # how many backgrounds the run was to camouflage
    # Per round, per (robot, kind): the distinct steps recorded (flags) and how many. A robot
    # whose round is whole (done reported, every message there) is let go of them and flagged
    # in `whole`, a byte per robot; a continuous run's rounds older than its ACTIVE_ROUNDS
    # latest keep those flags as ranges of robots: a long run's ledger grows by a few numbers
    # a round.
    counts: dict[int, Counter] = field(default_factory=dict)
    steps: dict[int, dict[tuple[int, str], bytearray]] = field(default_factory=dict)
    done: dict[int, set[int]] = field(default_factory=dict)  # round -> robots done, not whole
    whole: dict[int, bytearray | tuple] = field(default_factory=dict)  # round -> whole robots
    frames: Frames = field(default_factory=Frames)  # the background frames recorded, by number
    result: dict | None = None  # the launcher's /<run>/swarm/result, once recorded
    limits: dict[str, int] = field(default_factory=dict)  # kind -> steps a robot sends
    results_expected: bool = True  # bags of runs before run ids hold no result
    continuous: bool = False  # rounds named by the frames' numbers (set_run)
    distinct: int = 0  # robot messages recorded, each robot's step of a kind once
    # A continuous run's rounds older than its ACTIVE_ROUNDS latest are settled: robots not
    # whole then stay so (the kinds they lacked kept, `_settled`), their messages ignored.
    _settled: dict[int, frozenset[str]] = field(default_factory=dict)
    _settled_below: int = 0
    _alike: dict = field(default_factory=dict)
    # complete_count's answers, and the rounds whose counts changed since (a continuous run's
    # recorder reports its latest rounds', four times a second, for as long as the run goes).
    _counted: dict[int, int] = field(default_factory=dict)
    _changed: set[int] = field(default_factory=set)

    def set_run(self, params: CamoParams, rounds: int, continuous: bool = False) -> None:
        """`continuous`: its rounds are named by the frames' numbers (else the k-th background
        is round k's, however the projector numbered it)."""
        self.params, self.rounds, self.continuous = params, rounds, continuous
        self.limits = messages_per_round(params)
        self._counted.clear()  # what a round must hold is known now
        for round_index, robots in list(self.done.items()):  # those whole already
            for robot in list(robots):
                self._check_whole(round_index, robot)

    def message(self, kind: str, robot: int, round_index: int, step: int = 0) -> None:
        if not 0 <= step < self.limits.get(kind, MAX_STEP) or round_index < 0:
            return  # no robot of the run sends that
        if not self._open(round_index, robot):
            return
        flags = self.steps.setdefault(round_index, {}).setdefault((robot, kind), bytearray())
        if step >= len(flags):
            flags.extend(bytes(step + 1 - len(flags)))
        if not flags[step]:
            flags[step] = 1
            self.distinct += 1
            counts = self.counts.setdefault(round_index, Counter())
            counts[(robot, kind)] += 1
            self._mark(round_index)
            if counts[(robot, kind)] == self.limits.get(kind):
                self._check_whole(round_index, robot)

    def _open(self, round_index: int, robot: int) -> bool:
        """Whether a message of this robot in this round still counts: not once its round is
        whole or settled. A round not seen before may settle the oldest."""
        if round_index in self._settled or (self.continuous and round_index < self._settled_below):
            return False
        if self._whole(round_index, robot) or isinstance(self.whole.get(round_index), tuple):
            return False  # whole, or a round settled with its flags packed
        if self.continuous and round_index not in self.counts and round_index not in self.done:
            active = set(self.counts) | set(self.done)
            while len(active) >= ACTIVE_ROUNDS:
                oldest = min(active)
                if oldest > round_index:
                    return False  # older than every round counted: settled already
                self._settle(oldest)
                active.discard(oldest)
            latest = sorted(active | set(self.whole) | {round_index})[-ACTIVE_ROUNDS:]
            for old, flags in list(self.whole.items()):
                if old < latest[0] and isinstance(flags, bytearray):
                    robots = np.flatnonzero(np.frombuffer(flags, np.uint8)).tolist()
                    self.whole[old] = self._shared(tuple(contiguous(robots)))
            for old in [k for k in self._counted if k < latest[0]]:
                del self._counted[old]
        return True

    def _check_whole(self, round_index: int, robot: int) -> None:
        """The robot's round is whole: its flags and counts are let go."""
        if self.params is None or not self._holds(round_index, robot):
            return
        whole = self.whole.setdefault(round_index, bytearray(self.params.count))
        if 0 <= robot < len(whole):
            whole[robot] = 1
        for kind in self.limits:
            self.steps.get(round_index, {}).pop((robot, kind), None)
            self.counts.get(round_index, Counter()).pop((robot, kind), None)
        self.done.get(round_index, set()).discard(robot)
        for table in (self.steps, self.counts, self.done):
            if round_index in table and not table[round_index]:
                del table[round_index]
        self._mark(round_index)

    def _shared(self, value):
        """One object for what many rounds hold alike (all robots whole, the same kinds lacked)."""
        return self._alike.setdefault(value, value)

    def _mark(self, round_index: int) -> None:
        """The round's complete_count is to be worked out again (if it was)."""
        if round_index in self._counted:
            self._changed.add(round_index)

    def _settle(self, round_index: int) -> None:
        """A continuous run's round that is no longer counted robot by robot: what its robots
        that are not whole lacked, by kind (for `gaps`), and nothing else."""
        wanted = messages_per_round(self.params) if self.params is not None else {}
        counts = self.counts.pop(round_index, Counter())
        robots = {robot for robot, _ in counts} | self.done.get(round_index, set())
        lacked = {k for k, n in wanted.items() for r in robots if counts[(r, k)] < n}
        if any(r not in self.done.get(round_index, ()) for r in robots):
            lacked.add("done reports")
        self._settled[round_index] = self._shared(frozenset(lacked))
        self.steps.pop(round_index, None)
        self.done.pop(round_index, None)
        self._settled_below = max(self._settled_below, round_index + 1)
        self._counted.pop(round_index, None)
        self._changed.discard(round_index)

    def background(self, number: int | None = None) -> None:
        """A background frame is recorded: a continuous run's by its number, the others' (and a
        frame of a camo before numbered frames) as the next."""
        numbered = number is not None and self.continuous
        frame = number if numbered else len(self.frames)
        self.frames.add(frame)
        self._mark(frame)

    @property
    def backgrounds(self) -> int:
        return len(self.frames)

    def reported_done(self, robot: int, round_index: int) -> None:
        if not self._open(round_index, robot):
            return
        self.done.setdefault(round_index, set()).add(robot)
        self._mark(round_index)
        self._check_whole(round_index, robot)

    def latest_rounds(self, most: int = ACTIVE_ROUNDS) -> list[int]:
        """The `most` latest rounds robots reported done in (what a recorder reports)."""
        return sorted(set(self.done) | set(self.whole))[-most:]

    def complete_count(self, round_index: int) -> int:
        """len(complete(round_index)), worked out again only when the round's messages changed."""
        if round_index in self._changed or round_index not in self._counted:
            self._counted[round_index] = len(self.complete(round_index))
            self._changed.discard(round_index)
        return self._counted[round_index]

    def set_result(self, result: dict) -> None:
        self.result = result

    def _whole(self, round_index: int, robot: int) -> bool:
        whole = self.whole.get(round_index)
        if whole is None:
            return False
        if isinstance(whole, bytearray):
            return 0 <= robot < len(whole) and bool(whole[robot])
        at = bisect.bisect(whole, (robot, math.inf))
        return bool(at) and whole[at - 1][1] >= robot

    def _whole_robots(self, round_index: int) -> set[int]:
        whole = self.whole.get(round_index, b"")
        if isinstance(whole, bytearray | bytes):
            return set(np.flatnonzero(np.frombuffer(whole, np.uint8)).tolist())
        return {r for first, last in whole for r in range(first, last + 1)}

    def _holds(self, round_index: int, robot: int) -> bool:
        if self._whole(round_index, robot):
            return True
        counts = self.counts.get(round_index, Counter())
        wanted = messages_per_round(self.params)
        return robot in self.done.get(round_index, ()) and all(
            counts[(robot, k)] >= n for k, n in wanted.items()
        )

    def complete(self, round_index: int) -> set[int]:
        """Robots whose whole round is recorded (done reported and every message there)."""
        if self.params is None or round_index not in self.frames:
            return set()
        held = self._whole_robots(round_index)
        return held | {r for r in self.done.get(round_index, ()) if self._holds(round_index, r)}

    def lacking(self, round_index: int) -> dict[str, int]:
        """Messages missing from robots that reported done in this round, by kind."""
        if self.params is None:
            return {}
        wanted = messages_per_round(self.params)
        counts = self.counts.get(round_index, Counter())
        short: Counter = Counter()
        for robot in self.done.get(round_index, ()):
            for kind, n in wanted.items():
                short[kind] += max(0, n - counts[(robot, kind)])
        return {kind: n for kind, n in short.items() if n}

    # ---- what a finished recording lacks ------------------------------------------------

    def expected(self) -> dict[int, set[int]]:
        """Per round the bag must hold (by its frame number), the robots that must be whole in
        it. The result names a continuous run's rounds; the others' are 0, 1, ..."""
        if self.result is not None:
            rounds = self.result.get("rounds", [])
            return {
                int(r.get("round", k)): set(cells(r.get("finished", [])))
                for k, r in enumerate(rounds)
            }
        if self.params is None:
            return {}
        return {k: set(range(self.params.count)) for k in range(self.rounds or 1)}

    def gaps(self) -> list[str]:
        """What the bag lacks of the run, one line per round (or for the whole bag); none when
        the bag is complete."""
        if self.params is None:
            return ["the run's parameters are not in the bag"]
        lines = []
        if self.result is None and self.results_expected:
            lines.append("the run's result is not in the bag (the recording stopped first)")
        elif self.result is not None and self.result.get("ended") != "finished":
            lines.append(f"the run ended early ({self.result.get('ended')}): not every round ran")
        wanted = messages_per_round(self.params)
        for k, robots in self.expected().items():
            if k not in self.frames:
                lines.append(f"round {k}: its background is not in the bag")
            missing = sorted(r for r in robots if not self._holds(k, r))
            if not missing:
                continue
            counts = self.counts.get(k, Counter())
            if k in self._settled:  # what its robots lacked when it was settled
                kinds = [kind for kind in wanted if kind in self._settled[k]]
                kinds += ["done reports"] if "done reports" in self._settled[k] else []
                kinds = kinds or [*wanted, "done reports"]  # robots it never heard of
            else:
                kinds = [
                    kind
                    for kind, n in wanted.items()
                    if any(counts[(r, kind)] < n for r in missing)
                ]
                if any(r not in self.done.get(k, ()) for r in missing):
                    kinds.append("done reports")
            lines.append(
                f"round {k}: {robots_lack(len(missing))} {', '.join(map(plural, kinds))}: "
                f"{ranges_text(missing)}"
            )
        return lines


def gaps_of_round(gaps: list[str], round_index: int) -> list[str]:
    """The gaps that concern one round: its own, and those of the whole bag."""
    return [g for g in gaps if not g.startswith("round ") or g.startswith(f"round {round_index}:")]


def robots_lack(n: int) -> str:
    return "1 robot lacks" if n == 1 else f"{n} robots lack"


def plural(kind: str) -> str:
    names = {"hello": "hellos", "color": "colours", "energy": "energies", "vote": "votes"}
    return {**names, "state": "states", "relay": "relays"}.get(kind, kind)


def cells(ranges: list) -> list[int]:
    """[[first, last], ...] as robot ids (bounded: a range is at most a million robots)."""
    out = []
    for pair in ranges:
        first, last = int(pair[0]), int(pair[1])
        if 0 <= first <= last < first + 1_000_000:
            out.extend(range(first, last + 1))
    return out


def ranges_text(robots: list[int], most: int = 12) -> str:
    """3-9, 12, 15-20 ... (the first `most` ranges)."""
    spans = contiguous(robots)
    text = ", ".join(f"{a}-{b}" if a != b else str(a) for a, b in spans[:most])
    return text + (" ..." if len(spans) > most else "")
