"""Compiled per-step kernels of the whole-grid simulator (numba).

Each robot's arithmetic is exactly that of `rules.py`, in the same float64
order (no fast-math, so no reassociation or fused multiply-add); only the loop
over robots is compiled, and rows run in parallel. The link's loss draws are
docs/algorithm.md §3's hash, computed in place from (prefix, sender, receiver).
"""

from __future__ import annotations

import hashlib

import numpy as np

from camo_core.algorithm import orientation, rng
from camo_core.algorithm.jit import njit, prange
from camo_core.algorithm.orientation import KNIGHT_FALLBACKS, OFFSETS, ORIENTED, RELAY_PATHS
from camo_core.algorithm.patterns import HORIZONTAL, MOTTLED, VERTICAL
from camo_core.algorithm.rules import DIAGONAL_FALLBACKS, OPPOSITE_CARDINAL

# Offsets 0-11 are the slots, 12-19 the knight cells of --orientation any (orientation.OFFSETS).
DI = np.array([o[0] for o in OFFSETS], dtype=np.int64)
DJ = np.array([o[1] for o in OFFSETS], dtype=np.int64)
SLOTS = 12
# Fallback slots per slot (-1: none), in the order docs/algorithm.md §2.4 tries them.
FALLBACK = np.full((12, 3), -1, dtype=np.int64)
for _s in range(12):
    _chain = DIAGONAL_FALLBACKS.get(_s) or (OPPOSITE_CARDINAL[_s],)
    FALLBACK[_s, : len(_chain)] = _chain
# ROLE[pattern code, offset]: 1 activator, -1 inhibitor, 0 unused.
ROLE = orientation.ROLES
# Per knight cell: the (neighbour slot, its slot of the cell) pairs that relay it, and the knight
# cells that stand in for it.
RELAY = np.array(RELAY_PATHS, dtype=np.int64)
KNIGHT_FALLBACK = np.array(KNIGHT_FALLBACKS, dtype=np.int64)

# docs/algorithm.md §3's SplitMix64, with rng.py's constants (numba freezes module globals).
_GOLDEN = np.uint64(rng.GOLDEN)
_M1 = np.uint64(rng.M1)
_M2 = np.uint64(rng.M2)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_INV_2_53 = rng.INV_2_53
ALL_SLOTS = (1 << 12) - 1
# w = 1 / (1 + max degree), computed once per possible degree: the same float64 as rules.py.
METROPOLIS = np.array([1.0 / (1.0 + d) for d in range(9)])


def _fingerprint() -> int:
    """A hash of every value the kernels freeze from other modules. numba's cache is keyed on
    this file alone: after a change to rules.py, grid.py or rng.py (a `git pull`, say), cached
    kernels would run the old tables, and the simulator would part from the per-robot rules."""
    frozen = (DI, DJ, FALLBACK, ROLE, RELAY, KNIGHT_FALLBACK, METROPOLIS)
    numbers = (HORIZONTAL, VERTICAL, MOTTLED, ORIENTED, rng.GOLDEN, rng.M1, rng.M2, rng.INV_2_53)
    text = repr(([a.tolist() for a in frozen], numbers)).encode()
    return int.from_bytes(hashlib.sha256(text).digest()[:7], "little")  # an int64


TABLES = _fingerprint()


@njit(cache=True, inline="always")
def _mix(x):
    x = x + _GOLDEN
    x = (x ^ (x >> _S30)) * _M1
    x = (x ^ (x >> _S27)) * _M2
    return x ^ (x >> _S31)


@njit(cache=True, inline="always")
def _arrives(prefix, src, dst, rho):
    if rho <= 0.0:
        return True
    h = _mix(_mix(prefix ^ np.uint64(src)) ^ np.uint64(dst))
    return float(h >> _S11) * _INV_2_53 >= rho


@njit(cache=True, inline="always")
def _weight(known, degree, i, j, s, prefix, rho):
    """The Metropolis weight robot (i, j) gives its slot s's message this step: 0 when that
    slot is unknown or its message is lost."""
    if (known[i, j] >> s) & 1 == 0:
        return 0.0
    cols = degree.shape[1]
    ni = i + DI[s]
    nj = j + DJ[s]
    if not _arrives(prefix, ni * cols + nj, i * cols + j, rho):
        return 0.0
    d = degree[i, j]
    dn = degree[ni, nj]
    return METROPOLIS[d if d > dn else dn]


