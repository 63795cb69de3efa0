"""What a robot makes of its neighbours' colours: the threshold (fixed or auto) and the
descriptor (the paper's axes vote, or a structure tensor for stripes at any angle).

Each is one object, chosen once from a run's parameters (`modes.modes_of`). A descriptor
describes one robot (Python floats) and the whole grid (NumPy and the compiled kernels) with
the same float64 operations in the same order, says what its robots average (`width` entries of
p), how a robot chooses its pattern from the averaged p, which pattern codes it can choose, and
what a valid p looks like.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from camo_core.algorithm import layout_rules, orientation, rules
from camo_core.algorithm.orientation import CODES, ORIENTED
from camo_core.algorithm.patterns import PATTERN_NAMES, WIDTH

# ---- thresholds ------------------------------------------------------------------------------


class FixedThreshold:
    """The paper's: one threshold T for every robot (--threshold T)."""

    averages_energy = False  # no averaging of texture energy before the vote
    chosen_by = ""  # the options that chose it, beyond the paper's (none)

    def __init__(self, value: float) -> None:
        self.value = value

    def of(self, energy: float) -> float:
        return self.value

    def of_grid(self, energy: np.ndarray) -> float:
        return self.value

    def regulariser(self, energy: float) -> float:
        return orientation.REGULARISER

    def regulariser_grid(self, threshold) -> float:
        return orientation.REGULARISER


class AutoThreshold:
    """--threshold auto: each robot's T from the swarm's mean texture energy, which it averages
    first (docs/algorithm.md, "Threshold auto")."""

    averages_energy = True
    chosen_by = "threshold_auto (--threshold auto)"

    def of(self, energy: float) -> float:
        return rules.auto_threshold(energy)

    def of_grid(self, energy: np.ndarray) -> np.ndarray:
        return np.maximum(rules.MIN_THRESHOLD, rules.THRESHOLD_SHARE * energy)

    def regulariser(self, energy: float) -> float:
        """16 * (T / 5)^2 for the robot's threshold T: the same share of a faint texture's
        tensor is discounted as of a strong one's."""
        scale = rules.auto_threshold(energy) / rules.MIN_THRESHOLD
        return orientation.REGULARISER * scale * scale

    def regulariser_grid(self, threshold: np.ndarray) -> np.ndarray:
        scale = threshold / rules.MIN_THRESHOLD
        return orientation.REGULARISER * scale * scale  # regulariser's order


Threshold = FixedThreshold | AutoThreshold

# ---- descriptors -----------------------------------------------------------------------------


class Axes:
    """The paper's descriptor (docs/algorithm.md §2.2): second differences across x and y
    against the threshold; a one-hot vote for a pattern of the table, averaged as p."""

    name = "axes"
    oriented = False
    width = WIDTH  # p: one entry per pattern
    codes = range(WIDTH)
    colour_slots = 4  # it reads the colours of slots 0-3
    chosen_by = ""

    def __init__(self, threshold: Threshold) -> None:
        self.threshold = threshold

    def describe(self, own: float, received: Sequence[float | None], profile: str, place=None):
        """(scores, tensor, energy) of one robot from its grey and its colour slots' (None:
        none came); the tensor is --orientation any's, `place` a layout's robot's."""
        horizontal, vertical, energy = rules.descriptor(own, received[:4], profile)
        return (horizontal, vertical), None, energy

    def vote(self, scores, tensor, energy: float) -> tuple[int, tuple[float, ...]]:
        """(the robot's vote, the p it starts consensus with)."""
        horizontal, vertical = scores
        vote = rules.vote_from(horizontal, vertical, self.threshold.of(energy))
        return vote, rules.one_hot(vote)

    def vote_all(self, sensed, known_mask, prefix, rho, scores, energy):
        """vote for every robot: (votes, p0), from the grid's scores and energies."""
        horizontal, vertical = scores
        votes = rules.vote_from(horizontal, vertical, self.threshold.of_grid(energy))
        p0 = np.zeros((*sensed.shape, self.width))
        for k in range(self.width):
            p0[:, :, k] = votes == k
        return votes, p0

    def choose(self, p):
        """The pattern (code) a robot chooses from its averaged p (or an array of them)."""
        return rules.select_pattern(p)

    def name_of(self, code: int) -> str:
        return PATTERN_NAMES[code]

    def p_ok(self, p: Sequence[float], tolerance: float) -> bool:
        """A probability vector of the table's width."""
        if len(p) != self.width:
            return False
        return all(math.isfinite(x) and -tolerance <= x <= 1.0 + tolerance for x in p) and (
            abs(sum(p) - 1.0) <= tolerance
        )

    def p_rows_ok(self, p: np.ndarray, tolerance: float) -> np.ndarray:
        """p_ok for each row of p (n x width)."""
        finite = np.isfinite(p).all(axis=1)
        with np.errstate(invalid="ignore"):
            inside = ((p >= -tolerance) & (p <= 1 + tolerance)).all(axis=1)
            return finite & inside & (np.abs(p.sum(axis=1) - 1.0) <= tolerance)


