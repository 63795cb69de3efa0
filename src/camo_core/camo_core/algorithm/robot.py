"""One robot's view of a camouflage run: what it knows, holds and decides.

The per-robot reference driver (`perrobot.py`) and the step protocol
(`protocol.py`, which every robot node runs) use this class. It takes what was *delivered* to the
robot, applies the
simulated link (docs/algorithm.md §3: a message is lost by a deterministic draw keyed
on sender, receiver and step) and calls the rules of `rules.py`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from camo_core.algorithm import orientation, rng, rules
from camo_core.algorithm.grid import CONSENSUS_SLOTS, robot_id
from camo_core.algorithm.link import LinkDraws
from camo_core.algorithm.modes import Modes, modes_of
from camo_core.algorithm.modes.palettes import RobotPalette
from camo_core.algorithm.modes.scopes import GlobalRobot, LocalRobot, Previous
from camo_core.algorithm.params import CamoParams, ParameterError
from camo_core.algorithm.sensing import noisy_colour, noisy_value

Vote = tuple[Sequence[float], int]


@dataclass
class RobotCore:
    params: CamoParams
    row: int
    col: int
    # The run's variations (modes.modes_of(params) unless given): what it senses, describes,
    # averages and shows, and where its neighbours are.
    modes: Modes = None  # type: ignore[assignment]  # modes_of(params) when not given
    # The link's draws, made for all of its process's robots at once (link.LinkDraws); None:
    # this robot draws its own.
    link: LinkDraws | None = None
    # What it is handed has had the link's losses and its unknown neighbours taken out already
    # (the step protocol takes a step's messages by `heard`): nothing is left to filter.
    delivered_filtered: bool = False
    # Its last finished round, in a later round of a --scope local run (scopes.Previous): what
    # it keeps showing if nothing changed for it.
    previous: Previous | None = None
    # Filled in as the phases go by.
    known: list[bool] = field(default_factory=list)
    sensed: float = float("nan")
    vote: int = rules.MOTTLED
    p: tuple[float, ...] = (0.0, 0.0, 1.0)  # with --levels or --colours, a histogram follows
    pattern: int | None = None
    state: int = 0
    # The descriptor: scores, and texture energy (averaged with --threshold auto).
    scores: tuple[float, float] = (0.0, 0.0)
    energy: float = 0.0

    def __post_init__(self) -> None:
        if not (0 <= self.row < self.params.rows and 0 <= self.col < self.params.cols):
            raise ParameterError(
                f"cell ({self.row}, {self.col}) is outside the "
                f"{self.params.rows}x{self.params.cols} grid"
            )
        modes = self.modes = self.modes or modes_of(self.params)
        self.id = robot_id(self.row, self.col, self.params.cols)
        self.link_row = -1 if self.link is None else self.link.index[self.id]
        # Its slots: on the grid the twelve of §1, on a --layout its neighbours by range, the
        # near ones first (colours, energies and votes come from those).
        self.neighbors, self.near, self.place = modes.layout.slots(self.id)
        self.known = [False] * len(self.neighbors)
        self._form = modes.layout.former(self.place, self.params)
        self.vote_steps = modes.scope.steps(self.params)  # the steps of its consensus phase
        self._colour_slots = range(
            modes.layout.listen(modes.descriptor.colour_slots, self.near)["color"]
        )
        self._arrivals: dict[tuple[int, int], tuple[bool, ...]] = {}
        # A lossless link delivers every neighbour's message: no draw needed.
        self._everyone = tuple(n is not None for n in self.neighbors)
        self._known_counts()
        self.tensor = (0.0, 0.0, 0.0)  # --orientation any: (Jxx, Jyy, Jxy) before normalising
        # What it sensed in colour (sRGB; a grey reading's is its grey), and its palette once
        # consensus ends (modes.palettes: --levels' greys, --colours' colours and shades).
        self.sensed_rgb: tuple[float, float, float] = (math.nan, math.nan, math.nan)
        self.shows = RobotPalette()
        self.raw = math.nan
        self.kept = False  # it keeps its last round's state (--scope local, a later round)
        # Its consensus (modes.scopes), from its vote on.
        self.averaging: GlobalRobot | LocalRobot = GlobalRobot(self.p, 3)

    # ---- the simulated link -------------------------------------------------

    def arrivals(self, stream: int, step: int) -> tuple[bool, ...]:
        """Per slot 0-11: does the message of `stream`/`step` from that slot's robot survive the
        link? Drawn once per (stream, step) and kept: the protocol asks on every delivery."""
        if self.params.rho_comm <= 0.0:
            return self._everyone
        if self.link is not None:  # kept there, for all of its process's robots
            return self.link.arrivals(self.id, stream, step)
        key = (stream, step)
        cached = self._arrivals.get(key)
        if cached is None:
            seed, me, rho = self.params.seed, self.id, self.params.rho_comm
            cached = tuple(
                src is not None and not rng.lost(seed, stream, step, src, me, rho)
                for src in self.neighbors
            )
            self._arrivals[key] = cached
        return cached

    def heard(self, stream: int, step: int, slots: int, known_only: bool = True) -> list[int]:
        """Per slot below `slots`, the neighbour whose message of `stream`/`step` survives the
        link (and, `known_only`, that it knows), else -1: no robot has that id, so a mailbox
        has nothing from it."""
        link = self.link
        if link is not None:
            view = link.view(stream, step, known_only)
            if view.holds(link.known_at[self.link_row]):
                return view.heard[self.link_row][:slots]
        arriving = self.arrivals(stream, step)
        known = (self.known if known_only else self._everyone)[:slots]
        near = zip(self.neighbors[:slots], arriving[:slots], known, strict=True)
        return [n if a and k else -1 for n, a, k in near]  # type: ignore[misc]  # a: n is not None

    def _filter(self, stream: int, step: int, delivered: Sequence, slots: range) -> Sequence:
        """What was delivered from known neighbours whose message survived the link (a slot
        without a neighbour delivers nothing)."""
        arriving = self._everyone if self.delivered_filtered else self.arrivals(stream, step)
        if (self.all_known or self.delivered_filtered) and arriving is self._everyone:
            if not slots.start and slots.stop == len(delivered):
                return delivered  # all of it (read, never changed)
            return [delivered[s] for s in slots]
        return [
            delivered[s] if delivered[s] is not None and self.known[s] and arriving[s] else None
            for s in slots
        ]

    # ---- phase 0: discovery -------------------------------------------------

    def discover(self, heard: Sequence[bool]) -> None:
        """`heard[s]`: a hello from slot s was delivered. Known = delivered and not lost."""
        arriving = self.arrivals(rng.STREAM_HELLO, 0)
        self.known = [bool(heard[s]) and arriving[s] for s in range(len(self.neighbors))]
        self._known_counts()
        if self.link is not None:
            self.link.set_known(self.id, self.known)

    def _known_counts(self) -> None:
        """The consensus degree and the known-slot mask, once known changes (read every step)."""
        self.degree = sum(self.known[s] for s in range(self.near))
        self.known_mask = sum(1 << s for s, known in enumerate(self.known) if known)
        # Every neighbour known: with a lossless link a step's messages need no filtering.
        self.all_known = all(
            k or n is None for k, n in zip(self.known, self.neighbors, strict=True)
        )

    # ---- phase 1: sensing and the local vote ----------------------------------

    def sense(
        self,
        raw: float,
        exempt_from_noise: bool = False,
        rgb: Sequence[float] | None = None,
    ) -> float:
        """Keep the sensed value, after measurement error unless it is a real reading; `rgb`:
        the colour read with it (sRGB 0..255; by default the grey's), replaced with it."""
        params = self.params
        rgb = (raw, raw, raw) if rgb is None else rgb
        colour = (float(rgb[0]), float(rgb[1]), float(rgb[2]))
        self.raw = float(raw)  # before measurement noise: what a later round compares
        if exempt_from_noise:
            self.sensed, self.sensed_rgb = float(raw), colour
        else:
            self.sensed = noisy_value(params.seed, self.id, raw, params.rho_meas)
            self.sensed_rgb = noisy_colour(params.seed, self.id, colour, params.rho_meas)
        self.state = rules.initial_state(self.sensed)
        return self.sensed

    def describe(self, colors: Sequence[float | None]) -> float:
        """`colors[s]` for its colour slots (0-3, 0-7 with --orientation any, the near ones on a
        layout): the delivered neighbour values (None if none). Keeps the scores (or the
        structure tensor); the texture energy, which --threshold auto averages before the
        vote."""
        received = self._filter(rng.STREAM_COLOR, 0, colors, self._colour_slots)
        scores, tensor, self.energy = self.modes.descriptor.describe(
            self.sensed, received, self.params.profile, self.place
        )
        self.scores = scores
        if tensor is not None:
            self.tensor = tensor
        return self.energy

    def average_energy(self, step: int, energies: Sequence[tuple[float, int] | None]) -> float:
        """`energies[s]` for slots 0-7: (energy, degree) delivered for `step`, or None."""
        received = self._filter(rng.STREAM_ENERGY, step, energies, range(self.near))
        self.energy = rules.energy_step(self.energy, self.degree, received)
        return self.energy

    def cast_vote(self) -> int:
        """The vote, against the fixed threshold or (--threshold auto) the averaged energy's,
        and the vector it averages: p, then its histogram (--levels, --colours)."""
        modes = self.modes
        self.vote, p = modes.descriptor.vote(self.scores, self.tensor, self.energy)
        whole = (*p, *modes.histogram.start_vector(self.sensed, self.sensed_rgb))
        self.averaging = modes.scope.robot(whole, modes.descriptor.width)
        self.p = self.averaging.vector
        return self.vote

    # ---- phase 2: consensus -------------------------------------------------

    def consensus(self, step: int, votes: Sequence[Vote | None]) -> tuple[float, ...]:
        """`votes[s]` for slots 0-7: (p, degree) delivered for `step`, or None."""
        received = self._filter(rng.STREAM_CONSENSUS, step, votes, range(self.near))
        self.p = self.averaging.step(step, self.degree, received)
        return self.p

    @property
    def pattern_p(self) -> tuple[float, ...]:
        """p without its histogram: what a robot reports (with --scope local its evidence
        until its segment's consensus)."""
        return self.averaging.reported

    def finish_consensus(self) -> int:
        modes = self.modes
        width = modes.descriptor.width
        result = self.averaging.result()
        self.pattern = modes.scope.choose(modes.descriptor, result[:width])
        tail = result[width:]
        self.shows = modes.palette.robot(tail, self.sensed, self.sensed_rgb)
        if self.shows.initial is not None:
            self.state = self.shows.initial
        previous = self.previous
        if previous is not None and modes.scope.keeps(previous, self.raw):
            self.kept = True
            self.pattern, self.state = int(previous.pattern), int(previous.final)
            self.shows = previous.palette
        return self.pattern

    def done(self) -> Previous:
        """This round, as the next one compares with it."""
        assert self.pattern is not None  # a finished round
        return Previous(self.raw, self.pattern, self.state, self.shows)

    @property
    def palette(self) -> tuple[int, ...]:
        """--levels: the greys it can show, darkest first (else none)."""
        return self.shows.greys

    @property
    def colours(self) -> tuple[tuple[int, int, int], ...]:
        """--colours: its palette's colours, sRGB darkest first (else none)."""
        return self.shows.colours

    @property
    def shades(self) -> tuple[int, int]:
        """--colours: the two of its colours it shows, where its pattern is on and off."""
        return self.shows.shades

    @property
    def display(self) -> int:
        """The grey this robot shows: black on, white off; with --levels its palette's (with
        --colours its pattern's tone: black on, white off)."""
        if self.modes.palette.colour:
            return 0 if self.state == 1 else 255
        return self.display_rgb[0]

    @property
    def display_rgb(self) -> tuple[int, int, int]:
        """The colour this robot shows: with --colours its palette's for its pattern's state,
        else its grey."""
        return self.modes.palette.shown(self.state, self.shows)

    # ---- phase 3: pattern formation ------------------------------------------

    def relay(self, step: int, states: Sequence[int | None]) -> tuple[int | None, ...]:
        """--orientation any: what this robot passes on of `step`'s states from slots 0-7 (the
        same `states` form takes): those that reached it, None for the others."""
        return tuple(self._filter(rng.STREAM_STATE, step, states, CONSENSUS_SLOTS))

    def form(
        self,
        step: int,
        states: Sequence[int | None],
        relays: Sequence[Sequence[int | None] | None] = (),
    ) -> int:
        """`states[s]` for slots 0-11: neighbour states delivered for `step`, or None;
        (--orientation any) `relays[s]` for slots 0-7: their relays for `step`, or None."""
        if self.pattern is None:
            self.finish_consensus()
        pattern = self.pattern
        assert pattern is not None
        if self.kept:  # what it showed, unchanged: its neighbours form against it
            return self.state
        received = self._filter(rng.STREAM_STATE, step, states, range(len(self.neighbors)))
        knights: list[int | None] = [None] * 8
        if self.modes.relays:
            relayed = self._filter(rng.STREAM_RELAY, step, relays, CONSENSUS_SLOTS)
            knights = orientation.knight_states(relayed)
        layers = self.modes.palette.layers
        if layers == 1:
            self.state = self._form(self.state, pattern, received, knights)
            return self.state
        # --levels: each layer is one bit of the states, formed on its own.
        state = 0
        for k in range(layers):

            def bit(v, k=k):
                return None if v is None else (v >> k) & 1

            layer = self._form(
                (self.state >> k) & 1,
                pattern,
                [bit(v) for v in received],
                [bit(v) for v in knights],
            )
            state |= layer << k
        self.state = state
        return self.state
