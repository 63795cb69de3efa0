"""Driver (b): the vectorised whole-grid reference simulator.

The same rules as `rules.py`, computed for every robot at once with NumPy and
no Python loop over robots: each neighbour slot is a shifted view of a padded
array. Float64 operations happen in the same order as the per-robot rules, so
the results are bit-identical (tests check it).
"""
from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from . import rng
from .grid import NEIGHBOR_OFFSETS, NUM_SLOTS
from .params import CamoParams
from .result import RunResult, mean_p
from .rules import ACTIVATORS, DIAGONAL_FALLBACKS, HORIZONTAL, INHIBITORS, MOTTLED, VERTICAL
from .sensing import apply_noise

PAD = 2  # slots reach two cells away
_OPPOSITE = {0: 2, 2: 0, 1: 3, 3: 1, 8: 10, 10: 8, 9: 11, 11: 9}

Progress = Callable[[str, int, int], None]


class Grid:
    """Shifted views of padded arrays: `view(padded, slot)` is each robot's neighbour in `slot`."""

    def __init__(self, rows: int, cols: int) -> None:
        self.rows, self.cols = rows, cols
        self.ids = np.arange(rows * cols, dtype=np.uint64).reshape(rows, cols)
        self.exists = [self.view(self.pad(np.ones((rows, cols), bool)), s) for s in range(NUM_SLOTS)]

    def pad(self, a: np.ndarray, fill: float = 0) -> np.ndarray:
        shape = a.shape[:-2] + (self.rows + 2 * PAD, self.cols + 2 * PAD)
        out = np.full(shape, fill, dtype=a.dtype)
        out[..., PAD:PAD + self.rows, PAD:PAD + self.cols] = a
        return out

    def view(self, padded: np.ndarray, slot: int) -> np.ndarray:
        di, dj = NEIGHBOR_OFFSETS[slot]
        return padded[..., PAD + di:PAD + di + self.rows, PAD + dj:PAD + dj + self.cols]

    def interior(self, padded: np.ndarray) -> np.ndarray:
        return padded[..., PAD:PAD + self.rows, PAD:PAD + self.cols]

    def arrivals(self, params: CamoParams, stream: int, step: int, slots: range) -> list[np.ndarray] | None:
        """Per slot, which robots receive their neighbour's message (None: the link loses nothing)."""
        if params.rho_comm <= 0.0:
            return None
        sender = self.pad(rng.sender_hash(params.seed, stream, step, self.ids))
        out = []
        for s in slots:
            u = rng.to_unit(rng.mix_array(self.view(sender, s) ^ self.ids))
            out.append(u >= params.rho_comm)
        return out


def simulate(
    params: CamoParams,
    raw_sensed: np.ndarray,
    exempt: np.ndarray | None = None,
    progress: Progress | None = None,
) -> RunResult:
    """Run all phases on rows x cols block means (before measurement noise)."""
    start = time.perf_counter()
    rows, cols = params.rows, params.cols
    if raw_sensed.shape != (rows, cols):
        raise ValueError(f"sensed grid is {raw_sensed.shape}, expected {(rows, cols)}")
    grid = Grid(rows, cols)

    # Phase 0: a slot is known when its robot exists and its hello survived.
    hello = grid.arrivals(params, rng.STREAM_HELLO, 0, range(NUM_SLOTS))
    known = [grid.exists[s] if hello is None else grid.exists[s] & hello[s] for s in range(NUM_SLOTS)]

    # Phase 1: sensing and the local vote.
    sensed = apply_noise(raw_sensed, params.seed, params.rho_meas, exempt)
    votes = _vote(grid, params, sensed, known)
    initial = (sensed < 127).astype(np.uint8)

    # Phase 2: consensus.
    p, trace = _consensus(grid, params, votes, known, progress)
    selected = _select(p)

    # Phase 3: pattern formation.
    final = _formation(grid, params, initial, selected, known, progress)

    return RunResult(
        params=params,
        sensed=sensed,
        votes=votes,
        p=np.moveaxis(p, 0, -1).copy(),
        selected=selected,
        initial=initial,
        final=final,
        consensus_trace=trace,
        elapsed_s=time.perf_counter() - start,
    )


