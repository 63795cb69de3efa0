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

from camo_core.algorithm import colours
from camo_core.algorithm.layout import MAX_SLOTS
from camo_core.algorithm.levels import BIN_WIDTH, BINS
from camo_core.algorithm.orientation import CODES
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.robot_io import (
    CONSENSUS,
    DONE,
    FORMATION,
    NO_PATTERN,
    PHASE_OF,
    SENSING,
    Message,
)
from camo_core.algorithm.rules import MOTTLED
from camo_core.algorithm.status_rows import StatusRows

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
    return len(p) == 3 and shares(p, tolerance)


def shares(p: Sequence[float], tolerance: float = TOLERANCE) -> bool:
    """Finite entries in [0, 1] that sum to 1 (up to `tolerance`)."""
    return all(math.isfinite(x) and -tolerance <= x <= 1.0 + tolerance for x in p) and (
        abs(sum(p) - 1.0) <= tolerance
    )


def tensor_vector(p: Sequence[float], tolerance: float = TOLERANCE) -> bool:
    """A normalised structure tensor (--orientation any) or an average of them: Jxx, Jyy >= 0,
    Jxx + Jyy < 1 (the regulariser is positive) and |Jxy| <= (Jxx + Jyy) / 2."""
    if len(p) != 3 or not all(math.isfinite(x) for x in p):
        return False
    jxx, jyy, jxy = p
    trace = jxx + jyy
    return (
        jxx >= -tolerance
        and jyy >= -tolerance
        and trace <= 1.0 + tolerance
        and (abs(jxy) <= trace / 2 + tolerance)
    )


def histogram_vector(v: Sequence[float], tolerance: float = TOLERANCE) -> bool:
    """--levels' averaged histogram: 16 shares summing to 1, then per bin a sum of greys that
    lies between the bin's least and greatest grey times its share."""
    if len(v) != 2 * BINS or not all(math.isfinite(x) for x in v):
        return False
    histogram, sums = v[:BINS], v[BINS:]
    if not shares(histogram, tolerance):
        return False
    return all(
        BIN_WIDTH * b * h - tolerance * 256 <= s <= 256 * h + tolerance * 256
        for b, (h, s) in enumerate(zip(histogram, sums, strict=True))
    )


MAX_LAB = 128.0  # |a*|, |b*| of sRGB colours stay below it (and L* within 0..100)


def colour_vector(v: Sequence[float], tolerance: float = TOLERANCE) -> bool:
    """--colours' averaged histogram: 64 shares summing to 1, then per bin sums of L*, a* and
    b* within what colours of that share can add up to."""
    if len(v) != colours.SIZE or not all(math.isfinite(x) for x in v):
        return False
    histogram = v[: colours.BINS]
    if not shares(histogram, tolerance):
        return False
    slack = tolerance * 256
    lightness, a, b = (v[colours.BINS * k : colours.BINS * (k + 1)] for k in (1, 2, 3))
    return all(
        -slack <= lightness[k] <= 100.0 * h + slack
        and abs(a[k]) <= MAX_LAB * h + slack
        and abs(b[k]) <= MAX_LAB * h + slack
        for k, h in enumerate(histogram)
    )


def vote_vector(params: CamoParams, tolerance: float = TOLERANCE):
    """The check of what a run's robots average: p, or with --orientation any the tensor; with
    --levels or --colours followed by the histogram."""
    check = tensor_vector if params.orientation_any else probability_vector
    if params.levels:
        return lambda p: check(p[:3], tolerance) and histogram_vector(p[3:], tolerance)
    if params.colours:
        return lambda p: check(p[:3], tolerance) and colour_vector(p[3:], tolerance)
    return lambda p: check(p, tolerance)


def states_of(params: CamoParams) -> range:
    """The values a state can take: 0 and 1, or with --levels K any K - 1 layer bits."""
    return range(2 ** (params.levels - 1)) if params.levels else range(2)


def message_problem(message: Message, params: CamoParams) -> str | None:
    """Why a robot must not use this message, or None."""
    if not 0 <= message.sender < params.count:
        return "sender is not a robot of the grid"
    if message.round < 0:
        return "round out of range"
    check = _KIND_CHECKS.get(message.kind)
    return "unknown kind" if check is None else check(message, params)


def _degree_ok(degree, params: CamoParams) -> bool:
    return 0 <= degree <= (MAX_SLOTS if params.layout else 8)  # neighbours a degree counts


def _hello_problem(message: Message, params: CamoParams) -> str | None:
    if message.step != 0 or tuple(message.value) != divmod(message.sender, params.cols):
        return "hello from the wrong cell"
    return None


def _color_problem(message: Message, params: CamoParams) -> str | None:
    return "colour out of range" if message.step != 0 or not _grey(message.value) else None


