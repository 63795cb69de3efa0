"""What a message must look like before a robot or the monitor uses it. No ROS here.

A robot's neighbours are other processes, possibly on other machines, and any
process in the same domain can publish on a run's topics: every message that
arrives from outside is checked against what the run's parameters allow
(values finite and in range, steps within their phase, a sender that is a
robot of the grid) before it reaches the rules. Each check returns the reason
a message is refused, or None; the transport counts the reasons.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from camo_core.algorithm.modes import modes_of
from camo_core.algorithm.params import CamoParams
from camo_core.swarm.robot_io import (
    CONSENSUS,
    DONE,
    FORMATION,
    NO_PATTERN,
    PHASE_OF,
    SENSING,
    Message,
)
from camo_core.swarm.status_rows import StatusRows

TOLERANCE = 1e-9  # a consensus p sums to 1 up to rounding
REPORT_TOLERANCE = 1e-3  # a Droplet's own firmware prints p with 4 decimals


# |Px| and |Py| are at most 2 x 255 grey levels, and so is their mean; averaging 510s can give
# 510 plus a rounding error.
MAX_ENERGY = 510.0 * (1 + TOLERANCE)


def _finite(value) -> bool:
    return isinstance(value, float | int) and math.isfinite(value)


def _grey(value: float) -> bool:
    return isinstance(value, float | int) and math.isfinite(value) and 0.0 <= value <= 255.0


def probability_vector(p: Sequence[float], tolerance: float = TOLERANCE) -> bool:
    """A p of the paper's rules: finite shares of the pattern table's width summing to 1."""
    return modes_of(CamoParams()).descriptor.p_ok(p, tolerance)


def vote_vector(params: CamoParams, tolerance: float = TOLERANCE):
    """The check of what a run's robots average: p (a probability vector, or with --orientation
    any a structure tensor), followed by its histogram (--levels, --colours); `head_only`: p
    alone (what --scope local's robots average first)."""
    modes = modes_of(params)
    descriptor, histogram, width = modes.descriptor, modes.histogram, modes.descriptor.width

    def whole_ok(p, head_only: bool = False) -> bool:
        if head_only:
            return descriptor.p_ok(p, tolerance)
        return descriptor.p_ok(p[:width], tolerance) and histogram.ok(p[width:], tolerance)

    return whole_ok


def states_of(params: CamoParams) -> range:
    """The values a state can take: 0 and 1, or with --levels K any K - 1 layer bits."""
    return modes_of(params).palette.states


def message_problem(message: Message, params: CamoParams) -> str | None:
    """Why a robot must not use this message, or None."""
    if not 0 <= message.sender < params.count:
        return "sender is not a robot of the grid"
    if message.round < 0:
        return "round out of range"
    check = _KIND_CHECKS.get(message.kind)
    return "unknown kind" if check is None else check(message, params)


def _degree_ok(degree, params: CamoParams) -> bool:
    return 0 <= degree <= modes_of(params).layout.max_degree  # neighbours a degree counts


def _hello_problem(message: Message, params: CamoParams) -> str | None:
    if message.step != 0 or tuple(message.value) != divmod(message.sender, params.cols):
        return "hello from the wrong cell"
    return None


def _color_problem(message: Message, params: CamoParams) -> str | None:
    return "colour out of range" if message.step != 0 or not _grey(message.value) else None


def _energy_problem(message: Message, params: CamoParams) -> str | None:
    energy, degree = message.value
    if not modes_of(params).threshold.averages_energy:
        return "an energy in a run without --threshold auto"
    if not 0 <= message.step < params.consensus_steps:
        return "step out of range"
    if not (_finite(energy) and 0.0 <= energy <= MAX_ENERGY) or not _degree_ok(degree, params):
        return "energy out of range"
    return None


def _vote_problem(message: Message, params: CamoParams) -> str | None:
    p, degree = message.value
    scope = modes_of(params).scope
    if not 0 <= message.step < scope.steps(params):
        return "step out of range"
    if not scope.vote_ok(message.step, p, vote_vector(params)) or not _degree_ok(degree, params):
        return "vote out of range"
    return None


def _state_problem(message: Message, params: CamoParams) -> str | None:
    if not 0 <= message.step < params.formation_steps:
        return "step out of range"
    return "state out of range" if message.value not in states_of(params) else None


def _relay_problem(message: Message, params: CamoParams) -> str | None:
    if not modes_of(params).relays:
        return "a relay in a run without --orientation any on the grid"
    if not 0 <= message.step < params.formation_steps:
        return "step out of range"
    value, states = message.value, states_of(params)
    if len(value) != 8 or any(v is not None and v not in states for v in value):
        return "relay out of range"
    return None


_KIND_CHECKS = {
    "hello": _hello_problem,
    "color": _color_problem,
    "energy": _energy_problem,
    "vote": _vote_problem,
    "state": _state_problem,
    "relay": _relay_problem,
}


def phase_problem(kind: str, phase: int) -> str | None:
    """A message's phase field must be its kind's."""
    return None if PHASE_OF.get(kind) == phase else "phase does not match the kind"


def report_problem(status, params: CamoParams) -> str | None:
    """Why the monitor must not use this status (a RobotStatus or a Report), or None."""
    return rows_problems(StatusRows.from_reports([status], params.cols), params)[0]


def _colours_bad(rows: StatusRows, params: CamoParams) -> np.ndarray:
    """Rows whose colours do not fit the run: a sensed colour that is not one (0..255), a
    palette of other than --colours' K colours, shades that are not two of its indices."""
    palette = modes_of(params).palette
    k = palette.k if palette.colour else 0
    bad = (rows.sensed_rgb_count > 1) | (rows.shades_count > 1)
    bad |= (rows.palette_rgb_count != 0) & (rows.palette_rgb_count != k)
    if len(rows.sensed_rgb):
        with np.errstate(invalid="ignore"):
            rgb = rows.sensed_rgb
            colour = np.isfinite(rgb) & (rgb >= 0) & (rgb <= 255)
        sensed_rows, _ = rows.spans("sensed_rgb")
        bad[sensed_rows[~colour.all(axis=1)]] = True
    if len(rows.shades):
        shade_rows, _ = rows.spans("shades")
        outside = (rows.shades < 0) | (rows.shades >= max(k, 1))
        bad[shade_rows[outside.any(axis=1)]] = True
    return bad


def rows_problems(rows: StatusRows, params: CamoParams) -> list[str | None]:
    """Why the monitor must not use each row of a status table, or None: report_problem's
    checks, a column at a time (a process's array holds thousands)."""
    n = len(rows)
    problems = np.full(n, None, object)
    modes = modes_of(params)
    states, codes, p_rows_ok = (
        modes.palette.states,
        modes.descriptor.codes,
        modes.descriptor.p_rows_ok,
    )
    greys = modes.palette.k if not modes.palette.colour else 0
    bad_state = (rows.state < states.start) | (rows.state >= states.stop)
    bad_pattern = ~np.isin(rows.pattern, [*codes, NO_PATTERN])
    # From the last check to the first: a row gets the first problem report_problem names.
    silent_rows, _ = rows.spans("silent")
    out_of_grid = (rows.silent < 0) | (rows.silent >= params.count)
    problems[np.unique(silent_rows[out_of_grid])] = "status names a robot not of the grid"
    palette_rows, within = rows.spans("palette")
    unsorted = np.zeros(n, bool)
    if len(rows.palette) > 1:
        descending = np.r_[False, rows.palette[1:] < rows.palette[:-1]] & (within > 0)
        unsorted[palette_rows[descending]] = True
    wrong_count = (rows.palette_count != 0) & (rows.palette_count != greys)
    problems[unsorted | wrong_count | _colours_bad(rows, params)] = "status palette out of range"
    trace_bad = rows.ragged.copy()
    p_rows, _ = rows.spans("p_trace")
    if rows.width != modes.descriptor.width:  # p of another width than the run's
        trace_bad[p_rows] = True
    else:
        trace_bad[p_rows[~p_rows_ok(rows.p_trace, REPORT_TOLERANCE)]] = True
    s_rows, _ = rows.spans("state_trace")
    wrong = (rows.state_trace < states.start) | (rows.state_trace >= states.stop)
    trace_bad[s_rows[wrong]] = True
    problems[trace_bad] = "status trace out of range"
    with np.errstate(invalid="ignore"):
        grey = np.isfinite(rows.sensed) & (rows.sensed >= 0) & (rows.sensed <= 255)
    good_p = p_rows_ok(rows.p, REPORT_TOLERANCE) & (rows.width == modes.descriptor.width)
    values_bad = (rows.phase >= CONSENSUS) & (~grey | ~good_p | bad_state | bad_pattern)
    problems[values_bad] = "status values out of range"
    limit = np.where(
        rows.phase == CONSENSUS,
        modes.scope.steps(params),
        np.where(rows.phase == FORMATION, params.formation_steps, np.iinfo(np.int64).max),
    )
    phase_bad = (rows.phase < SENSING) | (rows.phase > DONE) | (rows.step < 0)
    problems[phase_bad | (rows.step > limit)] = "phase or step out of range"
    problems[rows.wrong_cell] = "status from the wrong cell"
    problems[(rows.sender_id < 0) | (rows.sender_id >= params.count)] = (
        "sender is not a robot of the grid"
    )
    return problems.tolist()
