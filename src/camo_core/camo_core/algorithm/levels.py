"""--levels K: the swarm shows K greys of its own choosing (docs/algorithm.md §2.6).

Each robot starts consensus with a 32-value vector: the one-hot of its grey's 16-level bin and
its grey times that one-hot. Averaged over the swarm (by the p-vector's Metropolis steps, in the
same messages), the first half is the swarm's grey histogram and the second the greys' sums per
bin. From it every robot computes the K - 1 multi-Otsu cuts (between bins, maximising the sum
over classes of n_k mu_k^2) and the classes' mean greys, its palette. Its state is then K - 1
bits, one binary layer per cut (on where its grey is below the cut), each running the
unchanged formation rule; a robot with L layers on shows palette[K - 1 - L].

Every sum runs left to right in float64, the same in a robot (Python floats) and over the
whole grid (NumPy, element by element), so all drivers compute the same cuts and palettes.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from functools import cache

import numpy as np

BINS = 16
BIN_WIDTH = 256 // BINS
SIZE = 2 * BINS  # the averaged vector: histogram, then sums of grey


def bin_of(grey: float) -> int:
    return min(BINS - 1, math.floor(grey / BIN_WIDTH))


def start_vector(grey: float) -> tuple[float, ...]:
    """What a robot averages: one-hot of its bin, then its grey in that bin."""
    vector = [0.0] * SIZE
    b = bin_of(grey)
    vector[b] = 1.0
    vector[BINS + b] = float(grey)
    return tuple(vector)


def start_vectors(greys: np.ndarray) -> np.ndarray:
    """start_vector for every robot (... x 32)."""
    bins = np.minimum(BINS - 1, np.floor(greys / BIN_WIDTH)).astype(np.int64)
    out = np.zeros((*greys.shape, SIZE))
    np.put_along_axis(out, bins[..., None], 1.0, axis=-1)
    np.put_along_axis(out, bins[..., None] + BINS, greys[..., None].astype(np.float64), axis=-1)
    return out


@cache
def _cut_sets(levels: int) -> tuple[tuple[int, ...], ...]:
    """Every choice of K - 1 cuts between bins (bin indices 1..15), in lexicographic order."""
    return tuple(itertools.combinations(range(1, BINS), levels - 1))


def _classes(levels: int) -> tuple[tuple[int, int], ...]:
    """Every (first bin, end bin) a class of some cut set can span."""
    return tuple(sorted({(lo, hi) for cuts in _cut_sets(levels) for lo, hi in _spans(cuts)}))


def _spans(cuts: Sequence[int]) -> list[tuple[int, int]]:
    edges = (0, *cuts, BINS)
    return list(itertools.pairwise(edges))


def palette(vector: Sequence[float], levels: int) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """(cuts in grey levels, ascending; the K display greys, darkest first) from one robot's
    averaged vector."""
    h, s = vector[:BINS], vector[BINS:SIZE]
    sums = {}
    for lo, hi in _classes(levels):
        n, total = 0.0, 0.0
        for b in range(lo, hi):
            n, total = n + h[b], total + s[b]
        sums[lo, hi] = (n, total, total * total / n if n > 0 else 0.0)
    best, chosen = -1.0, None
    for cuts in _cut_sets(levels):
        score = 0.0
        for span in _spans(cuts):
            score = score + sums[span][2]
        if score > best:
            best, chosen = score, cuts
    assert chosen is not None  # every score is >= 0 > -1, so some cut set is chosen
    greys = []
    for lo, hi in _spans(chosen):
        n, total, _ = sums[lo, hi]
        mean = total / n if n > 0 else BIN_WIDTH * (lo + hi) / 2
        greys.append(_grey(mean))
    return tuple(BIN_WIDTH * c for c in chosen), tuple(greys)


def palettes(vectors: np.ndarray, levels: int) -> tuple[np.ndarray, np.ndarray]:
    """palette for every robot (vectors ... x 32): cuts ... x (K - 1), greys ... x K."""
    h, s = vectors[..., :BINS], vectors[..., BINS:SIZE]
    shape = vectors.shape[:-1]
    sums = {}
    for lo, hi in _classes(levels):
        n, total = np.zeros(shape), np.zeros(shape)
        for b in range(lo, hi):
            n, total = n + h[..., b], total + s[..., b]
        with np.errstate(divide="ignore", invalid="ignore"):
            term = np.where(n > 0, total * total / n, 0.0)
        sums[lo, hi] = (n, total, term)
    best = np.full(shape, -1.0)
    chosen = np.zeros(shape, dtype=np.int64)
    sets = _cut_sets(levels)
    for index, cuts in enumerate(sets):
        score = np.zeros(shape)
        for span in _spans(cuts):
            score = score + sums[span][2]
        better = score > best
        chosen = np.where(better, index, chosen)
        best = np.where(better, score, best)
    table = np.array(sets, dtype=np.int64).reshape(len(sets), levels - 1)
    chosen_cuts = table[chosen]
    greys = np.zeros((*shape, levels), dtype=np.int64)
    for index, cut_set in enumerate(sets):
        here = chosen == index
        if not here.any():
            continue
        for k, (lo, hi) in enumerate(_spans(cut_set)):
            n, total, _ = sums[lo, hi]
            with np.errstate(divide="ignore", invalid="ignore"):
                mean = np.where(n > 0, total / n, BIN_WIDTH * (lo + hi) / 2)
            greys[..., k] = np.where(here, _greys(mean), greys[..., k])
    return BIN_WIDTH * chosen_cuts, greys


def _grey(mean: float) -> int:
    """A class mean as the integer grey a robot shows (halves round up)."""
    return int(min(255, max(0, math.floor(mean + 0.5))))


def _greys(mean: np.ndarray) -> np.ndarray:
    return np.clip(np.floor(mean + 0.5), 0, 255).astype(np.int64)


def initial_layers(grey: float, cuts: Sequence[int]) -> int:
    """The state's K - 1 bits: bit k on where the grey is below cut k."""
    return sum(1 << k for k, cut in enumerate(cuts) if grey < cut)


def shown(state: int, greys: Sequence[int]) -> int:
    """The grey a robot with these layers on shows."""
    return greys[len(greys) - 1 - state.bit_count()]


def shown_grid(states: np.ndarray, greys: np.ndarray) -> np.ndarray:
    """shown for every robot: states ... (layer bits), greys ... x K."""
    on = np.zeros(states.shape, dtype=np.int64)
    for k in range(greys.shape[-1] - 1):
        on += (states >> k) & 1
    index = greys.shape[-1] - 1 - on
    return np.take_along_axis(greys, index[..., None], axis=-1)[..., 0]
