"""Driver (b): the whole-grid reference simulator.

The same rules as `rules.py`, computed for every robot at once, with no Python
loop over robots: discovery, sensing and the vote with NumPy (each neighbour
slot a shifted view of a padded array), the many consensus and formation steps
with the compiled kernels of `kernels.py`. Float64 operations happen in the same
order as the per-robot rules, so the results are bit-identical (tests check it).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np

from camo_core.algorithm import kernels, orientation, rng
from camo_core.algorithm.grid import NEIGHBOR_OFFSETS, NUM_SLOTS
from camo_core.algorithm.jit import numba
from camo_core.algorithm.modes import Modes, modes_of
from camo_core.algorithm.modes.palettes import GridPalette
from camo_core.algorithm.modes.scopes import Previous
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.result import RunResult, p_stats
from camo_core.algorithm.sensing import apply_colour_noise, apply_noise

PAD = 2  # slots reach two cells away
# Up to this many robots the kernels run on one thread: numba's threads gain a small grid
# nothing and cost it much when the cores are busy (an 8x8 grid took 0.9 ms on one thread,
# 12-35 ms on two of a loaded 2-core machine; twenty 32x32 runs beside two busy processes
# 0.29 CPU-s on two threads, 0.11 on one).
ONE_THREAD_ROBOTS = 128 * 128

Progress = Callable[[str, int, int], None]
# Shown every step: ("consensus", k, p before consensus step k), once ("chosen", 0, each
# robot's pattern code) and ("formation", k, state before formation step k); the arrays are
# reused afterwards (snapshots.Snapshots copies).
Observer = Callable[[str, int, np.ndarray], None]


class Grid:
    """Shifted views of padded arrays: `view(padded, slot)` is each robot's neighbour in `slot`."""

    def __init__(self, rows: int, cols: int) -> None:
        self.rows, self.cols = rows, cols
        self.ids = np.arange(rows * cols, dtype=np.uint64).reshape(rows, cols)
        self.exists = [
            self.view(self.pad(np.ones((rows, cols), bool)), s) for s in range(NUM_SLOTS)
        ]

    def pad(self, a: np.ndarray) -> np.ndarray:
        shape = (*a.shape[:-2], self.rows + 2 * PAD, self.cols + 2 * PAD)
        out = np.zeros(shape, dtype=a.dtype)
        out[..., PAD : PAD + self.rows, PAD : PAD + self.cols] = a
        return out

    def view(self, padded: np.ndarray, slot: int) -> np.ndarray:
        di, dj = NEIGHBOR_OFFSETS[slot]
        return padded[..., PAD + di : PAD + di + self.rows, PAD + dj : PAD + dj + self.cols]

    def arrivals(
        self, params: CamoParams, stream: int, step: int, slots: range
    ) -> list[np.ndarray] | None:
        """Per slot, which robots receive their neighbour's message (None: the link loses
        nothing)."""
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
    observe: Observer | None = None,
    raw_colours: np.ndarray | None = None,
    modes: Modes | None = None,
    previous: Previous | None = None,
) -> RunResult:
    """Run all phases on rows x cols block means (before measurement noise); `raw_colours`:
    the blocks' mean colours (rows x cols x 3 sRGB; colour sensing needs them, and with them the
    result knows how far the colours shown are from those sensed); `modes`: the run's
    variations (modes.modes_of(params) unless given); `previous`: the grid's last round, in a
    later round of a --scope local run (robots that saw no change keep what they showed)."""
    with kernel_threads(params.count):
        return _simulate(
            params, raw_sensed, exempt, progress, observe, raw_colours, modes, previous
        )


@contextmanager
def kernel_threads(robots: int) -> Iterator[None]:
    """numba's threads for a grid of `robots`: one up to ONE_THREAD_ROBOTS, else all of them
    (NUMBA_NUM_THREADS); as they were afterwards."""
    before = numba.get_num_threads()
    every = numba.config.NUMBA_NUM_THREADS  # type: ignore[attr-defined]  # set as numba loads
    numba.set_num_threads(1 if robots <= ONE_THREAD_ROBOTS else every)
    try:
        yield
    finally:
        numba.set_num_threads(before)


