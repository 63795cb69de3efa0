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

from collections import Counter, defaultdict
from dataclasses import dataclass, field

from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.robot_io import messages_per_round
from camo_core.algorithm.run_setup import contiguous
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


@dataclass
class Ledger:
    params: CamoParams | None = None
    rounds: int | None = None  # how many backgrounds the run was to camouflage
    counts: Counter = field(default_factory=Counter)  # (round, robot, kind) -> distinct steps
    steps: dict[tuple[int, int, str], bytearray] = field(default_factory=dict)
    done: dict[int, set[int]] = field(default_factory=lambda: defaultdict(set))  # round -> robots
    frames: set[int] = field(default_factory=set)  # the background frames recorded, by number
    result: dict | None = None  # the launcher's /<run>/swarm/result, once recorded
    limits: dict[str, int] = field(default_factory=dict)  # kind -> steps a robot sends
    results_expected: bool = True  # bags of runs before run ids hold no result
    continuous: bool = False  # rounds named by the frames' numbers (set_run)
    # complete_count's answers, and the rounds whose counts changed since (a continuous run's
    # recorder reports every round's, four times a second, for as long as the run goes).
    _counted: dict[int, int] = field(default_factory=dict)
    _changed: set[int] = field(default_factory=set)

    def set_run(self, params: CamoParams, rounds: int, continuous: bool = False) -> None:
        """`continuous`: its rounds are named by the frames' numbers (else the k-th background
        is round k's, however the projector numbered it)."""
        self.params, self.rounds, self.continuous = params, rounds, continuous
        self.limits = messages_per_round(params)
        self._counted.clear()  # what a round must hold is known now

    def message(self, kind: str, robot: int, round_index: int, step: int = 0) -> None:
        if not 0 <= step < self.limits.get(kind, MAX_STEP) or round_index < 0:
            return  # no robot of the run sends that
        key = (round_index, robot, kind)
        flags = self.steps.get(key)
        if flags is None:
            flags = self.steps[key] = bytearray()
        if step >= len(flags):
            flags.extend(bytes(step + 1 - len(flags)))
        if not flags[step]:
            flags[step] = 1
            self.counts[key] += 1
            self._changed.add(round_index)

    def background(self, number: int | None = None) -> None:
        """A background frame is recorded: a continuous run's by its number, the others' (and a
        frame of a camo before numbered frames) as the next."""
        numbered = number is not None and self.continuous
        frame = number if numbered else len(self.frames)
        self.frames.add(frame)
        self._changed.add(frame)

    @property
    def backgrounds(self) -> int:
        return len(self.frames)

    def reported_done(self, robot: int, round_index: int) -> None:
        self.done[round_index].add(robot)
        self._changed.add(round_index)

    def complete_count(self, round_index: int) -> int:
        """len(complete(round_index)), worked out again only when the round's messages changed."""
        if round_index in self._changed or round_index not in self._counted:
            self._counted[round_index] = len(self.complete(round_index))
            self._changed.discard(round_index)
        return self._counted[round_index]

    def set_result(self, result: dict) -> None:
        self.result = result

    def _holds(self, round_index: int, robot: int) -> bool:
        wanted = messages_per_round(self.params)
        return robot in self.done.get(round_index, ()) and all(
            self.counts[(round_index, robot, k)] >= n for k, n in wanted.items()
        )

    def complete(self, round_index: int) -> set[int]:
        """Robots whose whole round is recorded (done reported and every message there)."""
        if self.params is None or round_index not in self.frames:
            return set()
        return {r for r in self.done.get(round_index, ()) if self._holds(round_index, r)}

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
            kinds = [
                kind
                for kind, n in wanted.items()
                if any(self.counts[(k, r, kind)] < n for r in missing)
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