def _energy_problem(message: Message, params: CamoParams) -> str | None:
    energy, degree = message.value
    if not params.threshold_auto:
        return "an energy in a run without --threshold auto"
    if not 0 <= message.step < params.consensus_steps:
        return "step out of range"
    if not (_finite(energy) and 0.0 <= energy <= MAX_ENERGY) or not _degree_ok(degree, params):
        return "energy out of range"
    return None


def _vote_problem(message: Message, params: CamoParams) -> str | None:
    p, degree = message.value
    if not 0 <= message.step < params.consensus_steps:
        return "step out of range"
    if not vote_vector(params)(p) or not _degree_ok(degree, params):
        return "vote out of range"
    return None


def _state_problem(message: Message, params: CamoParams) -> str | None:
    if not 0 <= message.step < params.formation_steps:
        return "step out of range"
    return "state out of range" if message.value not in states_of(params) else None


def _relay_problem(message: Message, params: CamoParams) -> str | None:
    if not params.orientation_any or params.layout:
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


def _p_rows_ok(p: np.ndarray, orientation_any: bool) -> np.ndarray:
    """Each row of p (n x 3) a probability vector, or with --orientation any a tensor (the
    row-wise probability_vector and tensor_vector, at REPORT_TOLERANCE)."""
    tol = REPORT_TOLERANCE
    finite = np.isfinite(p).all(axis=1)
    with np.errstate(invalid="ignore"):
        if orientation_any:
            jxx, jyy, jxy = p[:, 0], p[:, 1], p[:, 2]
            trace = jxx + jyy
            ok = (jxx >= -tol) & (jyy >= -tol) & (trace <= 1 + tol)
            return finite & ok & (np.abs(jxy) <= trace / 2 + tol)
        inside = ((p >= -tol) & (p <= 1 + tol)).all(axis=1)
        return finite & inside & (np.abs(p.sum(axis=1) - 1.0) <= tol)


def _colours_bad(rows: StatusRows, params: CamoParams) -> np.ndarray:
    """Rows whose colours do not fit the run: a sensed colour that is not one (0..255), a
    palette of other than --colours' K colours, shades that are not two of its indices."""
    bad = (rows.sensed_rgb_count > 1) | (rows.shades_count > 1)
    bad |= (rows.palette_rgb_count != 0) & (rows.palette_rgb_count != params.colours)
    if len(rows.sensed_rgb):
        with np.errstate(invalid="ignore"):
            rgb = rows.sensed_rgb
            colour = np.isfinite(rgb) & (rgb >= 0) & (rgb <= 255)
        sensed_rows, _ = rows.spans("sensed_rgb")
        bad[sensed_rows[~colour.all(axis=1)]] = True
    if len(rows.shades):
        shade_rows, _ = rows.spans("shades")
        outside = (rows.shades < 0) | (rows.shades >= max(params.colours, 1))
        bad[shade_rows[outside.any(axis=1)]] = True
    return bad


def rows_problems(rows: StatusRows, params: CamoParams) -> list[str | None]:
    """Why the monitor must not use each row of a status table, or None: report_problem's
    checks, a column at a time (a process's array holds thousands)."""
    n = len(rows)
    problems = np.full(n, None, object)
    states = states_of(params)
    codes = range(MOTTLED, CODES) if params.orientation_any else range(MOTTLED + 1)
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
    wrong_count = (rows.palette_count != 0) & (rows.palette_count != params.levels)
    problems[unsorted | wrong_count | _colours_bad(rows, params)] = "status palette out of range"
    trace_bad = rows.ragged.copy()
    p_rows, _ = rows.spans("p_trace")
    trace_bad[p_rows[~_p_rows_ok(rows.p_trace, params.orientation_any)]] = True
    s_rows, _ = rows.spans("state_trace")
    wrong = (rows.state_trace < states.start) | (rows.state_trace >= states.stop)
    trace_bad[s_rows[wrong]] = True
    problems[trace_bad] = "status trace out of range"
    with np.errstate(invalid="ignore"):
        grey = np.isfinite(rows.sensed) & (rows.sensed >= 0) & (rows.sensed <= 255)
    good_p = _p_rows_ok(rows.p, params.orientation_any)
    values_bad = (rows.phase >= CONSENSUS) & (~grey | ~good_p | bad_state | bad_pattern)
    problems[values_bad] = "status values out of range"
    limit = np.where(
        rows.phase == CONSENSUS,
        params.consensus_steps,
        np.where(rows.phase == FORMATION, params.formation_steps, np.iinfo(np.int64).max),
    )
    phase_bad = (rows.phase < SENSING) | (rows.phase > DONE) | (rows.step < 0)
    problems[phase_bad | (rows.step > limit)] = "phase or step out of range"
    problems[rows.wrong_cell] = "status from the wrong cell"
    problems[(rows.sender_id < 0) | (rows.sender_id >= params.count)] = (
        "sender is not a robot of the grid"
    )
    return problems.tolist()