def _simulate(
    params: CamoParams,
    raw_sensed: np.ndarray,
    exempt: np.ndarray | None,
    progress: Progress | None,
    observe: Observer | None,
    raw_colours: np.ndarray | None,
    modes: Modes | None,
    previous: Previous | None,
) -> RunResult:
    start = time.perf_counter()
    modes = modes or modes_of(params)
    rows, cols = params.rows, params.cols
    if raw_sensed.shape != (rows, cols):
        raise ValueError(f"sensed grid is {raw_sensed.shape}, expected {(rows, cols)}")
    if raw_colours is None and modes.sensing.colour:
        raise ValueError(f"{modes.sensing.name} sensing needs the sensed colours (raw_colours)")
    if raw_colours is not None and raw_colours.shape != (rows, cols, 3):
        raise ValueError(f"sensed colours are {raw_colours.shape}, expected {(rows, cols, 3)}")
    grid = Grid(rows, cols)

    # Phase 0: a slot is known when its robot exists and its hello survived.
    hello = grid.arrivals(params, rng.STREAM_HELLO, 0, range(NUM_SLOTS))
    known = [
        grid.exists[s] if hello is None else grid.exists[s] & hello[s] for s in range(NUM_SLOTS)
    ]
    known_mask = np.zeros((rows, cols), np.uint16)
    for s in range(NUM_SLOTS):
        known_mask |= known[s].astype(np.uint16) << np.uint16(s)

    degree = np.zeros((rows, cols), np.uint8)
    for s in range(8):
        degree += ((known_mask >> s) & 1).astype(np.uint8)

    # Phase 1: sensing and the local vote.
    sensed = apply_noise(raw_sensed, params.seed, params.rho_meas, exempt)
    sensed_rgb = None
    if raw_colours is not None:
        sensed_rgb = apply_colour_noise(raw_colours, params.seed, params.rho_meas, exempt)
    votes, p0 = _vote(params, modes, sensed, known_mask, degree)
    initial = (sensed < 127).astype(np.uint8)
    tails = modes.histogram.start_vectors(sensed, sensed_rgb)
    if tails is not None:  # the histogram is averaged with p, in the same messages
        p0 = np.concatenate([p0, tails], axis=-1)

    # Phase 2: consensus.
    width = modes.descriptor.width
    p, trace, spread = _consensus(params, modes, p0, known_mask, degree, progress, observe)
    p, histogram = p[..., :width], p[..., width:]
    selected = modes.scope.choose(modes.descriptor, p)
    palette = modes.palette.grid(histogram, sensed, sensed_rgb)
    if palette.initial is not None:
        initial = palette.initial
    kept = None
    if previous is not None:  # robots that saw no change keep their camouflage
        kept = np.asarray(modes.scope.keeps(previous, raw_sensed), dtype=bool)
        selected = np.where(kept, previous.pattern, selected)
        initial = np.where(kept, previous.final, initial).astype(np.uint8)
        palette = palette.kept(kept, previous.palette)
    if observe:
        observe("chosen", 0, selected)

    # Phase 3: pattern formation.
    final = _formation(
        grid, params, modes, initial, selected, known_mask, progress, observe, palette, kept
    )

    return RunResult(
        params=params,
        sensed=sensed,
        votes=votes,
        p=p,
        selected=selected,
        initial=initial,
        final=final,
        consensus_trace=trace,
        elapsed_s=time.perf_counter() - start,
        consensus_range=spread,
        palette=palette.greys,
        sensed_rgb=sensed_rgb,
        palette_rgb=palette.colours,
        shades=palette.shades,
    )


