"""What a robot's step protocol takes in and gives out, and the hardware it is handed.

Messages between robots, reports for monitors, the output of one protocol
event; the sensor and display interfaces (a projected image and nothing, or a
Droplet's colour sensor and LED). No ROS here: a transport turns these into
camo_msgs messages.
"""

from __future__ import annotations

from dataclasses import MISSING, dataclass, field, fields
from typing import Any, Protocol

import numpy as np

from camo_core.algorithm import rng
from camo_core.algorithm.grid import NUM_SLOTS
from camo_core.algorithm.modes import modes_of
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.sensing import Reading

DISCOVERY, SENSING, CONSENSUS, FORMATION, DONE = range(5)
PHASE_NAMES = ("discovery", "sensing", "consensus", "formation", "done")
# The kinds of message (kinds_of): "energy" is --threshold auto's averaging of texture energy,
# in the sensing phase; "relay" --orientation any's passing on of states, in formation. Each
# kind is heard from the first slots its layout says (modes.layouts.Grid.listen).
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
    modes = modes_of(params)
    return modes.layout.listen(modes.descriptor.colour_slots, near, slots)


NO_PATTERN = 255  # RobotStatus.PATTERN_NONE


def messages_per_round(params: CamoParams) -> dict[str, int]:
    """What each robot sends in a round it finishes: one hello, one colour, (--threshold auto)
    an energy per averaging step, a vote per consensus step, a state and (--orientation any) a
    relay per formation step (a recording of the run must hold them all)."""
    modes = modes_of(params)
    sent = {"hello": 1, "color": 1}
    if modes.threshold.averages_energy:
        sent["energy"] = params.consensus_steps
    sent |= {"vote": modes.scope.steps(params), "state": params.formation_steps}
    if modes.relays:  # a layout's robots hear two hops
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


P = "p"  # a status list's entries of p's width (the descriptor's: 3 for the paper's)


def column(
    element: str,
    dtype: Any,
    shape: str = "value",
    per: int | str = 1,
    single: bool = True,
    array: bool = True,
    default: Any = MISSING,
) -> Any:
    """A Report field as a status column: its ROS element type (`element`, as RobotStatus.msg
    and StatusArray.msg spell it), the numpy dtype a status table holds it in, and its `shape`:
    "value" (one a robot), "vector" (p: its width's values a robot, flattened in a StatusArray)
    or "list" (entries of `per` values each, P: of p's width, flattened, with a count a robot in
    a StatusArray: `<name>_count`); `single`: a RobotStatus (one robot's report, what older
    bags hold) has it too; `array`: a StatusArray has it (row and col are a RobotStatus's)."""
    meta = {
        "element": element,
        "dtype": dtype,
        "shape": shape,
        "per": per,
        "single": single,
        "array": array,
    }
    if default is MISSING:
        return field(metadata=meta)
    return field(default=default, metadata=meta)


@dataclass(slots=True)
class Report:
    """Where a robot is and what it shows, for monitors and recorders: a robot's status. Each
    field is declared once, as a status column (`column`): StatusRows' columns, a StatusArray's
    fields and their check against RobotStatus.msg and StatusArray.msg are derived from these
    (status_rows.py, tests/camo_msgs/test_msgs.py)."""

    sender_id: int = column("uint32", np.int64)
    row: int = column("uint32", np.int64, array=False)
    col: int = column("uint32", np.int64, array=False)
    phase: int = column("uint8", np.int64)
    step: int = column("uint32", np.int64)
    round: int = column("uint32", np.int64)
    sensed: float = column("float64", np.float64)
    p: tuple[float, ...] = column("float64", np.float64, "vector")  # its p, or its tensor
    pattern: int = column("uint8", np.int64)
    state: int = column("uint8", np.int64)
    alive: bool = column("bool", np.bool_)
    known_slots: int = column("uint64", np.uint64)
    deadlines: int = column("uint32", np.int64)
    # Neighbours it has given up on (robot ids).
    silent: tuple[int, ...] = column("uint32", np.int64, "list", per=1, default=())
    # p before consensus step p_from, p_from + 1, ... (flattened): every p not yet reported, so
    # that reports spaced in time still give the monitor every step.
    p_from: int = column("uint32", np.int64, default=0)
    p_trace: tuple[float, ...] = column("float64", np.float64, "list", per=P, default=())
    # The state before formation step state_from, state_from + 1, ..., likewise.
    state_from: int = column("uint32", np.int64, default=0)
    state_trace: tuple[int, ...] = column("uint8", np.int64, "list", per=1, default=())
    # --levels: the greys it can show, darkest first.
    palette: tuple[int, ...] = column("uint8", np.int64, "list", per=1, default=())
    # The colour it sensed (sRGB), once it has.
    sensed_rgb: tuple[float, ...] = column(
        "float64", np.float64, "list", per=3, single=False, default=()
    )
    # --colours: its palette (sRGB triples, darkest first, flattened) and the two of them it
    # shows (palette indices: where its pattern is on, where it is off).
    palette_rgb: tuple[int, ...] = column(
        "uint8", np.int64, "list", per=3, single=False, default=()
    )
    shades: tuple[int, ...] = column("uint8", np.int64, "list", per=2, single=False, default=())


STATUS_COLUMNS = {f.name: f.metadata for f in fields(Report)}


@dataclass
class Traces:
    """A robot's p before consensus step p_from, p_from + 1, ... (flattened, `width` a step) and
    its state before formation step state_from, ...: what no report carried yet. A report takes
    them (`unreported`) and they are let go: a robot keeps a few steps' traces, not a round's,
    whose floats would fill a big swarm's memory and push its working set out of the caches."""

    p: list[float] = field(default_factory=list)
    states: list[int] = field(default_factory=list)
    p_from: int = 0
    state_from: int = 0
    width: int = 3  # entries of a p (modes.descriptor.width)

    def unreported(self) -> dict[str, Any]:
        """A Report's trace fields: every p and state not reported yet (now they are)."""
        fields = {
            "p_from": self.p_from,
            "p_trace": tuple(self.p),
            "state_from": self.state_from,
            "state_trace": tuple(self.states),
        }
        self.p_from += len(self.p) // self.width
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
