"""What a robot's step protocol takes in and gives out, and the hardware it is handed.

Messages between robots, reports for monitors, the output of one protocol
event; the sensor and display interfaces (a projected image and nothing, or a
Droplet's colour sensor and LED). No ROS here: a transport turns these into
camo_msgs messages.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

from .params import CamoParams
from .sensing import Reading


def messages_per_round(params: CamoParams) -> dict[str, int]:
    """What each robot sends in a round it finishes: one hello, one colour, (--threshold auto)
    an energy per averaging step, a vote per consensus step and a state per formation step (a
    recording of the run must hold them all)."""
    sent = {"hello": 1, "color": 1}
    if params.threshold_auto:
        sent["energy"] = params.consensus_steps
    return {**sent, "vote": params.consensus_steps, "state": params.formation_steps}


def kinds_of(params: CamoParams) -> tuple[str, ...]:
    """The kinds of message a run's robots exchange (energies only with --threshold auto)."""
    return tuple(messages_per_round(params))


@dataclass(slots=True)
class Message:
    """What one robot sends its neighbours. `value`: hello (row, col); colour the sensed grey;
    energy (energy, degree); vote (p, degree); state 0 or 1."""

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


@dataclass
class Output:
    send: list[Message] = field(default_factory=list)
    reports: list[Report] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


NOTHING = Output()  # what most deliveries produce (never to be appended to)


class Sensor(Protocol):
    def read(self) -> Reading | None:
        """This robot's grey value now, or None if it cannot be read yet (try again later)."""

    def next_round(self) -> None:
        """A new background is up: later reads are of it."""

    def ok(self) -> bool:
        """The hardware behind the sensor is reachable."""


class Display(Protocol):
    def show(self, state: int) -> None: ...

    def ready(self) -> bool:
        """It shows the last state it was given."""

    def ok(self) -> bool: ...


class NoDisplay:
    """A simulated robot shows nothing."""

    def show(self, state: int) -> None:
        pass

    def ready(self) -> bool:
        return True

    def ok(self) -> bool:
        return True