def _vote(
    params: CamoParams,
    modes: Modes,
    sensed: np.ndarray,
    known_mask: np.ndarray,
    degree: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Each robot's vote (pattern code) and the p it starts consensus with: the one-hot vote,
    or with --orientation any its normalised structure tensor (and the vote that tensor says)."""
    shape = sensed.shape
    scores = np.empty(shape), np.empty(shape)
    energy = np.empty(shape)
    prefix = np.uint64(rng.prefix(params.seed, rng.STREAM_COLOR, 0))
    paper = params.profile == "paper"
    kernels.descriptors_all(sensed, known_mask, prefix, params.rho_comm, paper, *scores, energy)
    if modes.threshold.averages_energy:
        energy = _average_energy(params, energy, known_mask, degree)
    return modes.descriptor.vote_all(sensed, known_mask, prefix, params.rho_comm, scores, energy)


def _average_energy(
    params: CamoParams, energy: np.ndarray, known_mask: np.ndarray, degree: np.ndarray
) -> np.ndarray:
    """--threshold auto: consensus_steps Metropolis steps on the texture energy, by the
    p-vector's kernel (in its first component; the rule is per component)."""
    values = np.zeros((*energy.shape, 3))
    values[:, :, 0] = energy
    nxt = np.empty_like(values)
    for step in range(params.consensus_steps):
        prefix = np.uint64(rng.prefix(params.seed, rng.STREAM_ENERGY, step))
        kernels.consensus_step(values, nxt, known_mask, degree, prefix, params.rho_comm)
        values, nxt = nxt, values
    return values[:, :, 0].copy()


def _consensus(
    params: CamoParams,
    modes: Modes,
    p0: np.ndarray,
    known_mask: np.ndarray,
    degree: np.ndarray,
    progress: Progress | None,
    observe: Observer | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The consensus phase on p0 (p, the descriptor's width, then any histogram), as the
    scope has it: the averaged vectors, and per step the mean of what robots report and its
    least and greatest over robots."""
    width = modes.descriptor.width
    steps = modes.scope.steps(params)
    mean, least_greatest = p_stats(p0[..., :width])
    trace, spread = [mean], [least_greatest]
    if observe:
        observe("consensus", 0, p0[..., :width])

    def each_step(step: int, reported: np.ndarray) -> None:
        mean, least_greatest = p_stats(reported)
        trace.append(mean)
        spread.append(least_greatest)
        if observe:
            observe("consensus", step + 1, reported)
        if progress:
            progress("consensus", step + 1, steps)

    p = modes.scope.run(params, p0, width, known_mask, degree, each_step)
    return p, np.array(trace), np.array(spread)


def _formation(
    grid: Grid,
    params: CamoParams,
    modes: Modes,
    initial: np.ndarray,
    selected: np.ndarray,
    known_mask: np.ndarray,
    progress: Progress | None,
    observe: Observer | None,
    palette: GridPalette,
    kept: np.ndarray | None = None,
) -> np.ndarray:
    """Formation steps, on every layer of the states' bits (--levels: each with the same
    losses, as one state message carries them all); the observer sees what the robots show
    (modes.palette: states, greys or colours)."""
    state = initial.copy()
    nxt = np.empty_like(state)
    layer, layer_next = np.empty_like(state), np.empty_like(state)
    w2 = np.array(orientation.inhibitor_weights(params))
    layers = modes.palette.layers

    if observe:
        observe("formation", 0, modes.palette.frame(state, palette))
    for step in range(params.formation_steps):
        prefix = np.uint64(rng.prefix(params.seed, rng.STREAM_STATE, step))
        relay_prefix = np.uint64(rng.prefix(params.seed, rng.STREAM_RELAY, step))
        rule = (
            known_mask,
            selected,
            prefix,
            relay_prefix,
            params.rho_comm,
            params.w1,
            w2,
            params.profile == "droplet",
        )
        if layers == 1:
            kernels.formation_step(state, nxt, *rule)
        else:
            nxt[:] = 0
            for k in range(layers):
                np.bitwise_and(state >> np.uint8(k), 1, out=layer)
                kernels.formation_step(layer, layer_next, *rule)
                nxt |= layer_next << np.uint8(k)
        if kept is not None:  # robots that keep their last round's state: unchanged
            nxt[kept] = initial[kept]
        state, nxt = nxt, state
        if observe:
            observe("formation", step + 1, modes.palette.frame(state, palette))
        if progress:
            progress("formation", step + 1, params.formation_steps)
    return state
