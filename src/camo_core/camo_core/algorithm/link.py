"""The simulated link for many robots at once (docs/algorithm.md §3).

Whether a neighbour's message of a stream and step reaches a robot is a pure function of
(seed, stream, step, sender, receiver). A robot alone draws its own (`RobotCore.arrivals`, one
Python hash a slot); a process hosting thousands of robots draws them for all its robots at
once, vectorised (`LinkDraws`), the same bits: a lossy swarm then steps as fast as a
loss-free one (docs/swarm.md).
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np

from camo_core.algorithm import rng
from camo_core.algorithm.modes import modes_of
from camo_core.algorithm.params import CamoParams

KEPT = 64  # (stream, step) tables a round's draws keep: the steps its robots are in, and more
VIEWS_KEPT = 24  # views of them (a worker of 8192 robots: about 1 MB each)


class LinkDraws:
    """One round's link for some robots: per (stream, step), a table robots x slots of which
    neighbours' messages survive. Drawn once per (stream, step) for all of them."""

    def __init__(self, params: CamoParams, robots: list[int]) -> None:
        self.seed, self.rho = params.seed, params.rho_comm
        layout = modes_of(params).layout
        slots = [layout.slots(robot)[0] for robot in robots]
        width = max((len(s) for s in slots), default=0)
        senders = np.full((len(robots), width), -1, np.int64)
        for row, neighbours in enumerate(slots):
            senders[row, : len(neighbours)] = [-1 if n is None else n for n in neighbours]
        self.index = {robot: row for row, robot in enumerate(robots)}
        self.widths = [len(s) for s in slots]
        self.present = senders >= 0
        self.ids = senders  # per slot its neighbour's id, -1 for none
        self.senders = np.where(self.present, senders, 0).astype(np.uint64)
        self.receivers = np.asarray(robots, dtype=np.uint64)[:, None]
        # Whom each robot knows (discovery's outcome, set by the robot), and when it was set:
        # a view is made for all robots at once with the knowledge of that moment, and is a
        # robot's only if it had set its own by then.
        self.known = np.zeros_like(self.present)
        self.known_at = [0] * len(robots)  # 0: not yet
        self.epoch = 0
        # Per (stream, step): the table of survivals, and each robot's row of it as a tuple.
        self._tables: OrderedDict[tuple[int, int], tuple[np.ndarray, list]] = OrderedDict()
        # Per (stream, step, known_only): what robots read (View), of all their slots (a robot
        # reads the ones it listens to: on a --layout the number differs from robot to robot).
        self._views: OrderedDict[tuple[int, int, bool], View] = OrderedDict()

    def _drawn(self, stream: int, step: int) -> tuple[np.ndarray, list]:
        key = (stream, step)
        drawn = self._tables.get(key)
        if drawn is None:
            sender = rng.sender_hash(self.seed, stream, step, self.senders)
            u = rng.to_unit(rng.mix_array(sender ^ self.receivers))
            table = self.present & ~(u < self.rho)
            drawn = self._tables[key] = table, []
            if len(self._tables) > KEPT:
                self._tables.popitem(last=False)
        return drawn

    def set_known(self, robot: int, known: list[bool]) -> None:
        """A robot's discovery is over: these are the neighbours it knows."""
        row = self.index[robot]
        self.known[row] = False
        self.known[row, : len(known)] = known
        self.epoch += 1
        self.known_at[row] = self.epoch

    def table(self, stream: int, step: int) -> np.ndarray:
        """robots x slots: the messages of `stream`/`step` that survive (False for no robot)."""
        return self._drawn(stream, step)[0]

    def arrivals(self, robot: int, stream: int, step: int) -> tuple[bool, ...]:
        """A robot's row: per slot, does its neighbour's message survive."""
        table, rows = self._drawn(stream, step)
        if not rows:  # made for all robots at once
            width = table.shape[1]
            rows.extend(
                tuple(values) if w == width else tuple(values[:w])
                for values, w in zip(table.tolist(), self.widths, strict=True)
            )
        return rows[self.index[robot]]

    def view(self, stream: int, step: int, known_only: bool) -> View:
        """What robots read of a step's messages of `stream` (and, `known_only`, from the
        neighbours they know), made for all of them at once."""
        key = (stream, step, known_only)
        view = self._views.get(key)
        if view is None:
            table = self._drawn(stream, step)[0]
            if known_only:
                table = table & self.known
            heard = np.where(table, self.ids, -1).tolist()  # one C call for all rows
            view = self._views[key] = View(self.epoch if known_only else None, heard)
            if len(self._views) > VIEWS_KEPT:
                self._views.popitem(last=False)
        return view


class View:
    """A (stream, step)'s messages as a process's robots read them, by row (LinkDraws.index):
    `heard[row]` per slot the neighbour whose message survives, -1 where none does (no robot
    has that id: a mailbox has nothing from it). Made with whom robots knew at `epoch` (None:
    whom they know does not matter): a robot whose discovery ended later
    (`LinkDraws.known_at`) reads its own row elsewhere."""

    __slots__ = ("epoch", "heard")

    def __init__(self, epoch: int | None, heard: list) -> None:
        self.epoch, self.heard = epoch, heard

    def holds(self, known_at: int) -> bool:
        """Whether a robot whose discovery ended at `known_at` (0: not yet) may read its row."""
        return self.epoch is None or 0 < known_at <= self.epoch


class LinkBook:
    """A process's link draws, one LinkDraws per round's parameters (the latest few), for the
    robots it hosts."""

    def __init__(self, robots: list[int], rounds: int = 4) -> None:
        self.robots = sorted(robots)
        self.rounds = rounds
        self._draws: OrderedDict[CamoParams, LinkDraws] = OrderedDict()

    def draws(self, params: CamoParams) -> LinkDraws | None:
        """The round's draws (None without loss: every message survives)."""
        if params.rho_comm <= 0.0:
            return None
        draws = self._draws.get(params)
        if draws is None:
            draws = self._draws[params] = LinkDraws(params, self.robots)
            if len(self._draws) > self.rounds:
                self._draws.popitem(last=False)
        return draws
