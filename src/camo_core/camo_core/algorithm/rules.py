"""The per-robot rules of docs/algorithm.md §2, as pure functions of what one robot has.

A robot node calls these with what it received; the per-robot driver of the
reference simulator calls them for every cell. Missing messages are None.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import overload

import numpy as np

from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.patterns import (
    ACTIVATORS,
    HORIZONTAL,
    INHIBITORS,
    MOTTLED,
    PATTERNS,
    TIE,
    VERTICAL,
    WIDTH,
)

# Slot pairs that stand in for each other when one is missing (docs/algorithm.md §2.2, 2.4).
OPPOSITE_CARDINAL = {0: 2, 2: 0, 1: 3, 3: 1, 8: 10, 10: 8, 9: 11, 11: 9}
# Diagonals: mirror across the robot's row, then across its column, then point-opposite.
DIAGONAL_FALLBACKS: dict[int, tuple[int, int, int]] = {
    4: (5, 7, 6),
    5: (4, 6, 7),
    6: (7, 5, 4),
    7: (6, 4, 5),
}


# ---- phase 1: pattern descriptor ------------------------------------------------


def reflect_four(
    own: float, received: Sequence[float | None]
) -> tuple[float, float, float, float]:
    """T, R, B, L: a missing side takes the opposite side, else the robot's own value."""
    filled = []
    for slot in range(4):
        value = received[slot]
        if value is None:
            value = received[(slot + 2) % 4]
        filled.append(own if value is None else value)
    return filled[0], filled[1], filled[2], filled[3]


def descriptor(
    own: float, received: Sequence[float | None], profile: str
) -> tuple[float, float, float]:
    """(horizontal score, vertical score, texture energy) from the robot's value and slots
    0-3's values. The energy is the mean of the two differences' sizes: what a threshold is
    measured against."""
    top, right, bottom, left = reflect_four(own, received)
    if profile == "paper":
        across_x = abs(left + right - 2 * own)  # |Px|
        across_y = abs(top + bottom - 2 * own)  # |Py|
    else:
        across_x = abs(own - right) + abs(own - left)
        across_y = abs(own - top) + abs(own - bottom)
    return across_y - across_x, across_x - across_y, (across_x + across_y) / 2


@overload
def vote_from(horizontal_score: float, vertical_score: float, threshold: float) -> int: ...
@overload
def vote_from(
    horizontal_score: np.ndarray, vertical_score: np.ndarray, threshold: np.ndarray | float
) -> np.ndarray: ...
def vote_from(horizontal_score, vertical_score, threshold):
    """The vote from a descriptor's scores (docs/algorithm.md §2.2): one robot's (an int), or
    the whole grid's (arrays: an array of pattern codes)."""
    if isinstance(horizontal_score, np.ndarray):
        return np.where(
            horizontal_score > threshold,
            HORIZONTAL,
            np.where(vertical_score > threshold, VERTICAL, MOTTLED),
        ).astype(np.int64)
    if horizontal_score > threshold:
        return HORIZONTAL
    if vertical_score > threshold:
        return VERTICAL
    return MOTTLED


def vote(own: float, received: Sequence[float | None], params: CamoParams) -> int:
    """The local pattern vote from the robot's value and slots 0-3's values."""
    horizontal_score, vertical_score, _ = descriptor(own, received, params.profile)
    return vote_from(horizontal_score, vertical_score, params.threshold)


# --threshold auto: T_i = max(MIN_THRESHOLD, THRESHOLD_SHARE * the swarm's mean energy).
MIN_THRESHOLD = 5.0
THRESHOLD_SHARE = 0.5


def auto_threshold(energy: float) -> float:
    return max(MIN_THRESHOLD, THRESHOLD_SHARE * energy)


def one_hot(pattern: int) -> tuple[float, ...]:
    p = [0.0] * WIDTH
    p[pattern] = 1.0
    return tuple(p)


# ---- phase 2: consensus ---------------------------------------------------------


