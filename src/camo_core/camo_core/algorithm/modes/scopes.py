"""How far a robot's evidence reaches: the whole swarm (--scope global, the paper's consensus)
or its own region of the scene (--scope local, docs/algorithm.md §2.9).

--scope local is asymmetry-segmented consensus (ASC). The swarm first agrees, locally, on which
robots belong together, then runs the paper's consensus among those alone, and each robot
chooses as the paper's robots do. All of it is the paper's Metropolis step on vectors of a few
values, in phases of the consensus phase (its messages are votes, a step each):

  A. evidence: n1 = round(L^2) steps on the robot's vote p: its local average e;
  B. class (no message): its texture's imbalance: with the paper's axes a = e_h - e_v, the
     class is h-like if a > KAPPA, v-like if -a > KAPPA, else m-like (scores (a, -a, KAPPA),
     the strictly largest; a tie goes to the last); with --orientation any the scores are
     e's double-angle direction against the twelve stripe directions and ORIENTED_KAPPA for
     "no direction";
  C. clean-up: ROUNDS rounds of n2 = round(1.5 L^2) steps on the one-hot of its class y, each
     ending with the class the strictly largest of y + LAMBDA x scores (islands of another
     class smaller than about L shrink away);
  D. segment consensus: the run's consensus steps on p (and what is averaged with it: the
     --levels and --colours histograms), each robot taking only the neighbours of its own class
     (their messages carry it);
  E. the choice from the averaged p, the paper's.

L is --scope-scale (2 robots by default). Only + - * / and comparisons, in a fixed order: the
robots (Python floats), NumPy and the compiled kernels compute the same bits.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from camo_core.algorithm import orientation, rng, rules
from camo_core.algorithm.params import CamoParams

KAPPA = 0.25  # the imbalance e_h - e_v of stripes, beyond which a robot's texture is striped
ORIENTED_KAPPA = orientation.COHERENCE_MIN  # --orientation any's: coherence of a direction
LAMBDA = 1.0  # how much a robot's own evidence counts against its neighbours' classes
ROUNDS = 6  # clean-up rounds

# A later round of a --scope local run: a robot keeps what it showed if its reading moved by at
# most this (the change rule's own threshold, docs/algorithm.md §6) and it chose as before.
KEEP_GREYS = 24.0

Vector = tuple[float, ...]
Received = Sequence[tuple[Sequence[float], int] | None]


def strict_argmax(values: Sequence[float], tie: int) -> int:
    """The index of the strictly largest value; any tie for the largest goes to `tie`."""
    best = 0
    for k in range(1, len(values)):
        if values[k] > values[best]:
            best = k
    for k, value in enumerate(values):
        if k != best and not values[best] > value:
            return tie
    return best


def strict_argmax_all(values: np.ndarray, tie: int) -> np.ndarray:
    """strict_argmax along the last axis."""
    width = values.shape[-1]
    chosen = np.full(values.shape[:-1], tie, dtype=np.int64)
    for k in range(width):
        largest = np.ones(values.shape[:-1], bool)
        for j in range(width):
            if j != k:
                largest &= values[..., k] > values[..., j]
        chosen = np.where(largest, k, chosen)
    return chosen


class GlobalScope:
    """The paper's: the whole swarm averages p (and what goes with it) for the run's consensus
    steps."""

    name = "global"
    chosen_by = ""

    def steps(self, params: CamoParams) -> int:
        """The vote steps of a round's consensus phase."""
        return params.consensus_steps

    def robot(self, p: Vector, width: int) -> GlobalRobot:
        """One robot's consensus, from the vector it averages (p, `width` wide, and its
        histogram)."""
        return GlobalRobot(p, width)

    def vote_ok(self, step: int, vector: Sequence[float], whole_ok) -> bool:
        """Whether a vote of `step` can be a robot's (`whole_ok`: the check of p and its
        histogram)."""
        return whole_ok(vector)

    def choose(self, descriptor, p):
        """The pattern (code) a robot chooses from its averaged p (or codes, from an array of
        them): the descriptor's choice, the paper's."""
        return descriptor.choose(p)

    def keeps(self, previous, raw) -> bool | np.ndarray:
        """Whether a robot keeps what it showed in its previous round (the paper's swarm
        re-camouflages whole: never)."""
        return False if np.ndim(raw) == 0 else np.zeros(np.shape(raw), bool)

    def run(self, params, p0, width, known_mask, degree, each_step) -> np.ndarray:
        """The whole grid's consensus from p0 (rows x cols x (width + histogram)); each_step(k,
        reported) is told the p each robot reports after step k. The averaged vectors."""
        from camo_core.algorithm import kernels  # numba: for the whole grid's paths only

        p = p0
        nxt = np.empty_like(p)
        step_kernel = kernels.consensus_step if p.shape[-1] == 3 else kernels.consensus_step_n
        for step in range(params.consensus_steps):
            prefix = np.uint64(rng.prefix(params.seed, rng.STREAM_CONSENSUS, step))
            step_kernel(p, nxt, known_mask, degree, prefix, params.rho_comm)
            p, nxt = nxt, p
            each_step(step, p[..., :width])
        return p


