"""--orientation any: stripes at any angle (docs/algorithm.md, "Orientation any").

Instead of a vote for horizontal, vertical or mottled, each robot measures a structure tensor
(Jxx, Jyy, Jxy) from its eight neighbours' colours; the swarm averages it as it averages p; each
robot reads a stripe direction (a multiple of 15 degrees) or mottled off its average, and draws
stripes with a kernel turned to that direction. Its two-hop cells that are not among the twelve
slots (the eight knight's moves) it learns from its neighbours' *relays*: each robot passes on
the states it received. Pattern codes: 0-2 are the paper's (rules.HORIZONTAL, VERTICAL,
MOTTLED); ORIENTED + k is stripes at 15k degrees, counter-clockwise from horizontal, y up.

Everything here is a table or plain arithmetic (+ - * / sqrt and comparisons, each rounded
once by IEEE 754), so that a robot, NumPy over the whole grid and the compiled kernels compute
the same bits.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import lru_cache
from typing import overload

import numpy as np

from camo_core.algorithm.grid import NEIGHBOR_OFFSETS
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.patterns import ACTIVATORS, INHIBITORS, MOTTLED, PATTERN_NAMES, WIDTH
from camo_core.algorithm.rules import (
    DIAGONAL_FALLBACKS,
    OPPOSITE_CARDINAL,
    reflect_four,
    w2_for,
)

REGULARISER = 16.0  # squared grey levels added to a tensor's trace before normalising it
COHERENCE_MIN = 0.15  # below it the averaged tensor says mottled
STEP_DEG = 15
ANGLES = 180 // STEP_DEG
ORIENTED = WIDTH  # pattern code of stripes at 0 degrees: the codes after the table's
CODES = ORIENTED + ANGLES

# The eight two-hop cells beyond the twelve slots, offsets (d_row, d_col): offsets 12-19.
KNIGHTS: tuple[tuple[int, int], ...] = (
    (-1, 2),
    (1, 2),
    (2, 1),
    (2, -1),
    (1, -2),
    (-1, -2),
    (-2, -1),
    (-2, 1),
)
OFFSETS = NEIGHBOR_OFFSETS + KNIGHTS
_SLOT_AT = {offset: slot for slot, offset in enumerate(NEIGHBOR_OFFSETS[:8])}


def _paths(di: int, dj: int) -> tuple[tuple[int, int], tuple[int, int]]:
    """The two neighbours that can relay a knight cell, as (slot of the neighbour, slot of the
    cell from that neighbour): first the one straight ahead, then the diagonal one."""
    if abs(dj) == 2:
        ahead, diagonal = (0, dj // 2), (di, dj // 2)
    else:
        ahead, diagonal = (di // 2, 0), (di // 2, dj)
    first, second = (
        (_SLOT_AT[mid], _SLOT_AT[(di - mid[0], dj - mid[1])]) for mid in (ahead, diagonal)
    )
    return first, second


RELAY_PATHS = tuple(_paths(di, dj) for di, dj in KNIGHTS)
# A knight cell nobody relayed takes its mirror across the robot's row, then across its column,
# then the point-opposite one, as a missing diagonal does (rules.DIAGONAL_FALLBACKS); in the
# oriented kernels a stand-in must have the missing cell's role (see formation_step).
KNIGHT_FALLBACKS = tuple(
    tuple(KNIGHTS.index(m) for m in ((-di, dj), (di, -dj), (-di, -dj))) for di, dj in KNIGHTS
)
# Per offset 0-19, the offsets that stand in for it, in order.
STAND_INS = tuple(
    DIAGONAL_FALLBACKS.get(s) or (OPPOSITE_CARDINAL[s],) for s in range(len(NEIGHBOR_OFFSETS))
) + tuple(tuple(len(NEIGHBOR_OFFSETS) + k for k in chain) for chain in KNIGHT_FALLBACKS)
OPPOSITE_CORNER = {4: 6, 5: 7, 6: 4, 7: 5}


# ---- phase 1: the structure tensor ------------------------------------------------


def raw_tensor(own: float, received: Sequence[float | None]) -> tuple[float, float, float]:
    """(Jxx, Jyy, Jxy) from the robot's grey and slots 0-7's (None: missing). A missing
    neighbour takes the one opposite it (so that a pair measures the same line), else the
    robot's own grey."""
    top, right, bottom, left = reflect_four(own, received)
    corner = []
    for slot in range(4, 8):
        value = received[slot]
        if value is None:
            value = received[OPPOSITE_CORNER[slot]]
        corner.append(own if value is None else value)
    top_right, bottom_right, bottom_left, top_left = corner
    return tensor_of(own, top, right, bottom, left, top_right, bottom_right, bottom_left, top_left)


def tensor_of(m, t, r, b, lf, tr, br, bl, tl):
    """The tensor from filled greys (scalars or NumPy arrays alike); y points down."""
    dr, dl, db, dt = r - m, lf - m, b - m, t - m
    dbr, dtl, dtr, dbl = br - m, tl - m, tr - m, bl - m
    q0 = (dr * dr + dl * dl) / 2
    q90 = (db * db + dt * dt) / 2
    qa = (dbr * dbr + dtl * dtl) / 4
    qb = (dtr * dtr + dbl * dbl) / 4
    diagonal = (qa + qb) / 2
    return q0 + diagonal, q90 + diagonal, (qa - qb) / 2


def normalised(jxx, jyy, jxy, reg):
    """The tensor each robot starts consensus with: divided by its trace plus `reg`."""
    denominator = (jxx + jyy) + reg
    return jxx / denominator, jyy / denominator, jxy / denominator


# ---- after consensus: the choice -----------------------------------------------------