def consensus_step(
    p_own: Sequence[float],
    degree: int,
    received: Sequence[tuple[Sequence[float], int] | None],
) -> tuple[float, ...]:
    """One Metropolis step. `received[k]` is (p, degree) from slot k (0-7), or None; p has 3
    entries (35 with --levels: p, then the grey histogram and sums).

    Float64 accumulation order is part of the spec: neighbour terms and weights in
    slot order, then the self term last; a lost message's weight stays home.
    """
    size = len(p_own)
    if size == 3:
        return _consensus_step3(p_own, degree, received)
    acc = [0.0] * size
    weight_sum = 0.0
    for message in received:  # slots 0-7 on the grid; a layout's near neighbours in id order
        if message is None:
            continue
        p_other, degree_other = message
        w = 1.0 / (1.0 + max(degree, degree_other))
        for k in range(size):
            acc[k] = acc[k] + w * p_other[k]
        weight_sum = weight_sum + w
    keep = 1.0 - weight_sum
    return tuple(acc[k] + keep * p_own[k] for k in range(size))


def _consensus_step3(
    p_own: Sequence[float], degree: int, received: Sequence[tuple[Sequence[float], int] | None]
) -> tuple[float, float, float]:
    """consensus_step for the paper's 3-vector, written out: the same operations in the same
    order (so the same bits), without the per-component loop, which is most of a robot's step."""
    a0 = a1 = a2 = weight_sum = 0.0
    for message in received:
        if message is None:
            continue
        p_other, degree_other = message
        w = 1.0 / (1.0 + (degree_other if degree_other > degree else degree))
        a0 = a0 + w * p_other[0]
        a1 = a1 + w * p_other[1]
        a2 = a2 + w * p_other[2]
        weight_sum = weight_sum + w
    keep = 1.0 - weight_sum
    return a0 + keep * p_own[0], a1 + keep * p_own[1], a2 + keep * p_own[2]


def energy_step(energy: float, degree: int, received: Sequence[tuple[float, int] | None]) -> float:
    """consensus_step on one number: `received[k]` is (energy, degree) from slot k (0-7), or
    None. Carried in p's first component, as the simulator's kernel carries it (the rule is the
    same for each component)."""
    as_p = [None if m is None else ((m[0], 0.0, 0.0), m[1]) for m in received]
    return consensus_step((energy, 0.0, 0.0), degree, as_p)[0]


@overload
def select_pattern(p: Sequence[float]) -> int: ...
@overload
def select_pattern(p: np.ndarray) -> np.ndarray: ...
def select_pattern(p: Sequence[float] | np.ndarray) -> int | np.ndarray:
    """The pattern whose entry of p is strictly the largest; any tie for the largest goes to
    patterns.TIE (mottled).

    `p` is one robot's vector (an int comes back) or an array of them, last axis one entry per
    pattern (an array of pattern codes comes back, for the whole grid).
    """
    a = np.asarray(p, dtype=np.float64)
    chosen = np.full(a.shape[:-1], TIE)
    for k in range(WIDTH):
        if k == TIE:
            continue
        largest = np.ones(a.shape[:-1], bool)
        for j in range(WIDTH):
            if j != k:
                largest &= a[..., k] > a[..., j]
        chosen = np.where(largest, k, chosen)
    return int(chosen) if chosen.ndim == 0 else chosen


# ---- phase 3: pattern formation -------------------------------------------------


def initial_state(sensed: float) -> int:
    """Dark (1) where the sensed grey value is below 127."""
    return 1 if sensed < 127 else 0


def fill_states(received: Sequence[int | None]) -> list[int]:
    """Mirror rules for missing slots 0-11; fills read only values that arrived."""
    arrived = [v for v in received[:12] if v is not None]
    if len(arrived) == 12:
        return arrived  # every slot arrived (most robots, most steps)
    filled: list[int] = []
    for slot in range(12):
        value = received[slot]
        if value is None:
            candidates = DIAGONAL_FALLBACKS.get(slot) or (OPPOSITE_CARDINAL[slot],)
            value = next((v for c in candidates if (v := received[c]) is not None), 0)
        filled.append(value)
    return filled


def w2_for(pattern: int, params: CamoParams) -> float:
    """The inhibitor weight W2 of a pattern's kernel: the parameter its row names."""
    return getattr(params, PATTERNS[pattern].w2)


def formation_step(
    state: int, pattern: int, received: Sequence[int | None], params: CamoParams
) -> int:
    """Young's rule for one robot; the robot itself is an activator, on or off."""
    filled = fill_states(received)
    on_activators = state + sum(filled[s] for s in ACTIVATORS[pattern])
    on_inhibitors = sum(filled[s] for s in INHIBITORS[pattern])
    s = params.w1 * on_activators + w2_for(pattern, params) * on_inhibitors
    if s > 0:
        return 1
    if params.profile == "droplet" and s == 0:
        return state
    return 0
