"""The rules on a --layout, and the driver that runs them (docs/algorithm.md §2.7).

A robot on a layout has no grid slots: it has neighbours at measured offsets. Its
descriptor is a least-squares fit of a structure tensor to the squared grey changes towards
its near neighbours; consensus and the choice are those of --orientation any; its formation
kernel is built from the offsets of the neighbours within reach, with its own inhibitor
weight, which stands in for the grid's edge mirroring. A lost message counts as off.

A robot's RobotCore calls these (robot.py); on a layout the simulator is the per-robot
driver (perrobot.py), which runs exactly what the robot nodes run.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from camo_core.algorithm import orientation
from camo_core.algorithm.params import CamoParams

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
        r = round(math.hypot(dx, dy), 9)
        if angle is None:
            roles.append(1 if r <= MOTTLED_ACTIVATOR else -1 if r <= MOTTLED_INHIBITOR else 0)
            continue
        c, s = math.cos(math.radians(angle)), math.sin(math.radians(angle))
        along = round(abs(dx * c - dy * s), 9)  # exactly 0.5 or 1.5 stays so (orientation.py)
        across = round(abs(dx * s + dy * c), 9)
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
