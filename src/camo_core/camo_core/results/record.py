"""What the robots reported in each round, assembled into the reference simulator's result.

The monitor fills it live from the robots' statuses; `camo render` fills it
from a bag. A report is anything with RobotStatus's fields (a `protocol.Report`
or the message itself).
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from camo_core.algorithm.change import params_of_round
from camo_core.algorithm.modes import modes_of
from camo_core.algorithm.modes.palettes import GridPalette
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.result import RunResult, mean_p, p_stats
from camo_core.swarm.robot_io import CONSENSUS, DONE, FORMATION
from camo_core.swarm.status_rows import StatusRows


@dataclass
class RoundRecord:
    """Everything the robots reported in one camouflage round."""

    params: CamoParams
    started: float = field(default_factory=time.monotonic)

    def __post_init__(self) -> None:
        self.modes = modes_of(self.params)
        # A robot's choice from its p.
        self.select = partial(self.modes.scope.choose, self.modes.descriptor)
        n, steps = self.params.count, self.modes.scope.steps(self.params)
        width = self.modes.descriptor.width
        self.sensed = np.full(n, np.nan)
        self.p_trace = np.full((steps + 1, n, width), np.nan)
        self.state_trace = np.full((self.params.formation_steps + 1, n), -1, np.int64)
        self.p_latest = np.full((n, width), np.nan)
        self.initial = np.full(n, -1, np.int64)
        self.state = np.full(n, -1, np.int64)
        self.selected = np.full(n, -1, np.int64)
        self.phase = np.zeros(n, np.int64)
        self.step = np.zeros(n, np.int64)
        self.finished = np.zeros(n, bool)
        self.deadlines = np.zeros(n, np.int64)  # step deadlines each robot let pass
        self.given_up: dict[int, frozenset[int]] = {}  # reporter -> neighbours it gave up on
        # When each robot voted and finished, by its own clock (s since the epoch): a monitor
        # that hears a report late still times the swarm right.
        # --levels: each robot's palette (the K greys it can show), as it reported it.
        palette = self.modes.palette
        self.greys = 0 if palette.colour else palette.k  # greys of a palette (--levels)
        self.colours = palette.k if palette.colour else 0  # colours of a palette (--colours)
        self.palette = np.zeros((n, max(self.greys, 1)), np.int64)
        # The colours robots sensed (sRGB), and with --colours their palettes (K colours) and
        # the two of them each shows (where its pattern is on, where it is off).
        self.sensed_rgb = np.full((n, 3), np.nan)
        self.palette_rgb = np.zeros((n, max(self.colours, 1), 3), np.int64)
        self.shades = np.zeros((n, 2), np.int64)
        self.voted_at = np.full(n, np.nan)
        self.done_at = np.full(n, np.nan)

    def add(self, report, stamp: float | None = None) -> None:
        """One report; `stamp`: when the robot sent it (s since the epoch), if known."""
        self.add_rows(StatusRows.from_reports([report]), stamp)

    def add_rows(self, rows: StatusRows, stamp: float | None = None) -> None:
        """Reports as a table (checked: `validation.rows_problems`), in their order; `stamp`:
        when they were sent (s since the epoch), if known."""
        rank = rows.occurrences()
        if len(rank) and rank.max() > 0:  # a robot twice: its reports one after the other
            for k in range(int(rank.max()) + 1):
                self._add_distinct(rows.select(rank == k), stamp)
        else:
            self._add_distinct(rows, stamp)

    def _add_distinct(self, rows: StatusRows, stamp: float | None) -> None:
        """Reports of distinct robots."""
        i, phase, step = rows.sender_id, rows.phase, rows.step
        if stamp is not None:
            voted = i[(phase >= CONSENSUS) & np.isnan(self.voted_at[i])]
            self.voted_at[voted] = stamp
            self.done_at[i[phase == DONE]] = stamp
        self.phase[i], self.step[i] = phase, step
        self.sensed[i], self.state[i], self.deadlines[i] = rows.sensed, rows.state, rows.deadlines
        self._given_up(rows)
        consensus = phase >= CONSENSUS
        self.p_latest[i[consensus]] = rows.p[consensus]
        now = phase == CONSENSUS
        self.p_trace[step[now], i[now]] = rows.p[now]
        self.initial[i[now]] = rows.state[now]
        forming = phase == FORMATION
        self.state_trace[step[forming], i[forming]] = rows.state[forming]
        if self.greys:
            full = rows.palette_count == self.greys
            if full.any():
                mine = np.repeat(full, rows.palette_count)
                self.palette[i[full]] = rows.palette[mine].reshape(-1, self.greys)
        self._colours(rows)
        # The steps since each robot's last report (statuses of an older camo have none: they
        # came one a step).
        self._traces(rows)
        done = phase == DONE
        self.state_trace[step[done], i[done]] = rows.state[done]
        self.selected[i[done]] = rows.pattern[done]
        self.finished[i[done]] = True

    def _colours(self, rows: StatusRows) -> None:
        """The colours sensed, and with --colours the palettes and the shades shown."""
        i = rows.sender_id
        sensed = rows.sensed_rgb_count == 1
        if sensed.any():
            self.sensed_rgb[i[sensed]] = rows.sensed_rgb[np.repeat(sensed, rows.sensed_rgb_count)]
        k = self.colours
        if not k:
            return
        full = rows.palette_rgb_count == k
        if full.any():
            mine = np.repeat(full, rows.palette_rgb_count)
            self.palette_rgb[i[full]] = rows.palette_rgb[mine].reshape(-1, k, 3)
        paired = rows.shades_count == 1
        if paired.any():
            self.shades[i[paired]] = rows.shades[np.repeat(paired, rows.shades_count)]

    def _given_up(self, rows: StatusRows) -> None:
        """Who each reporter has given up on, at its latest report (a few rows have any)."""
        ids = rows.sender_id
        have = rows.silent_count > 0
        known = np.fromiter(self.given_up, np.int64, len(self.given_up))
        if known.size:
            have |= np.isin(ids, known)
        if not have.any():
            return
        ends = np.cumsum(rows.silent_count)
        for row in np.flatnonzero(have):
            silent = rows.silent[ends[row] - rows.silent_count[row] : ends[row]]
            self.given_up[int(ids[row])] = frozenset(silent.tolist())

    def _traces(self, rows: StatusRows) -> None:
        ids = rows.sender_id
        if len(rows.p_trace):
            row, j = rows.spans("p_trace")
            at = rows.p_from[row] + j
            keep = at < len(self.p_trace)
            self.p_trace[at[keep], ids[row[keep]]] = rows.p_trace[keep]
        if len(rows.state_trace):
            row, j = rows.spans("state_trace")
            at = rows.state_from[row] + j
            keep = at < len(self.state_trace)
            self.state_trace[at[keep], ids[row[keep]]] = rows.state_trace[keep]

    def timing(self) -> tuple[float, float] | None:
        """(when the last robot voted, when the last robot finished), by the robots' clocks."""
        if np.isnan(self.voted_at).all() or np.isnan(self.done_at).all():
            return None
        return float(np.nanmax(self.voted_at)), float(np.nanmax(self.done_at))

    def declared_silent(self) -> np.ndarray:
        """Robots that a neighbour has given up on (at its latest report)."""
        silent = np.zeros(self.params.count, bool)
        for ids in self.given_up.values():
            silent[list(ids)] = True
        return silent

    def dead(self, lost: np.ndarray | None = None) -> np.ndarray:
        """Robots that did not finish and that their neighbours gave up on, or whose process is
        known to have died (`lost`): a late report alone never makes a robot dead."""
        gone = self.declared_silent() if lost is None else self.declared_silent() | lost
        return ~self.finished & gone

    def marks(self, dead: np.ndarray, bridged=()) -> dict[str, np.ndarray]:
        """The robots a figure marks besides the dead (rows x cols masks): those a neighbour gave
        up on for a while that finished all the same, and the bridged Droplets (ids)."""
        shape = (self.params.rows, self.params.cols)
        real = np.zeros(self.params.count, bool)
        real[[i for i in bridged if 0 <= i < self.params.count]] = True
        return {
            "silent": (self.declared_silent() & ~dead).reshape(shape),
            "bridged": real.reshape(shape),
        }

    def timeline(self) -> list[tuple[str, np.ndarray]]:
        """The swarm at each consensus step (selected pattern, -1 unknown) and formation step
        (state; with --colours the colour shown, rows x cols x 3, -1 unknown)."""
        shape = (self.params.rows, self.params.cols)
        frames: list[tuple[str, np.ndarray]] = []
        for step, p in enumerate(self.p_trace):
            unknown = np.isnan(p).any(axis=1)
            chosen = self.select(np.nan_to_num(p))
            frames.append((f"c{step}", np.where(unknown, -1, chosen).reshape(shape)))
        palette = self.grid_palette()
        for step, states in enumerate(self.state_trace):
            grid = states.reshape(shape)
            if self.modes.palette.colour:  # a strip of states, or of the colours shown
                grid = self.modes.palette.frame(grid, palette)
            frames.append((f"f{step}", grid))
        return frames

    @property
    def sensed_shown(self) -> np.ndarray:
        """What a GIF shows as sensed: the robots' colours with --colours, else their greys."""
        return self.modes.sensing.shown(self.sensed, self.sensed_rgb)

    def grid_palette(self) -> GridPalette:
        """The robots' palettes as reported, as the whole grid's (rows x cols x ...)."""
        shape = (self.params.rows, self.params.cols)
        return GridPalette(
            greys=self.palette.reshape((*shape, -1)) if self.greys else None,
            colours=self.palette_rgb.reshape((*shape, -1, 3)) if self.colours else None,
            shades=self.shades.reshape((*shape, 2)) if self.colours else None,
        )

    def result(self, dead: np.ndarray, partial: bool = False) -> RunResult:
        """What the swarm computed, in the reference simulator's form; dead robots masked out.

        `partial`: the run was stopped early; robots still working count as alive and show
        their latest report, and the consensus trace ends where the slowest robot was.
        """
        shape = (self.params.rows, self.params.cols)
        palette = self.grid_palette()
        if partial:
            alive = ~dead & (self.phase >= CONSENSUS)
            # A robot still in consensus shows what its current p would select.
            selected = np.where(
                self.selected < 0, self.select(np.nan_to_num(self.p_latest)), self.selected
            )
        else:
            alive = self.finished & ~dead
            selected = self.selected
        trace, spread = [], []
        for step in self.p_trace:
            if np.isnan(step[alive]).any():
                break
            if alive.any():
                mean, least_greatest = p_stats(step[alive])
                trace.append(mean)
                spread.append(least_greatest)
            else:
                trace.append(mean_p(step[alive]))
        first = self.p_trace[0]
        votes = np.where(np.isnan(first).any(axis=1), -1, self.select(np.nan_to_num(first)))
        return RunResult(
            params=self.params,
            sensed=self.sensed.reshape(shape),
            votes=votes.reshape(shape),
            p=self.p_latest.reshape((*shape, self.modes.descriptor.width)),
            selected=selected.reshape(shape),
            # The state formation starts from: with --levels the layers set once the palette is
            # known, with --scope local a kept state (else the sensed grey's, as reported).
            initial=np.where(self.state_trace[0] >= 0, self.state_trace[0], self.initial).reshape(
                shape
            ),
            final=self.state.reshape(shape),
            consensus_trace=np.array(trace).reshape(-1, self.modes.descriptor.width),
            elapsed_s=time.monotonic() - self.started,
            alive=None if alive.all() else alive.reshape(shape),
            palette=palette.greys,
            positions=self.modes.layout.positions,
            consensus_range=(
                np.array(spread).reshape(-1, self.modes.descriptor.width, 2) if spread else None
            ),
            # Known only where every robot that took part said what it sensed.
            sensed_rgb=self.sensed_rgb.reshape((*shape, 3))
            if not np.isnan(self.sensed_rgb[alive]).any()
            else None,
            palette_rgb=palette.colours,
            shades=palette.shades,
        )