class GlobalRobot:
    """A robot's consensus in the paper's scope: the Metropolis step on its whole vector."""

    __slots__ = ("vector", "width")

    def __init__(self, p: Vector, width: int) -> None:
        self.vector = p  # what it sends for its next step (here: what it averages)
        self.width = width

    @property
    def reported(self) -> Vector:
        """The p it reports (its p, or tensor: without the histogram)."""
        return self.vector[: self.width]

    def step(self, step: int, degree: int, received: Received) -> Vector:
        self.vector = rules.consensus_step(self.vector, degree, received)
        return self.vector

    def result(self) -> Vector:
        """What it chooses its pattern (and palette) from."""
        return self.vector


class LocalScope:
    """--scope local (module docstring): ASC with length scale L."""

    name = "local"
    chosen_by = "scope local (--scope local)"

    def __init__(self, scale: float, oriented: bool) -> None:
        self.scale = scale
        self.evidence = max(1, math.floor(scale * scale + 0.5))  # n1
        self.cleanup = max(1, math.floor(1.5 * scale * scale + 0.5))  # n2
        self.oriented = oriented
        # Classes: h-like, v-like, m-like; or the twelve stripe directions and none.
        self.classes = orientation.ANGLES + 1 if oriented else 3
        self.segmented = self.evidence + ROUNDS * self.cleanup  # steps before phase D

    def steps(self, params: CamoParams) -> int:
        return self.segmented + params.consensus_steps

    def robot(self, p: Vector, width: int) -> LocalRobot:
        return LocalRobot(self, p, width)

    def phase_of(self, step: int) -> str:
        """Which phase a vote of `step` belongs to: "evidence", "cleanup" or "segment"."""
        if step < self.evidence:
            return "evidence"
        return "cleanup" if step < self.segmented else "segment"

    def vote_ok(self, step: int, vector: Sequence[float], whole_ok) -> bool:
        phase = self.phase_of(step)
        if phase == "segment":
            label = vector[-1] if vector else -1.0
            return label in range(self.classes) and whole_ok(vector[:-1])
        if phase == "cleanup":  # an average of one-hots: shares summing to 1
            return len(vector) == self.classes and _shares(vector)
        return whole_ok(vector, head_only=True)

    def choose(self, descriptor, p):
        """The paper's choice from the segment's averaged p, but for one thing: a segment
        whose robots mostly vote mottled while its striped ones lean one way, by more than
        KAPPA (|p_h - p_v| > KAPPA), draws those stripes. The paper's descriptor votes mottled
        where it sees no texture at all, and a region of faint or wide stripes has as many such
        robots (on the stripes' flanks and crests) as it has robots that see the stripes:
        their imbalance is what says the region is striped (docs/algorithm.md §2.9). With
        --orientation any the choice is the descriptor's (its coherence says as much)."""
        chosen = descriptor.choose(p)
        if self.oriented:
            return chosen
        a = np.asarray(p, dtype=np.float64)
        imbalance = a[..., 0] - a[..., 1]
        striped = np.where(
            imbalance > KAPPA, rules.HORIZONTAL, np.where(-imbalance > KAPPA, rules.VERTICAL, -1)
        )
        chosen = np.where((chosen == rules.MOTTLED) & (striped >= 0), striped, chosen)
        return int(chosen) if chosen.ndim == 0 else chosen

    def keeps(self, previous, raw) -> bool | np.ndarray:
        """A later round (`previous`: the robot's last finished round, or the grid's: its raw
        reading, pattern code, final state and palette): a robot whose reading moved by at most
        KEEP_GREYS keeps its camouflage (its pattern, state and palette), whatever its votes
        say this round: its scene did not change. A change confined to one region
        re-camouflages that region; elsewhere robots keep their display (a robot next to the
        change forms against its kept neighbours). One robot (scalars) or the grid (arrays)
        alike."""
        if previous is None:
            return False if np.ndim(raw) == 0 else np.zeros(np.shape(raw), bool)
        same = np.abs(np.asarray(raw) - previous.raw) <= KEEP_GREYS
        return bool(same) if np.ndim(same) == 0 else same

    # ---- phase B and C's arithmetic, one robot and the grid alike -----------------------------

    def scores(self, e: Sequence[float]) -> Vector:
        """A robot's class scores from its evidence (its averaged p, or tensor)."""
        if not self.oriented:
            a = e[0] - e[1]
            return a, -a, KAPPA
        x, y = e[0] - e[1], 2.0 * e[2]
        directions = orientation.DIRECTIONS
        return (*(x * c + y * s for c, s in directions), ORIENTED_KAPPA)

    def scores_all(self, e: np.ndarray) -> np.ndarray:
        if not self.oriented:
            a = e[..., 0] - e[..., 1]
            return np.stack([a, -a, np.full(a.shape, KAPPA)], axis=-1)
        x, y = e[..., 0] - e[..., 1], 2.0 * e[..., 2]
        directions = orientation.DIRECTIONS
        each = [x * c + y * s for c, s in directions]
        return np.stack([*each, np.full(x.shape, ORIENTED_KAPPA)], axis=-1)

    def run(self, params, p0, width, known_mask, degree, each_step) -> np.ndarray:
        """ASC for the whole grid (module docstring), with the robots' arithmetic. What robots
        report after each step: their evidence as it is averaged (phase A), then as it stands
        (C), and from the end of C, when their segment's consensus begins, their p."""
        seed, rho = params.seed, params.rho_comm
        shown: list[np.ndarray] = []  # what robots report while they do not average p

        from camo_core.algorithm import kernels  # numba: for the whole grid's paths only

        def averaged(x: np.ndarray, first: int, steps: int, gate=None) -> np.ndarray:
            nxt = np.empty_like(x)
            for k in range(first, first + steps):
                prefix = np.uint64(rng.prefix(seed, rng.STREAM_CONSENSUS, k))
                if gate is not None:
                    kernels.consensus_step_gated(x, nxt, known_mask, degree, prefix, rho, gate)
                elif x.shape[-1] == 3:
                    kernels.consensus_step(x, nxt, known_mask, degree, prefix, rho)
                else:
                    kernels.consensus_step_n(x, nxt, known_mask, degree, prefix, rho)
                x, nxt = nxt, x
                if k == self.segmented - 1:
                    shown[:] = [p0[..., :width]]  # segmented: p from now on
                each_step(k, shown[0] if shown else x[..., :width])
            return x

        e = averaged(p0[..., :width].copy(), 0, self.evidence)  # p0 is D's start: kept
        shown.append(e)
        scores = self.scores_all(e)
        tie = self.classes - 1
        label = strict_argmax_all(scores, tie)
        eye = np.eye(self.classes)
        for r in range(ROUNDS):
            y = averaged(eye[label], self.evidence + r * self.cleanup, self.cleanup)
            label = strict_argmax_all(y + LAMBDA * scores, tie)
        shown.clear()
        return averaged(p0.copy(), self.segmented, params.consensus_steps, label)