@njit(cache=True, parallel=True)
def consensus_step(p, out, known, degree, prefix, rho):
    """One Metropolis step for every robot: p (rows x cols x 3) -> out."""
    rows, cols = degree.shape
    for i in prange(rows):
        for j in range(cols):
            a0 = 0.0
            a1 = 0.0
            a2 = 0.0
            w_sum = 0.0
            for s in range(8):
                w = _weight(known, degree, i, j, s, prefix, rho)
                if w == 0.0:
                    continue
                ni = i + DI[s]
                nj = j + DJ[s]
                a0 = a0 + w * p[ni, nj, 0]
                a1 = a1 + w * p[ni, nj, 1]
                a2 = a2 + w * p[ni, nj, 2]
                w_sum = w_sum + w
            keep = 1.0 - w_sum
            out[i, j, 0] = a0 + keep * p[i, j, 0]
            out[i, j, 1] = a1 + keep * p[i, j, 1]
            out[i, j, 2] = a2 + keep * p[i, j, 2]


@njit(cache=True, parallel=True)
def consensus_step_n(p, out, known, degree, prefix, rho):
    """consensus_step for vectors of any length (--levels: p and the grey histogram)."""
    rows, cols = degree.shape
    size = p.shape[2]
    for i in prange(rows):
        acc = np.empty(size)
        for j in range(cols):
            for k in range(size):
                acc[k] = 0.0
            w_sum = 0.0
            for s in range(8):
                w = _weight(known, degree, i, j, s, prefix, rho)
                if w == 0.0:
                    continue
                ni = i + DI[s]
                nj = j + DJ[s]
                for k in range(size):
                    acc[k] = acc[k] + w * p[ni, nj, k]
                w_sum = w_sum + w
            keep = 1.0 - w_sum
            for k in range(size):
                out[i, j, k] = acc[k] + keep * p[i, j, k]


@njit(cache=True, parallel=True)
def consensus_step_gated(p, out, known, degree, prefix, rho, label):
    """consensus_step_n among neighbours of the robot's own label (--scope local's segment
    consensus): another label's message counts as not received."""
    rows, cols = degree.shape
    size = p.shape[2]
    for i in prange(rows):
        acc = np.empty(size)
        for j in range(cols):
            for k in range(size):
                acc[k] = 0.0
            w_sum = 0.0
            for s in range(8):
                w = _weight(known, degree, i, j, s, prefix, rho)
                if w == 0.0:
                    continue
                ni = i + DI[s]
                nj = j + DJ[s]
                if label[ni, nj] != label[i, j]:
                    continue
                for k in range(size):
                    acc[k] = acc[k] + w * p[ni, nj, k]
                w_sum = w_sum + w
            keep = 1.0 - w_sum
            for k in range(size):
                out[i, j, k] = acc[k] + keep * p[i, j, k]


@njit(cache=True, inline="always")
def _state_in(state, known, i, j, s, prefix, rho):
    """State received from slot s of robot (i, j), or -1 if nothing arrived."""
    if (known[i, j] >> s) & 1 == 0:
        return -1
    cols = state.shape[1]
    ni = i + DI[s]
    nj = j + DJ[s]
    if not _arrives(prefix, ni * cols + nj, i * cols + j, rho):
        return -1
    return np.int64(state[ni, nj])


@njit(cache=True, parallel=True)
def formation_step(state, out, known, selected, prefix, relay_prefix, rho, w1, w2, keep_on_zero):
    """One step of Young's rule for every robot: state (rows x cols uint8) -> out. `w2`: the
    inhibitor weight per pattern code; the knight cells (stripes at an angle) come relayed."""
    rows, cols = state.shape
    for i in prange(rows):
        for j in range(cols):
            pattern = selected[i, j]
            offsets = SLOTS if pattern < ORIENTED else SLOTS + 8
            on_act = np.int64(state[i, j])
            on_inh = np.int64(0)
            if rho <= 0.0 and known[i, j] == ALL_SLOTS:
                # Fast path: every slot known and nothing lost, so no slot needs filling (and
                # every knight cell is relayed, as its relays are two cells from any edge too).
                for s in range(offsets):
                    role = ROLE[pattern, s]
                    if role > 0:
                        on_act += state[i + DI[s], j + DJ[s]]
                    elif role < 0:
                        on_inh += state[i + DI[s], j + DJ[s]]
            else:
                on_act, on_inh = _counts_with_fill(
                    state, known, i, j, pattern, prefix, rho, on_act, on_inh
                )
                if offsets > SLOTS:
                    on_act, on_inh = _knight_counts(
                        state, known, i, j, pattern, prefix, relay_prefix, rho, on_act, on_inh
                    )
            strength = w1 * on_act + w2[pattern] * on_inh
            if strength > 0:
                out[i, j] = 1
            elif keep_on_zero and strength == 0:
                out[i, j] = state[i, j]
            else:
                out[i, j] = 0