class Rounds(dict):
    """Round index -> RoundRecord, created on first use (`rounds[k]`). Not setdefault: its
    default would allocate a record's traces (steps x robots) on every report."""

    def __init__(self, params: CamoParams) -> None:
        super().__init__()
        self.params = params

    def __missing__(self, index: int) -> RoundRecord:
        record = self[index] = RoundRecord(params_of_round(self.params, index))
        return record


class Backgrounds(dict):
    """The frames a run projected, by frame number (round r camouflaged self[r]), each kept once
    (by its stamp): those pinned (the frames of rounds), and of the others the newest `keep`,
    at most `budget` bytes of them beyond the newest `least` (a camera's 1080p frames are 6 MB
    each: 64 of them were 400 MB). A round names the newest frame its robots read, so the
    newest frames are those a notice or a report still to come can name. What is known of a
    frame (stamp, digest, time) goes with it."""

    def __init__(self, keep: int = 64, budget: int = 128 << 20, least: int = 4) -> None:
        super().__init__()
        self.keep, self.budget, self.least = keep, budget, least
        self.stamps: set[tuple[int, int]] = set()
        self.digests: dict[int, str] = {}  # frame number -> SHA-256 of its pixels as published
        self.times: dict[int, float] = {}  # frame number -> when it was projected (s, ROS time)
        self.pinned: set[int] = set()
        self._stamp_of: dict[int, tuple[int, int]] = {}
        self._order: deque[int] = deque()  # frames held, oldest first
        self._next = 0

    def add(
        self, stamp: tuple[int, int], decode, number: int | None = None, digest: str = ""
    ) -> int | None:
        """`decode()` gives the image; called only for a stamp not seen before. `number`: the
        frame's (None: the one after the newest, as frames without numbers are counted)."""
        if stamp in self.stamps:
            return None
        number = self._next if number is None else number
        if number in self:
            return None  # a frame held, stamped anew
        self._next = max(self._next, number + 1)
        self.stamps.add(stamp)
        self[number] = decode()
        self.digests[number], self.times[number] = digest, stamp[0] + stamp[1] * 1e-9
        self._stamp_of[number] = stamp
        self._order.append(number)
        self._let_go()
        return number

    def _let_go(self) -> None:
        """The oldest frames not pinned, beyond `keep` of them or `budget` bytes."""
        loose = [n for n in self._order if n not in self.pinned]
        held = sum(getattr(self[n], "nbytes", 0) for n in loose)
        for oldest in loose[: max(0, len(loose) - self.least)]:
            if len(loose) <= self.keep and held <= self.budget:
                break
            loose.pop(0)
            held -= getattr(self[oldest], "nbytes", 0)
            self._order.remove(oldest)
            del self[oldest], self.digests[oldest], self.times[oldest]
            self.stamps.discard(self._stamp_of.pop(oldest))

    def pin(self, number: int) -> None:
        """Keep frame `number` (a round's, perhaps still to come) whatever comes after it."""
        self.pinned.add(number)

    def unpin(self, number: int) -> None:
        self.pinned.discard(number)
        self._let_go()


# Notices of a continuous run: round -> (the robot that noticed its change first, when the scene
# changed, when it noticed: ROS time, s since the epoch).
Notices = dict[int, tuple[int, float, float]]


def round_fields(
    index: int,
    frame: int,
    backgrounds: Backgrounds,
    notices: Notices,
    record: RoundRecord,
    partial: bool = False,
) -> dict:
    """What a continuous run's round adds to its summary.json, written live (the launcher) and
    from a bag (`camo render`) alike: which round it is and which frame it camouflaged, that
    frame's SHA-256, when the scene changed, when and by whom that was noticed, and when every
    robot was done (ROS time, s since the epoch; None for a round the run stopped in)."""
    noticed = notices.get(frame)
    clocks = record.timing()
    return {
        "round": index,
        "frame": frame,
        "background_sha256": backgrounds.digests.get(frame),
        "changed_at": noticed[1] if noticed else backgrounds.times.get(frame),
        "noticed_at": noticed[2] if noticed else None,
        "noticed_by": noticed[0] if noticed else None,
        "done_at": clocks[1] if clocks is not None and not partial else None,
    }