def _shares(values: Sequence[float], tolerance: float = 1e-9) -> bool:
    return all(math.isfinite(v) and -tolerance <= v <= 1 + tolerance for v in values) and (
        abs(sum(values) - 1.0) <= tolerance
    )


class LocalRobot:
    """A robot's consensus in --scope local: its phases (module docstring), by step."""

    __slots__ = ("e", "label", "p0", "scope", "scores", "vector", "width", "x", "y")

    def __init__(self, scope: LocalScope, p: Vector, width: int) -> None:
        self.scope, self.p0, self.width = scope, p, width
        self.e = p[:width]  # phase A's evidence
        self.scores: Vector = ()
        self.label = -1
        self.y: Vector = ()
        self.x: Vector = ()
        self.vector = self.e  # what it sends for its next step

    @property
    def reported(self) -> Vector:
        """Its evidence until its segment is known (the end of phase C), then its p (or
        tensor)."""
        return self.x[: self.width] if self.x else self.e

    def step(self, step: int, degree: int, received: Received) -> Vector:
        scope = self.scope
        if step < scope.evidence:
            self.e = rules.consensus_step(self.e, degree, received)
            self.vector = self.e
            if step == scope.evidence - 1:
                self.scores = scope.scores(self.e)
                self.label = strict_argmax(self.scores, scope.classes - 1)
                self.vector = self.y = self._one_hot()
        elif step < scope.segmented:
            self.y = rules.consensus_step(self.y, degree, received)
            self.vector = self.y
            if (step - scope.evidence) % scope.cleanup == scope.cleanup - 1:
                total = tuple(y + LAMBDA * s for y, s in zip(self.y, self.scores, strict=True))
                self.label = strict_argmax(total, scope.classes - 1)
                if step == scope.segmented - 1:  # the segment's consensus next, from p
                    self.x = self.p0
                    self.vector = (*self.x, float(self.label))
                else:
                    self.vector = self.y = self._one_hot()
        else:
            label = float(self.label)
            own = [None if m is None or m[0][-1] != label else (m[0][:-1], m[1]) for m in received]
            self.x = rules.consensus_step(self.x, degree, own)
            self.vector = (*self.x, label)
        return self.vector

    def _one_hot(self) -> Vector:
        y = [0.0] * self.scope.classes
        y[self.label] = 1.0
        return tuple(y)

    def result(self) -> Vector:
        return self.x if self.x else self.p0


@dataclass(frozen=True)
class Previous:
    """What a robot did in its last finished round (arrays: the grid's): its raw reading (grey,
    before measurement noise), its pattern code, its final state and its palette (a
    palettes.RobotPalette; the grid's a GridPalette)."""

    raw: Any
    pattern: Any
    final: Any
    palette: Any


Scope = GlobalScope | LocalScope
