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
        self.senders = np.where(self.present, senders, 0).astype(np.uint64)
        self.receivers = np.asarray(robots, dtype=np.uint64)[:, None]
        # Per (stream, step): the table, and its rows as Python lists (what robots read).
        self._tables: OrderedDict[tuple[int, int], tuple[np.ndarray, list]] = OrderedDict()

    def _drawn(self, stream: int, step: int) -> tuple[np.ndarray, list]:
        key = (stream, step)
        drawn = self._tables.get(key)
        if drawn is None:
            sender = rng.sender_hash(self.seed, stream, step, self.senders)
            u = rng.to_unit(rng.mix_array(sender ^ self.receivers))
            table = self.present & ~(u < self.rho)
            drawn = self._tables[key] = table, table.tolist()  # one C call for all rows
            if len(self._tables) > KEPT:
                self._tables.popitem(last=False)
        return drawn

    def table(self, stream: int, step: int) -> np.ndarray:
        """robots x slots: the messages of `stream`/`step` that survive (False for no robot)."""
        return self._drawn(stream, step)[0]

    def arrivals(self, robot: int, stream: int, step: int) -> tuple[bool, ...]:
        """A robot's row: per slot, does its neighbour's message survive."""
        row = self.index[robot]
        values = self._drawn(stream, step)[1][row]
        width = self.widths[row]
        return tuple(values if width == len(values) else values[:width])


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