class AnyOrientation(Axes):
    """--orientation any (docs/algorithm.md, "Orientation any"): a structure tensor (Jxx, Jyy,
    Jxy) from slots 0-7's colours, normalised, averaged as p; stripes at multiples of 15
    degrees or mottled chosen from its coherence and direction."""

    name = "any"
    oriented = True
    width = 3  # Jxx, Jyy, Jxy
    codes = range(rules.MOTTLED, CODES)  # mottled and the twelve directions
    colour_slots = 8
    chosen_by = "orientation any (--orientation any)"

    def describe(self, own: float, received: Sequence[float | None], profile: str, place=None):
        scores, _, energy = super().describe(own, received, profile)
        return scores, orientation.raw_tensor(own, received[:8]), energy

    def vote(self, scores, tensor, energy: float) -> tuple[int, tuple[float, ...]]:
        jxx, jyy, jxy = tensor
        p = orientation.normalised(jxx, jyy, jxy, self.threshold.regulariser(energy))
        return orientation.choose(p), p

    def vote_all(self, sensed, known_mask, prefix, rho, scores, energy):
        from camo_core.algorithm import kernels  # numba: for the whole grid's paths only

        shape = sensed.shape
        tensor = np.empty(shape), np.empty(shape), np.empty(shape)
        kernels.tensors_all(sensed, known_mask, prefix, rho, *tensor)
        reg = self.threshold.regulariser_grid(self.threshold.of_grid(energy))
        p0 = np.stack(orientation.normalised(*tensor, reg), axis=-1)
        return orientation.choose(p0), p0

    def choose(self, p):
        return orientation.choose(p)

    def name_of(self, code: int) -> str:
        return orientation.pattern_name(code)

    def p_ok(self, p: Sequence[float], tolerance: float) -> bool:
        """A normalised structure tensor or an average of them: Jxx, Jyy >= 0, Jxx + Jyy < 1
        (the regulariser is positive) and |Jxy| <= (Jxx + Jyy) / 2."""
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

    def p_rows_ok(self, p: np.ndarray, tolerance: float) -> np.ndarray:
        finite = np.isfinite(p).all(axis=1)
        with np.errstate(invalid="ignore"):
            jxx, jyy, jxy = p[:, 0], p[:, 1], p[:, 2]
            trace = jxx + jyy
            ok = (jxx >= -tolerance) & (jyy >= -tolerance) & (trace <= 1 + tolerance)
            return finite & ok & (np.abs(jxy) <= trace / 2 + tolerance)

    @staticmethod
    def angle_of(code: int) -> int | None:
        return orientation.angle_of(code)


class FittedTensor(AnyOrientation):
    """On a --layout (docs/algorithm.md §2.7): a least-squares fit of a structure tensor to the
    squared grey changes towards the near neighbours, at their measured offsets; consensus and
    the choice are --orientation any's."""

    name = "fitted"

    def describe(self, own: float, received: Sequence[float | None], profile: str, place=None):
        """A robot with fewer than three bearings abstains: a zero tensor."""
        offsets = place.offsets[: place.near]
        fitted = layout_rules.fitted_tensor(own, received, offsets)
        energy = layout_rules.texture_energy(own, received, offsets)
        return (0.0, 0.0), fitted or (0.0, 0.0, 0.0), energy

    def vote_all(self, sensed, known_mask, prefix, rho, scores, energy):
        raise NotImplementedError("a layout's robots are simulated one by one (perrobot.py)")


def majority_name(code: int) -> str:
    """How a summary names the pattern most robots chose: the table's name, or "stripes"."""
    return "stripes" if code >= ORIENTED else PATTERN_NAMES[code]


Descriptor = Axes | AnyOrientation | FittedTensor
