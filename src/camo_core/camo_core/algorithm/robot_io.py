"""What a robot's step protocol takes in and gives out, and the hardware it is handed.

Messages between robots, reports for monitors, the output of one protocol
event; the sensor and display interfaces (a projected image and nothing, or a
Droplet's colour sensor and LED). No ROS here: a transport turns these into
camo_msgs messages.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

from camo_core.algorithm import rng
from camo_core.algorithm.grid import NUM_SLOTS
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.sensing import Reading

DISCOVERY, SENSING, CONSENSUS, FORMATION, DONE = range(5)
PHASE_NAMES = ("discovery", "sensing", "consensus", "formation", "done")
# The kinds of message (kinds_of): "energy" is --threshold auto's averaging of texture energy,
# in the sensing phase; "relay" --orientation any's passing on of states, in formation. Each
# kind is heard from the first LISTEN[kind] slots (docs/algorithm.md §1: vote 0-3, consensus
# 0-7; colours from 0-7 with --orientation any).
LISTEN = {"hello": NUM_SLOTS, "color": 4, "energy": 8, "vote": 8, "state": NUM_SLOTS, "relay": 8}
STREAM = {
    "hello": rng.STREAM_HELLO,
    "color": rng.STREAM_COLOR,
    "energy": rng.STREAM_ENERGY,
    "vote": rng.STREAM_CONSENSUS,
    "state": rng.STREAM_STATE,
    "relay": rng.STREAM_RELAY,
}
PHASE_OF = {
    "hello": DISCOVERY,
    "color": SENSING,
    "energy": SENSING,
    "vote": CONSENSUS,
    "state": FORMATION,
    "relay": FORMATION,
}


def listen_slots(params: CamoParams, near: int = 8, slots: int = NUM_SLOTS) -> dict[str, int]:
    """How many slots each kind is heard from in a run with these parameters; on a --layout,
    by a robot with `near` near neighbours among its `slots`."""
    if params.layout:
        return {"hello": slots, "color": near, "energy": near, "vote": near, "state": slots}
    return {**LISTEN, "color": 8} if params.orientation_any else LISTEN


NO_PATTERN = 255  # RobotStatus.PATTERN_NONE


def messages_per_round(params: CamoParams) -> dict[str, int]:
    """What each robot sends in a round it finishes: one hello, one colour, (--threshold auto)
    an energy per averaging step, a vote per consensus step, a state and (--orientation any) a
    relay per formation step (a recording of the run must hold them all)."""
    sent = {"hello": 1, "color": 1}
    if params.threshold_auto:
        sent["energy"] = params.consensus_steps
    sent |= {"vote": params.consensus_steps, "state": params.formation_steps}
    if params.orientation_any and not params.layout:  # a layout's robots hear two hops
        sent["relay"] = params.formation_steps
    return sent


def kinds_of(params: CamoParams) -> tuple[str, ...]:
    """The kinds of message a run's robots exchange (energies only with --threshold auto,
    relays only with --orientation any)."""
    return tuple(messages_per_round(params))


@dataclass(slots=True)
class Message:
    """What one robot sends its neighbours. `value`: hello (row, col); colour the sensed grey;
    energy (energy, degree); vote (p, degree); state 0 or 1; relay the states of slots 0-7
    for the same step as they reached the sender (None: did not)."""

    kind: str
    sender: int
    round: int
    step: int
    value: Any


@dataclass(slots=True)
class Report:
    """Where a robot is and what it shows, for monitors and recorders (a RobotStatus)."""

    sender_id: int
    row: int
    col: int
    phase: int
    step: int
    round: int
    sensed: float
    p: tuple[float, float, float]
    pattern: int
    state: int
    alive: bool
    known_slots: int
    deadlines: int
    silent: tuple[int, ...] = ()  # neighbours it has given up on (robot ids)
    # p before consensus step p_from, p_from + 1, ... (flattened): every p not yet reported, so
    # that reports spaced in time still give the monitor every step.
    p_from: int = 0
    p_trace: tuple[float, ...] = ()
    # The state before formation step state_from, state_from + 1, ..., likewise.
    state_from: int = 0
    state_trace: tuple[int, ...] = ()
    palette: tuple[int, ...] = ()  # --levels: the greys it can show, darkest first
    sensed_rgb: tuple[float, ...] = ()  # the colour it sensed (sRGB), once it has
    # --colours: its palette (sRGB triples, darkest first, flattened) and the two of them it
    # shows (palette indices: where its pattern is on, where it is off).
    palette_rgb: tuple[int, ...] = ()
    shades: tuple[int, ...] = ()


@dataclass
class Traces:
    """A robot's p before consensus step p_from, p_from + 1, ... (flattened, 3 a step) and its
    state before formation step state_from, ...: what no report carried yet. A report takes
    them (`unreported`) and they are let go: a robot keeps a few steps' traces, not a round's,
    whose floats would fill a big swarm's memory and push its working set out of the caches."""

    p: list[float] = field(default_factory=list)
    states: list[int] = field(default_factory=list)
    p_from: int = 0
    state_from: int = 0

    def unreported(self) -> dict[str, Any]:
        """A Report's trace fields: every p and state not reported yet (now they are)."""
        fields = {
            "p_from": self.p_from,
            "p_trace": tuple(self.p),
            "state_from": self.state_from,
            "state_trace": tuple(self.states),
        }
        self.p_from += len(self.p) // 3
        self.state_from += len(self.states)
        self.p, self.states = [], []
        return fields


@dataclass
class Output:
    send: list[Message] = field(default_factory=list)
    reports: list[Report] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


NOTHING = Output()  # what most deliveries produce (never to be appended to)


class Sensor(Protocol):
    def read(self) -> Reading | None:
        """This robot's grey value now, or None if it cannot be read yet (try again later)."""

    def next_round(self, frame: int) -> None:
        """A round on frame `frame` begins: later reads are of it."""

    def ok(self) -> bool:
        """The hardware behind the sensor is reachable."""


class Display(Protocol):
    def show(self, state: int, colour: tuple[int, int, int] | None = None) -> None:
        """Show the formation state; `colour`: what it shows as (--colours), if not the
        display's own colour for the state."""

    def ready(self) -> bool:
        """It shows the last state it was given."""

    def ok(self) -> bool: ...


class NoDisplay:
    """A simulated robot shows nothing."""

    def show(self, state: int, colour: tuple[int, int, int] | None = None) -> None:
        pass

    def ready(self) -> bool:
        return True

    def ok(self) -> bool:
        return True