# Stripes at 15k degrees have their double-angle vector (Jxx - Jyy, 2 Jxy) pointing at 180 - 30k
# degrees: the nearest of these twelve directions is the largest dot product.
DIRECTIONS = tuple(
    (
        math.cos(math.radians(180 - 2 * STEP_DEG * k)),
        math.sin(math.radians(180 - 2 * STEP_DEG * k)),
    )
    for k in range(ANGLES)
)


@overload
def choose(p: Sequence[float]) -> int: ...
@overload
def choose(p: np.ndarray) -> np.ndarray: ...
def choose(p: Sequence[float] | np.ndarray) -> int | np.ndarray:
    """Pattern code(s) from averaged tensors (last axis Jxx, Jyy, Jxy): MOTTLED where the
    coherence sqrt((Jxx - Jyy)^2 + 4 Jxy^2) / (Jxx + Jyy) is below COHERENCE_MIN (or the trace
    is not positive), else ORIENTED + k for the nearest 15k degrees."""
    a = np.asarray(p, dtype=np.float64)
    jxx, jyy, jxy = a[..., 0], a[..., 1], a[..., 2]
    x, y = jxx - jyy, 2.0 * jxy
    trace = jxx + jyy
    with np.errstate(divide="ignore", invalid="ignore"):
        coherence = np.sqrt(x * x + y * y) / trace
    best = x * DIRECTIONS[0][0] + y * DIRECTIONS[0][1]
    k = np.zeros(best.shape, dtype=np.int64)
    for index in range(1, ANGLES):
        c, s = DIRECTIONS[index]
        score = x * c + y * s
        k = np.where(score > best, index, k)
        best = np.maximum(score, best)
    chosen = np.where((trace > 0) & (coherence >= COHERENCE_MIN), ORIENTED + k, MOTTLED)
    return int(chosen) if chosen.ndim == 0 else chosen


def angle_of(code: int) -> int | None:
    """Degrees of a stripe code, counter-clockwise from horizontal (None for other codes)."""
    return (code - ORIENTED) * STEP_DEG if ORIENTED <= code < CODES else None


def pattern_name(code: int) -> str:
    return PATTERN_NAMES[code] if code < ORIENTED else f"stripes_{angle_of(code)}"


# ---- phase 3: the oriented kernel ------------------------------------------------


def _oriented_roles(degrees: float) -> list[int]:
    """Per offset 0-19: 1 activator, -1 inhibitor, 0 unused, for stripes at `degrees`."""
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    roles = []
    for di, dj in OFFSETS:
        # Rounded, so that a distance of exactly 0.5 or 1.5 (sin 30 is 0.49999999999999994 in
        # floats) falls on the side the rule puts it, and mirror angles get mirror kernels.
        along = round(abs(dj * c - di * s), 9)
        across = round(abs(dj * s + di * c), 9)
        if across < 0.5:
            roles.append(1)
        elif across < 1.5 and along < 1.5:
            roles.append(-1)
        else:
            roles.append(0)
    return roles


def _roles() -> np.ndarray:
    table = np.zeros((CODES, len(OFFSETS)), dtype=np.int64)
    for code in range(ORIENTED):
        table[code, list(ACTIVATORS[code])] = 1
        table[code, list(INHIBITORS[code])] = -1
    for k in range(ANGLES):
        table[ORIENTED + k] = _oriented_roles(k * STEP_DEG)
    return table


ROLES = _roles()  # ROLES[code, offset]


@lru_cache(maxsize=64)
def inhibitor_weights(params: CamoParams) -> tuple[float, ...]:
    """W2 per pattern code: the paper's two, and for stripes at an angle
    w2_stripes * (activators + 1) / 5 * 6 / inhibitors, which is w2_stripes at 0 and 90."""
    w2 = [w2_for(code, params) for code in range(ORIENTED)]
    for code in range(ORIENTED, CODES):
        activators = int(np.count_nonzero(ROLES[code] == 1))
        inhibitors = int(np.count_nonzero(ROLES[code] == -1))
        w2.append(params.w2_stripes * (activators + 1) / 5 * 6 / inhibitors)
    return tuple(w2)


def knight_states(relays: Sequence[Sequence[int | None] | None]) -> list[int | None]:
    """The eight knight cells' states from slots 0-7's relays (None: no relay), before
    fallbacks: the first relaying neighbour that had it."""
    out = []
    for paths in RELAY_PATHS:
        value = None
        for mid, sub in paths:
            relay = relays[mid]
            if value is None and relay is not None and relay[sub] is not None:
                value = relay[sub]
        out.append(value)
    return out


def formation_step(
    state: int,
    code: int,
    received: Sequence[int | None],
    knights: Sequence[int | None],
    params: CamoParams,
    w2: Sequence[float],
) -> int:
    """Young's rule over the twenty offsets of pattern `code` (received: slots 0-11, knights:
    the relayed knight cells, None where missing); the robot itself is an activator.

    A missing cell takes the first of its stand-ins (STAND_INS: the paper's mirrors) that has
    its role, else counts as off. In the paper's kernels every stand-in has its cell's role, so
    this is rules.fill_states; at 45 degrees the mirror across the row of an along-stripe
    diagonal lies across the stripe, and is passed over for the point-opposite one."""
    values = [*received[:12], *knights]
    roles = ROLES[code]
    on_activators, on_inhibitors = state, 0
    for offset, role in enumerate(roles):
        if role == 0:
            continue
        value = values[offset]
        for other in STAND_INS[offset]:
            if value is None and roles[other] == role:
                value = values[other]
        if value:
            if role > 0:
                on_activators += value
            else:
                on_inhibitors += value
    s = params.w1 * on_activators + w2[code] * on_inhibitors
    if s > 0:
        return 1
    if params.profile == "droplet" and s == 0:
        return state
    return 0
