"""The rules on a --layout, and the driver that runs them (docs/algorithm.md §2.7).

A robot on a layout has no grid slots: it has neighbours at measured offsets. Its
descriptor is a least-squares fit of a structure tensor to the squared grey changes towards
its near neighbours; consensus and the choice are those of --orientation any; its formation
kernel is built from the offsets of the neighbours within reach, with its own inhibitor
weight, which stands in for the grid's edge mirroring. A lost message counts as off.

The driver calls these per robot, as a robot node would: on a layout it is the simulator.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np

from . import levels, orientation, rng, rules
from .layout import Layout
from .params import CamoParams
from .result import RunResult, mean_p
from .sensing import noisy_value

STRIPE_REACH = 2.25  # an along-stripe activator is at most this far
MOTTLED_ACTIVATOR = 1.2
MOTTLED_INHIBITOR = 2.05


def fitted_tensor(
    own: float, greys: Sequence[float | None], offsets: Sequence[tuple[float, float]]
) -> tuple[float, float, float] | None:
    """(Gxx, Gyy, Gxy), y down, fitted by least squares to q_j = ((c_j - c) / |r_j|)^2 =
    u_j^T G u_j over the neighbours heard (u_j: unit bearing), negative eigenvalues clipped;
    None (the robot abstains) with fewer than three distinct bearings."""
    rows, qs, bearings = [], [], set()
    for grey, (dx, dy) in zip(greys, offsets, strict=True):
        if grey is None:
            continue
        r = math.hypot(dx, dy)
        ux, uy = dx / r, dy / r
        rows.append((ux * ux, uy * uy, 2 * ux * uy))
        change = (grey - own) / r
        qs.append(change * change)
        bearings.add(round(math.degrees(math.atan2(uy, ux)) % 180.0, 6) % 180.0)
    if len(bearings) < 3:
        return None
    m = [[sum(a[i] * a[j] for a in rows) for j in range(3)] for i in range(3)]
    b = [sum(a[i] * q for a, q in zip(rows, qs, strict=True)) for i in range(3)]
    det = _det(m)
    if abs(det) < 1e-12:
        return None
    g = []
    for k in range(3):
        replaced = [[b[i] if j == k else m[i][j] for j in range(3)] for i in range(3)]
        g.append(_det(replaced) / det)
    return _clipped(*g)


def _det(m: list[list[float]]) -> float:
    return (
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    )


def _clipped(a: float, c: float, b: float) -> tuple[float, float, float]:
    """The symmetric [[a, b], [b, c]] with its negative eigenvalues set to 0."""
    mean, radius = (a + c) / 2, math.hypot((a - c) / 2, b)
    high, low = mean + radius, mean - radius
    if low >= 0:
        return a, c, b
    if high <= 0:
        return 0.0, 0.0, 0.0
    vx, vy = (b, high - a) if abs(b) > 0 or high != a else (1.0, 0.0)
    if vx == 0 and vy == 0:
        vx, vy = high - c, b
    norm = vx * vx + vy * vy
    return high * vx * vx / norm, high * vy * vy / norm, high * vx * vy / norm


def texture_energy(own: float, greys: Sequence[float | None], offsets) -> float:
    """The mean size of the grey change per spacing towards the neighbours heard."""
    changes = [
        abs(grey - own) / math.hypot(dx, dy)
        for grey, (dx, dy) in zip(greys, offsets, strict=True)
        if grey is not None
    ]
    return sum(changes) / len(changes) if changes else 0.0


def kernel(
    code: int, offsets: Sequence[tuple[float, float]], params: CamoParams
) -> tuple[list[int], float]:
    """Roles (1 activator, -1 inhibitor, 0 unused) of the neighbours at `offsets`, and this
    robot's inhibitor weight W2 (n_act + 1) / 5 * 6 / n_inh (8 for mottled; 0 with none)."""
    roles = []
    angle = orientation.angle_of(code)
    for dx, dy in offsets:
        r = math.hypot(dx, dy)
        if angle is None:
            roles.append(1 if r <= MOTTLED_ACTIVATOR else -1 if r <= MOTTLED_INHIBITOR else 0)
            continue
        c, s = math.cos(math.radians(angle)), math.sin(math.radians(angle))
        along, across = abs(dx * c - dy * s), abs(dx * s + dy * c)
        if across < 0.5 and r <= STRIPE_REACH:
            roles.append(1)
        elif 0.5 <= across < 1.5 and along < 1.5:
            roles.append(-1)
        else:
            roles.append(0)
    n_act, n_inh = roles.count(1), roles.count(-1)
    w2, share = (params.w2_stripes, 6) if angle is not None else (params.w2_mottled, 8)
    return roles, (w2 * (n_act + 1) / 5 * share / n_inh if n_inh else 0.0)