def _vote(grid: Grid, params: CamoParams, sensed: np.ndarray, known: list[np.ndarray]) -> np.ndarray:
    padded = grid.pad(sensed)
    color = grid.arrivals(params, rng.STREAM_COLOR, 0, range(4))
    got = [known[s] if color is None else known[s] & color[s] for s in range(4)]
    value = [grid.view(padded, s) for s in range(4)]
    sides = []
    for s in range(4):
        o = (s + 2) % 4
        sides.append(np.where(got[s], value[s], np.where(got[o], value[o], sensed)))
    top, right, bottom, left = sides
    m = sensed
    if params.profile == "paper":
        px = left + right - 2 * m
        py = top + bottom - 2 * m
        h_score, v_score = np.abs(py) - np.abs(px), np.abs(px) - np.abs(py)
    else:
        dx = np.abs(m - right) + np.abs(m - left)
        dy = np.abs(m - top) + np.abs(m - bottom)
        h_score, v_score = dy - dx, dx - dy
    return np.where(h_score > params.threshold, HORIZONTAL, np.where(v_score > params.threshold, VERTICAL, MOTTLED))


def _consensus(grid: Grid, params: CamoParams, votes: np.ndarray, known: list[np.ndarray],
               progress: Progress | None) -> tuple[np.ndarray, np.ndarray]:
    rows, cols = grid.rows, grid.cols
    degree = np.zeros((rows, cols), np.int64)
    for s in range(8):
        degree += known[s]
    degree_pad = grid.pad(degree)
    # Metropolis weight per slot; zero where the slot is unknown, so it adds exactly nothing.
    weights = [np.where(known[s], 1.0 / (1.0 + np.maximum(degree, grid.view(degree_pad, s))), 0.0) for s in range(8)]

    planes = np.zeros((3, rows, cols))
    for k in range(3):
        planes[k] = votes == k
    buffers = [grid.pad(planes), grid.pad(planes)]
    trace = [mean_p(planes)]
    w_sum_static = _ordered_sum(weights)
    acc = np.empty((3, rows, cols))
    term = np.empty((3, rows, cols))
    for step in range(params.consensus_steps):
        cur_pad, nxt_pad = buffers[step % 2], buffers[(step + 1) % 2]
        cur = grid.interior(cur_pad)
        arrive = grid.arrivals(params, rng.STREAM_CONSENSUS, step, range(8))
        w = weights if arrive is None else [np.where(arrive[s], weights[s], 0.0) for s in range(8)]
        acc.fill(0.0)
        for s in range(8):
            np.multiply(w[s], grid.view(cur_pad, s), out=term)
            acc += term
        w_sum = w_sum_static if arrive is None else _ordered_sum(w)
        keep = 1.0 - w_sum
        nxt = grid.interior(nxt_pad)
        np.multiply(keep, cur, out=nxt)
        np.add(acc, nxt, out=nxt)
        trace.append(mean_p(nxt))
        if progress:
            progress("consensus", step + 1, params.consensus_steps)
    final = grid.interior(buffers[params.consensus_steps % 2]).copy()
    return final, np.array(trace)


def _ordered_sum(arrays: list[np.ndarray]) -> np.ndarray:
    total = np.zeros_like(arrays[0])
    for a in arrays:
        total = total + a
    return total


def _select(p: np.ndarray) -> np.ndarray:
    h, v, m = p
    return np.where((h > v) & (h > m), HORIZONTAL, np.where((v > h) & (v > m), VERTICAL, MOTTLED))


def _formation(grid: Grid, params: CamoParams, initial: np.ndarray, selected: np.ndarray,
               known: list[np.ndarray], progress: Progress | None) -> np.ndarray:
    state = initial.astype(np.int64)
    w2 = np.where(selected == MOTTLED, params.w2_mottled, params.w2_stripes)
    masks = {k: selected == k for k in (HORIZONTAL, VERTICAL, MOTTLED)}
    for step in range(params.formation_steps):
        padded = grid.pad(state)
        arrive = grid.arrivals(params, rng.STREAM_STATE, step, range(NUM_SLOTS))
        got = [known[s] if arrive is None else known[s] & arrive[s] for s in range(NUM_SLOTS)]
        value = [grid.view(padded, s) for s in range(NUM_SLOTS)]
        filled = []
        for s in range(NUM_SLOTS):
            fallbacks = DIAGONAL_FALLBACKS.get(s) or (_OPPOSITE[s],)
            v = np.zeros_like(state)
            for c in reversed(fallbacks):
                v = np.where(got[c], value[c], v)
            filled.append(np.where(got[s], value[s], v))
        on_act = state.copy()
        on_inh = np.zeros_like(state)
        for k, mask in masks.items():
            on_act += mask * sum(filled[s] for s in ACTIVATORS[k])
            on_inh += mask * sum(filled[s] for s in INHIBITORS[k])
        strength = params.w1 * on_act + w2 * on_inh
        new = (strength > 0).astype(np.int64)
        if params.profile == "droplet":
            new = np.where(strength == 0, state, new)
        state = new
        if progress:
            progress("formation", step + 1, params.formation_steps)
    return state.astype(np.uint8)