@njit(cache=True, inline="always")
def _counts_with_fill(state, known, i, j, pattern, prefix, rho, on_act, on_inh):
    """Activator and inhibitor counts where slots may be missing (docs/algorithm.md §2.4)."""
    for s in range(SLOTS):
        role = ROLE[pattern, s]
        if role == 0:
            continue
        v = _state_in(state, known, i, j, s, prefix, rho)
        f = 0
        while v < 0 and f < 3 and FALLBACK[s, f] >= 0:
            # A stand-in of another role is passed over (orientation.formation_step); in the
            # paper's kernels every stand-in has its cell's role.
            if ROLE[pattern, FALLBACK[s, f]] == role:
                v = _state_in(state, known, i, j, FALLBACK[s, f], prefix, rho)
            f += 1
        if v > 0:
            if role > 0:
                on_act += v
            else:
                on_inh += v
    return on_act, on_inh


@njit(cache=True, inline="always")
def _relayed(state, known, i, j, k, prefix, relay_prefix, rho):
    """Knight cell k's state as relayed to robot (i, j), or -1 (orientation.knight_states)."""
    cols = state.shape[1]
    for path in range(2):
        mid = RELAY[k, path, 0]
        sub = RELAY[k, path, 1]
        if (known[i, j] >> mid) & 1 == 0:
            continue
        mi = i + DI[mid]
        mj = j + DJ[mid]
        if not _arrives(relay_prefix, mi * cols + mj, i * cols + j, rho):
            continue
        v = _state_in(state, known, mi, mj, sub, prefix, rho)
        if v >= 0:
            return v
    return -1


@njit(cache=True, inline="always")
def _knight_counts(state, known, i, j, pattern, prefix, relay_prefix, rho, on_act, on_inh):
    """The knight cells' share of the counts, with their stand-ins (orientation.STAND_INS)."""
    for k in range(8):
        role = ROLE[pattern, SLOTS + k]
        if role == 0:
            continue
        v = _relayed(state, known, i, j, k, prefix, relay_prefix, rho)
        f = 0
        while v < 0 and f < 3:
            other = KNIGHT_FALLBACK[k, f]
            if ROLE[pattern, SLOTS + other] == role:
                v = _relayed(state, known, i, j, other, prefix, relay_prefix, rho)
            f += 1
        if v > 0:
            if role > 0:
                on_act += v
            else:
                on_inh += v
    return on_act, on_inh


@njit(cache=True, parallel=True)
def descriptors_all(sensed, known, prefix, rho, paper_profile, h_score, v_score, energy):
    """Every robot's descriptor (docs/algorithm.md §2.2), as rules.descriptor has it: its
    horizontal and vertical scores and its texture energy."""
    rows, cols = sensed.shape
    for i in prange(rows):
        side = np.empty(4)
        for j in range(cols):
            own = sensed[i, j]
            me = i * cols + j
            got = np.zeros(4, dtype=np.bool_)
            for s in range(4):
                if (known[i, j] >> s) & 1:
                    ni = i + DI[s]
                    nj = j + DJ[s]
                    if _arrives(prefix, ni * cols + nj, me, rho):
                        got[s] = True
                        side[s] = sensed[ni, nj]
            fill = np.empty(4)
            for s in range(4):
                o = (s + 2) % 4
                fill[s] = side[s] if got[s] else (side[o] if got[o] else own)
            top, right, bottom, left = fill[0], fill[1], fill[2], fill[3]
            if paper_profile:
                across_x = abs(left + right - 2 * own)
                across_y = abs(top + bottom - 2 * own)
            else:
                across_x = abs(own - right) + abs(own - left)
                across_y = abs(own - top) + abs(own - bottom)
            h_score[i, j] = across_y - across_x
            v_score[i, j] = across_x - across_y
            energy[i, j] = (across_x + across_y) / 2