def formation_step(
    state: int, roles: Sequence[int], w2: float, states: Sequence[int | None], params
) -> int:
    on_act = state + sum(v for v, r in zip(states, roles, strict=True) if r > 0 and v)
    on_inh = sum(v for v, r in zip(states, roles, strict=True) if r < 0 and v)
    s = params.w1 * on_act + w2 * on_inh
    if s > 0:
        return 1
    if params.profile == "droplet" and s == 0:
        return state
    return 0


def run_on_layout(
    params: CamoParams, layout: Layout, raw: np.ndarray, exempt: np.ndarray | None = None
) -> RunResult:
    """The whole run on a layout, robot by robot; `raw`: each robot's grey before noise."""
    start = time.perf_counter()
    seed, rho = params.seed, params.rho_comm
    n, positions = layout.count, layout.positions
    pairs = layout.neighbours()
    slots = [near + far for near, far in pairs]
    offsets = [[tuple(positions[j] - positions[i]) for j in s] for i, s in enumerate(slots)]

    def heard(stream, step, i, values, upto=None):
        chosen = slots[i][: len(pairs[i][0]) if upto == "near" else None]
        return [
            values[j] if known[i][k] and not rng.lost(seed, stream, step, j, i, rho) else None
            for k, j in enumerate(chosen)
        ]

    hello = rng.STREAM_HELLO
    known = [[not rng.lost(seed, hello, 0, j, i, rho) for j in s] for i, s in enumerate(slots)]
    degree = [sum(known[i][: len(pairs[i][0])]) for i in range(n)]
    real = np.zeros(n, bool) if exempt is None else np.asarray(exempt, bool).ravel()
    sensed = [
        float(raw[i]) if real[i] else noisy_value(seed, i, float(raw[i]), params.rho_meas)
        for i in range(n)
    ]
    near_offsets = [o[: len(pairs[i][0])] for i, o in enumerate(offsets)]
    colours = [heard(rng.STREAM_COLOR, 0, i, sensed, "near") for i in range(n)]
    energy = [texture_energy(sensed[i], colours[i], near_offsets[i]) for i in range(n)]
    if params.threshold_auto:
        for step in range(params.consensus_steps):
            sent = [(e, d) for e, d in zip(energy, degree, strict=True)]
            got = [heard(rng.STREAM_ENERGY, step, i, sent, "near") for i in range(n)]
            energy = [rules.energy_step(energy[i], degree[i], got[i]) for i in range(n)]
    p = []
    for i in range(n):
        tensor = fitted_tensor(sensed[i], colours[i], near_offsets[i]) or (0.0, 0.0, 0.0)
        vector = orientation.normalised(*tensor, orientation.regulariser(params, energy[i]))
        p.append((*vector, *levels.start_vector(sensed[i])) if params.levels else vector)
    votes = orientation.choose(np.array([v[:3] for v in p]))
    trace = [mean_p(np.array([v[:3] for v in p]))]
    for step in range(params.consensus_steps):
        sent = [(v, d) for v, d in zip(p, degree, strict=True)]
        got = [heard(rng.STREAM_CONSENSUS, step, i, sent, "near") for i in range(n)]
        p = [rules.consensus_step(p[i], degree[i], got[i]) for i in range(n)]
        trace.append(mean_p(np.array([v[:3] for v in p])))
    pattern = [orientation.choose(v[:3]) for v in p]
    palettes = [levels.palette(v[3:], params.levels) for v in p] if params.levels else None
    if palettes:
        state = [levels.initial_layers(sensed[i], palettes[i][0]) for i in range(n)]
    else:
        state = [rules.initial_state(g) for g in sensed]
    initial = list(state)
    kernels = [kernel(pattern[i], offsets[i], params) for i in range(n)]
    layers = max(1, params.levels - 1)
    for step in range(params.formation_steps):
        sent = list(state)
        new = []
        for i in range(n):
            got = heard(rng.STREAM_STATE, step, i, sent)
            roles, w2 = kernels[i]
            value = 0
            for k in range(layers):
                bits = [None if v is None else (v >> k) & 1 for v in got]
                value |= formation_step((state[i] >> k) & 1, roles, w2, bits, params) << k
            new.append(value)
        state = new
    shape = (params.rows, params.cols)
    return RunResult(
        params=params,
        sensed=np.array(sensed).reshape(shape),
        votes=np.asarray(votes).reshape(shape),
        p=np.array([v[:3] for v in p]).reshape((*shape, 3)),
        selected=np.array(pattern).reshape(shape),
        initial=np.array(initial, dtype=np.uint8).reshape(shape),
        final=np.array(state, dtype=np.uint8).reshape(shape),
        consensus_trace=np.array(trace),
        elapsed_s=time.perf_counter() - start,
        palette=np.array([g for _, g in palettes]).reshape((*shape, -1)) if palettes else None,
        positions=positions,
    )
