"""One robot's step protocol: when it may take its next step, as a state machine without ROS.

A robot goes through the phases by itself (hello, sense, colour, vote,
consensus, formation) with no clock master. It moves from step t to t+1 when,
for every neighbour slot the phase needs, one of these holds:

1. that neighbour's message for step t has been delivered;
2. the simulated link will drop it (a deterministic draw, known in advance);
3. the neighbour is *silent*: it let a deadline pass before and has not
   spoken since;
4. the step's deadline passes and the neighbour is not known to be alive
   (`known_alive`: its process has stopped beating, see liveness.py); the
   neighbours still missing become silent, so a dead robot costs one
   deadline, not one per step. A neighbour known to be alive is never given
   up on, however late: it is slow, or waiting itself for a robot further
   away, and giving up on it would compute something else.

The machine is driven from outside: `start`, `deliver`, `tick` and
`background` are handed the current time (the clock is injected) and return an
`Output`: the messages to send and the reports for monitors.

Rounds are named by the projector's frame numbers: round r camouflages against frame r
(with the seed `change.round_seed`). A robot that hears a neighbour's hello of a later round
than its own joins that round, abandoning an unfinished one: a newer round supersedes an
older. Without --continuous a robot starts the next round when a new frame is projected and it
is done; with it, only when it or a neighbour notices a change (`notice`, from the process's
`change.Watch`), and until then it is in no round. `due()` says when
a tick could next change anything, so that a process with thousands of robots
ticks only those (`Ticks`); `stalled()` discounts a stall of the robot's own
process from its deadline.
A transport (rclpy, or an in-memory bus in tests) moves the messages; a
`Sensor` and a `Display` are the robot's hardware (a projected image and
nothing, or a Droplet's colour sensor and LED).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import Any

from camo_core.algorithm.change import params_of_round
from camo_core.algorithm.modes.scopes import Previous
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.robot import RobotCore
from camo_core.swarm.mailbox import Key, Mailbox
from camo_core.swarm.robot_io import (
    CONSENSUS,
    DISCOVERY,
    DONE,
    FORMATION,
    NO_PATTERN,
    NOTHING,
    SENSING,
    STREAM,
    Display,
    Message,
    NoDisplay,
    Output,
    Report,
    Sensor,
    Traces,
    kinds_of,
    listen_slots,
)

TICK = 0.05  # s between the host's ticks
STALL = 0.5  # s: a tick this late means the robot's own process stalled
RECHECK = 0.25  # s between asks, past a deadline, whether the late neighbours are still alive
NOBODY: frozenset[int] = frozenset()  # heard for a kind the robot does not listen to
# Phases in which a step only moves the robot's `due()` later (its wait starts anew, with the
# same timeout): a tick schedule told once in the phase need not be told of every step.
DUE_ONLY_LATER = frozenset({CONSENSUS, FORMATION})


class StepProtocol:
    # Attributes in slots: a process steps thousands of robots in turn, and a robot's state
    # packed in its object (no per-robot dict) is fewer memory lines to fetch each step.
    __slots__ = (
        "_awaiting",
        "_awaiting_key",
        "_expected_ids",
        "_out",
        "_silent_since",
        "_vote_slots",
        "background_up",
        "base_params",
        "continuous",
        "core",
        "deadlines",
        "discovery_timeout",
        "display",
        "energy_step",
        "hardware_wait",
        "heard_from",
        "hello_from",
        "kinds",
        "known_alive",
        "last_report",
        "last_round",
        "listen",
        "mailbox",
        "newer_background",
        "params",
        "phase",
        "relayed",
        "report_period",
        "round",
        "sensor",
        "silent",
        "slot_of",
        "started",
        "step",
        "step_timeout",
        "traces",
        "wait_started",
    )

    def __init__(
        self,
        params: CamoParams,
        row: int,
        col: int,
        sensor: Sensor,
        display: Display | None = None,
        step_timeout: float = 10.0,
        discovery_timeout: float = 300.0,
        known_alive: Callable[[int], bool] | None = None,
        report_period: float = 0.0,
        mailbox: Mailbox | None = None,
    ) -> None:
        """`mailbox`: where the robot's messages wait, shared with the other robots of its
        process (which then wakes it: `wake`); its own when messages are handed to it one by
        one (`deliver`)."""
        self.params = params
        self.base_params = params
        self.continuous = False
        # A neighbour the transport knows to be alive (hosted by this process, or by one whose
        # heartbeats say it lives: liveness.py) is waited for past the deadline: it is slow, or
        # itself waiting, and giving up on it would compute something else than the simulator.
        self.known_alive = known_alive or (lambda robot: False)
        # Between phase changes a robot reports at most this often (0: every step): a large,
        # fast swarm's statuses would otherwise outnumber its messages.
        self.report_period = report_period
        self.last_report = -math.inf
        self.traces = Traces()
        # The neighbours (ids) whose messages for _awaiting_key's step were still to come when
        # the robot last looked (None: look again at once).
        self._awaiting: tuple[int, ...] | None = None
        self._awaiting_key: Key = (-1, "", -1)
        self._expected_ids: dict[tuple[str, int, bool], list[int]] = {}
        # Delivered and not yet used, by step and sender: early messages wait for their step.
        self.mailbox = mailbox or Mailbox()
        self.last_round: Previous | None = None  # its last finished round
        self.core = self._core(params, row, col)
        self.sensor = sensor
        self.display = display or NoDisplay()
        self.step_timeout = step_timeout
        self.discovery_timeout = discovery_timeout
        self.slot_of = {n: s for s, n in enumerate(self.core.neighbors) if n is not None}
        self.silent: set[int] = set()
        # What each silent slot's robot had said when it fell silent (`Mailbox.spoke`).
        self._silent_since: dict[int, int] = {}
        self.deadlines = 0  # step deadlines let pass in this round
        # The round it is in (-1: none yet, a continuous robot that has not noticed a scene).
        self.round = 0
        self.phase = DISCOVERY
        self.step = 0
        self.background_up = False
        # A newer frame arrived mid-round (its number; -1: none): camouflaged next.
        self.newer_background = -1
        self.started = False
        self.hardware_wait = False  # waiting for the sensor or display: ticks retry
        self.wait_started = 0.0
        self.energy_step: int | None = None  # --threshold auto: the averaging step, once described
        self.kinds = kinds_of(params)
        self.listen = listen_slots(params, self.core.near, len(self.core.neighbors))
        self._vote_slots = self.listen["vote"]
        # Per kind, the neighbours heard for it (what a delivery is checked against).
        self.heard_from = {
            kind: frozenset(n for n, s in self.slot_of.items() if s < slots)
            for kind, slots in self.listen.items()
        }
        self.hello_from = self.heard_from["hello"]  # whose hellos of a later round it joins
        # --orientation any: the formation step whose states were taken and relayed, and them.
        self.relayed: tuple[int, list] | None = None
        self._out = Output()

    def watching(self) -> StepProtocol:
        """Camouflage continuously (before `start`): rounds begin when this robot or a neighbour
        notices a change (`notice`), not when a frame is projected; until then it is in none."""
        self.continuous = True
        self.round, self.phase = -1, DONE
        return self

    @property
    def id(self) -> int:
        return self.core.id

    @property
    def done(self) -> bool:
        return self.phase == DONE

    def listens_to(self) -> Iterable[tuple[int, str]]:
        """(neighbour id, kind) of every message this robot needs."""
        for kind in self.kinds:
            for neighbor in self.heard_from[kind]:
                yield neighbor, kind

    # ---- events ---------------------------------------------------------------------

    def start(self, now: float) -> Output:
        """Say hello and begin (a continuous robot: watch, in no round yet). Messages delivered
        before are kept for their steps."""
        self.started = True
        self.wait_started = now
        if self.continuous:
            return self.wake(now)  # a neighbour may have started a round already
        self._send("hello", 0, (self.core.row, self.core.col))
        return self._advance(now)

    def deliver(self, message: Message, now: float) -> Output:
        """A neighbour's message, handed to this robot alone (into its own mailbox)."""
        if message.sender not in self.heard_from.get(message.kind, NOBODY):
            return NOTHING  # not a neighbour this robot listens to for that kind
        key = (message.round, message.kind, message.step)
        self.mailbox.put(key, message.sender, message.value)
        return self.wake(now)

    def wake(self, now: float) -> Output:
        """Messages came that this robot may be waiting for (its mailbox holds them): step if
        its step's messages are in. Cheap when they are not: a robot is woken by each
        neighbour's message, and steps on the last one it waits for."""
        if not self.started:
            return NOTHING
        if self.mailbox.newest > self.round and self._later_round(now):
            return self._advance(now)
        if self.silent:
            self._heard_silent()
        awaiting = self._awaiting
        if awaiting:
            box = self.mailbox.box(self._awaiting_key)
            for robot in awaiting:
                if robot not in box:
                    return NOTHING
        return self._advance(now)

    def _heard_silent(self) -> None:
        """A silent neighbour that has spoken since it fell silent is waited for again."""
        spoke = self.mailbox.spoke
        for slot, said in list(self._silent_since.items()):
            if spoke.get(self._neighbor(slot), 0) != said:
                self.silent.discard(slot)
                del self._silent_since[slot]
                self._awaiting = None

    def _later_round(self, now: float) -> bool:
        """Join the latest round later than its own that a neighbour has said hello in; whether
        there was one."""
        hello_from, mailbox = self.hello_from, self.mailbox
        for round_ in mailbox.hello_rounds_after(self.round):
            box = mailbox.box((round_, "hello", 0))
            if any(n in box for n in hello_from):
                self._join(round_, now)
                return True
        return False

    def notice(self, frame: int, now: float) -> Output:
        """Its process's watch says this robot noticed a change (continuous camouflage): start
        the round of `frame`, the newest frame, unless it is in that round or a later one."""
        if not self.started or frame <= self.round:
            return NOTHING
        self._join(frame, now)
        return self._advance(now)

    def holds(self, round_: int, kind: str, step: int, slot: int) -> bool:
        """Whether a message delivered for that step and slot waits to be taken."""
        return self.core.neighbors[slot] in self.mailbox.box((round_, kind, step))

    def background(self, now: float, frame: int = 0) -> Output:
        """Frame `frame` is projected (the sensor holds it). Without --continuous, a frame later
        than the robot's round is camouflaged next."""
        if self.background_up and frame > self.round and not self.continuous:
            self.newer_background = max(self.newer_background, frame)
        self.background_up = True
        return self._advance(now) if self.started else self._flush()

    def report_now(self, now: float) -> Output:
        """A report at once, with every p and state not reported yet: a process that stops
        keeps what its robots did since their last (spaced) report. A robot done said so in
        its last report (every phase change is reported): nothing to add."""
        if self.started and self.phase != DONE:
            self._report(now, forced=True)
        return self._flush()

    def stalled(self, seconds: float) -> None:
        """The robot's process could not listen for `seconds` (busy or descheduled): that time
        is not the neighbours' fault, and their messages may still be queued. Its host calls
        this before the tick that follows the stall."""
        self.wait_started += seconds

    def due(self) -> float:
        """When a tick could next change anything (math.inf: only a message or a background
        can): a deadline, or at once while the sensor or display is not ready."""
        if not self.started or self.phase == DONE:
            return math.inf
        if self.hardware_wait:
            return -math.inf
        if self.phase == SENSING and not self.background_up:
            return math.inf
        timeout = self.discovery_timeout if self.phase == DISCOVERY else self.step_timeout
        return self.wait_started + timeout

    def tick(self, now: float) -> Output:
        """The only event that lets a deadline pass (its host ticks a robot when `due()`)."""
        if not self.started or not (self.hardware_wait or self._deadline_due(now)):
            return self._flush()  # nothing a tick could change: keep a big swarm's ticks cheap
        return self._advance(now, ticking=True)

    def _deadline_due(self, now: float) -> bool:
        if self.phase == DONE:
            return False
        timeout = self.discovery_timeout if self.phase == DISCOVERY else self.step_timeout
        return now - self.wait_started >= timeout

    # ---- stepping -------------------------------------------------------------------

    def _advance(self, now: float, ticking: bool = False) -> Output:
        self.hardware_wait = False
        while self._step_once(now, ticking):
            pass
        return self._flush()

    def _step_once(self, now: float, ticking: bool) -> bool:
        """Take one step if it may be taken; False when the robot must wait."""
        phase = self.phase  # the phases of most steps first
        if phase == CONSENSUS:
            return self._consensus_step(now, ticking)
        if phase == FORMATION:
            return self._formation_step(now, ticking)
        if phase == DISCOVERY:
            return self._discovery_step(now, ticking)
        if phase == SENSING:
            return self._sensing_step(now, ticking)
        if self.newer_background > self.round:  # done, and a newer frame is up
            self._join(self.newer_background, now)
            return True
        return False

    def _discovery_step(self, now: float, ticking: bool) -> bool:
        pending = self._waiting_for("hello", 0, self.listen["hello"], known_only=False)
        if not self._ready(pending, self.discovery_timeout, now, ticking):
            return False
        hellos = self._take("hello", 0, self.listen["hello"], known_only=False)
        self.core.discover([h is not None for h in hellos])
        self._expected_ids.clear()  # who is known has changed
        self._next(SENSING, 0, now)
        return True

    def _sensing_step(self, now: float, ticking: bool) -> bool:
        """Sense, describe (with the neighbours' colours), average the energy (--threshold
        auto), then vote: each a step of its own."""
        core, params = self.core, self.params
        if not self.background_up:
            return False
        if math.isnan(core.sensed):
            reading = self.sensor.read()
            if reading is None:  # not available yet: tried again on the next tick
                self.hardware_wait = True
                return False
            core.sense(reading.value, reading.real, reading.rgb)
            self._send("color", 0, core.sensed)
            self.wait_started = now
        if self.energy_step is None:
            pending = self._waiting_for("color", 0, self.listen["color"])
            if not self._ready(pending, self.step_timeout, now, ticking):
                return False
            core.describe(self._take("color", 0, self.listen["color"]))
            self.energy_step = 0
            if core.modes.threshold.averages_energy and params.consensus_steps:
                self._wait_anew(now)
                self._send_energy()
                return True
        if core.modes.threshold.averages_energy and self.energy_step < params.consensus_steps:
            return self._energy_step(now, ticking)
        core.cast_vote()
        self.traces = Traces(p=list(core.pattern_p), width=len(core.pattern_p))
        self._next(CONSENSUS, 0, now)
        self._report(now, forced=True)
        self._send_vote()
        return True

    def _energy_step(self, now: float, ticking: bool) -> bool:
        step = self.energy_step
        assert step is not None
        pending = self._waiting_for("energy", step, self.listen["energy"])
        if not self._ready(pending, self.step_timeout, now, ticking):
            return False
        self.core.average_energy(step, self._take("energy", step, self.listen["energy"]))
        self.energy_step = step + 1
        self._wait_anew(now)
        if self.energy_step < self.params.consensus_steps:
            self._send_energy()
        return True

    def _consensus_step(self, now: float, ticking: bool) -> bool:
        core = self.core
        if self.step == core.vote_steps:
            core.finish_consensus()
            self.traces.states = [core.state]
            self._next(FORMATION, 0, now)
            self._report(now, forced=True)
            self._send("state", 0, core.state)
            return True
        # Most of a robot's steps are these: what the helpers do, partly written out.
        step, slots = self.step, self._vote_slots
        pending = self._waiting_for("vote", step, slots)
        if pending and not self._ready(pending, self.step_timeout, now, ticking):
            return False
        p = core.consensus(step, self._take("vote", step, slots))
        self.traces.p.extend(core.pattern_p)
        self.step = step = step + 1  # _next(CONSENSUS, step + 1, now)
        self.wait_started, self._awaiting = now, None
        self._report(now)
        if step < core.vote_steps:
            self._out.send.append(Message("vote", core.id, self.round, step, (p, core.degree)))
        return True

    def _formation_step(self, now: float, ticking: bool) -> bool:
        core, params = self.core, self.params
        if self.step == params.formation_steps:
            if not self.display.ready():  # a hardware robot is done once it shows its state
                self.hardware_wait = True
                return False
            self._next(DONE, self.step, now)
            self._report(now, forced=True)
            self.last_round = core.done()  # what a later round compares with (--scope local)
            return True
        if not self._formed(now, ticking):
            return False
        self.traces.states.append(core.state)
        self._next(FORMATION, self.step + 1, now)
        self._report(now)
        if self.step < params.formation_steps:
            self._send("state", self.step, core.state)
        return True

    def _formed(self, now: float, ticking: bool) -> bool:
        """Take the formation step if its states (and, with --orientation any, after relaying
        them, the neighbours' relays) are in; False while waiting."""
        step, core = self.step, self.core
        if self.relayed is None or self.relayed[0] != step:
            pending = self._waiting_for("state", step, self.listen["state"])
            if not self._ready(pending, self.step_timeout, now, ticking):
                return False
            states = self._take("state", step, self.listen["state"])
            if "relay" not in self.kinds:
                core.form(step, states)
                return True
            self.relayed = (step, states)
            self._send("relay", step, core.relay(step, states))
            self._wait_anew(now)
        pending = self._waiting_for("relay", step, 8)
        if not self._ready(pending, self.step_timeout, now, ticking):
            return False
        core.form(step, self.relayed[1], self._take("relay", step, 8))
        return True

    def _waiting_for(self, kind: str, step: int, slots: int, known_only: bool = True) -> list[int]:
        """Neighbours (ids) whose message for `step` is still to come: expected, not dropped, not
        silent, not in the mailbox. What it finds is what `wake` checks before looking again,
        and where it looks first the next time."""
        key = (self.round, kind, step)
        box = self.mailbox.box(key)
        if self._awaiting is not None and self._awaiting_key == key:
            pending = [n for n in self._awaiting if n not in box]
        else:
            expected = self._expected(kind, step, slots, known_only)
            pending = [n for n in expected if n >= 0 and n not in box]
            if self.silent and pending:
                slot_of, silent = self.slot_of, self.silent
                pending = [n for n in pending if slot_of[n] not in silent]
        self._awaiting_key = key
        self._awaiting = tuple(pending) if pending else None
        return pending

    def _expected(self, kind: str, step: int, slots: int, known_only: bool) -> list[int]:
        """Per slot below `slots`, the neighbour whose message for `step` survives the link
        (and, `known_only`, that was discovered), -1 where none does. Without loss the same
        every step: kept per phase."""
        core = self.core
        if self.params.rho_comm > 0.0:  # made for all of the process's robots at once, or drawn
            return core.heard(STREAM[kind], step, slots, known_only)
        cache_key = (kind, slots, known_only)
        expected = self._expected_ids.get(cache_key)
        if expected is None:
            expected = self._expected_ids[cache_key] = core.heard(
                STREAM[kind], step, slots, known_only
            )
        return expected

    def _ready(self, pending: list[int], timeout: float, now: float, ticking: bool) -> bool:
        """Whether the step may be taken, with these neighbours' messages still missing."""
        if not pending:
            return True
        # Only the tick lets a deadline pass: it has first discounted a stall of this process, and
        # a message handled before the tick after a stall would otherwise find the deadline gone.
        if not ticking or now - self.wait_started < timeout:
            return False
        given_up = sorted(self.slot_of[n] for n in pending if not self.known_alive(n))
        if given_up:
            spoke = self.mailbox.spoke
            for s in given_up:
                self.silent.add(s)
                self._silent_since[s] = spoke.get(self._neighbor(s), 0)
            self._awaiting = None
            self.deadlines += 1
            self._out.warnings.append(
                f"step deadline passed; neighbours in slots {given_up} are silent"
            )
        return len(given_up) == len(pending)

    def _neighbor(self, slot: int) -> int:
        """The robot in `slot`: one awaited or silent always has one (arrivals says so)."""
        robot = self.core.neighbors[slot]
        assert robot is not None
        return robot

    def _take(self, kind: str, step: int, slots: int, known_only: bool = True) -> list:
        """The step's messages by slot (None: none came, or the link lost it), taken out of the
        mailbox."""
        box = self.mailbox.take((self.round, kind, step))
        core = self.core
        if core.delivered_filtered:  # a slot whose message was lost, or is unknown, finds nothing
            return list(map(box.get, core.heard(STREAM[kind], step, slots, known_only)))
        return list(map(box.get, core.neighbors[:slots]))  # a slot's None finds nothing

    def _next(self, phase: int, step: int, now: float) -> None:
        self.phase, self.step = phase, step
        self._wait_anew(now)

    def _wait_anew(self, now: float) -> None:
        """A new step's wait: its deadline counts from now."""
        self.wait_started = now
        self._awaiting = None

    def _join(self, round_: int, now: float) -> None:
        """Camouflage in round `round_` (on its frame, with its seed): same rules, a fresh robot
        state; what it did of an unfinished round is left."""
        self.round = round_
        self.background_up = True  # a round's frame is projected, or about to be
        self.sensor.next_round(round_)
        core = self.core
        self.core = self._core(params_of_round(self.base_params, round_), core.row, core.col)
        self._expected_ids.clear()
        self.energy_step = None
        self.relayed = None
        self.deadlines = 0
        self.hardware_wait = False
        self.traces = Traces()
        self._next(DISCOVERY, 0, now)
        self._send("hello", 0, (core.row, core.col))

    def _core(self, params: CamoParams, row: int, col: int) -> RobotCore:
        """The robot in a round: with its process's link draws where its mailbox has them, and
        its last finished round (a --scope local robot that saw no change keeps its display)."""
        link = None if self.mailbox.link is None else self.mailbox.link.draws(params)
        return RobotCore(
            params,
            row,
            col,
            link=link,
            delivered_filtered=link is not None,
            previous=self.last_round,
        )

    # ---- output ---------------------------------------------------------------------

    def _send(self, kind: str, step: int, value: Any) -> None:
        self._out.send.append(Message(kind, self.core.id, self.round, step, value))

    def _send_energy(self) -> None:
        assert self.energy_step is not None  # sent once describing has set it
        self._send("energy", self.energy_step, (self.core.energy, self.core.degree))

    def _send_vote(self) -> None:
        self._send("vote", self.step, (tuple(self.core.p), self.core.degree))

    def _report(self, now: float, forced: bool = False) -> None:
        """A report at every phase change; within a phase at most every `report_period` s,
        carrying every p and state since the last report."""
        core = self.core
        if self.phase >= FORMATION:
            self.display.show(core.state, core.display_rgb if core.modes.palette.colour else None)
        if not forced and now - self.last_report < self.report_period:
            return
        self.last_report = now
        self._out.reports.append(
            Report(
                sender_id=core.id,
                row=core.row,
                col=core.col,
                phase=self.phase,
                step=self.step,
                round=self.round,
                sensed=core.sensed,
                p=core.pattern_p,
                pattern=NO_PATTERN if core.pattern is None else core.pattern,
                state=core.state,
                alive=self.sensor.ok() and self.display.ok(),
                known_slots=core.known_mask,
                deadlines=self.deadlines,
                silent=tuple(sorted(self._neighbor(s) for s in self.silent)),
                palette=core.palette,
                sensed_rgb=() if math.isnan(core.sensed) else core.sensed_rgb,
                palette_rgb=tuple(c for colour in core.colours for c in colour),
                shades=core.shades if core.modes.palette.colour else (),
                **self.traces.unreported(),
            )
        )

    def _flush(self) -> Output:
        out, self._out = self._out, Output()
        return out