_tensor_of = njit(cache=True, inline="always")(orientation.tensor_of)


@njit(cache=True, parallel=True)
def tensors_all(sensed, known, prefix, rho, jxx, jyy, jxy):
    """Every robot's structure tensor (--orientation any), as orientation.raw_tensor has it:
    from slots 0-7's colours, a missing one taking the opposite one's, else the robot's own."""
    rows, cols = sensed.shape
    for i in prange(rows):
        side = np.empty(8)
        got = np.zeros(8, dtype=np.bool_)
        fill = np.empty(8)
        for j in range(cols):
            own = sensed[i, j]
            me = i * cols + j
            for s in range(8):
                got[s] = False
                if (known[i, j] >> s) & 1:
                    ni = i + DI[s]
                    nj = j + DJ[s]
                    if _arrives(prefix, ni * cols + nj, me, rho):
                        got[s] = True
                        side[s] = sensed[ni, nj]
            for s in range(8):
                o = (s + 2) % 4 if s < 4 else 4 + (s - 2) % 4  # the opposite neighbour
                fill[s] = side[s] if got[s] else (side[o] if got[o] else own)
            a, b, c = _tensor_of(
                own, fill[0], fill[1], fill[2], fill[3], fill[4], fill[5], fill[6], fill[7]
            )
            jxx[i, j] = a
            jyy[i, j] = b
            jxy[i, j] = c


@njit(cache=True)
def mean_p(p_flat):
    """Mean of p over robots (robots x width), summed in robot-id order: one order for every
    driver."""
    n, width = p_flat.shape
    total = np.zeros(width)
    for r in range(n):
        for k in range(width):
            total[k] = total[k] + p_flat[r, k]
    return total / n


@njit(cache=True)
def p_stats(p_flat):
    """mean_p's mean (the same sums in the same order) and, in the same pass, width x 2: the
    least and the greatest p over robots, per entry (NaN where the first robot's is)."""
    n, width = p_flat.shape
    total = np.zeros(width)
    spread = np.full((width, 2), np.nan)
    if n == 0:
        return total / n, spread
    spread[:, 0] = p_flat[0]
    spread[:, 1] = p_flat[0]
    # Three entries at a time, each in robot-id order as mean_p sums them: three independent
    # sums, least and greatest in registers rather than one chain through memory.
    for k0 in range(0, width, 3):
        a, b, c = k0, min(k0 + 1, width - 1), min(k0 + 2, width - 1)
        sa, sb, sc = 0.0, 0.0, 0.0
        la, lb, lc = spread[a, 0], spread[b, 0], spread[c, 0]
        ga, gb, gc = spread[a, 1], spread[b, 1], spread[c, 1]
        for r in range(n):
            va, vb, vc = p_flat[r, a], p_flat[r, b], p_flat[r, c]
            sa += va
            sb += vb
            sc += vc
            la = va if va < la else la
            lb = vb if vb < lb else lb
            lc = vc if vc < lc else lc
            ga = va if va > ga else ga
            gb = vb if vb > gb else gb
            gc = vc if vc > gc else gc
        # a width that is no multiple of three repeats its last entry: the same values again
        total[c], spread[c, 0], spread[c, 1] = sc, lc, gc
        total[b], spread[b, 0], spread[b, 1] = sb, lb, gb
        total[a], spread[a, 0], spread[a, 1] = sa, la, ga
    return total / n, spread


@njit(cache=True)
def frozen_tables():
    """The fingerprint these compiled kernels were built with (TABLES, as it was then)."""
    return TABLES


def _drop_stale_kernels() -> None:
    """Cached kernels built from other tables than today's are thrown away and built again."""
    if frozen_tables() == TABLES:
        return
    for kernel in list(globals().values()):
        cache = getattr(kernel, "_cache", None)
        if cache is not None and hasattr(kernel, "recompile"):
            cache.flush()  # the cached versions; this process compiles them anew on first call
    frozen_tables.recompile()


_drop_stale_kernels()
