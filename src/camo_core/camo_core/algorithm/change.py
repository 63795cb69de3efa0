"""Continuous camouflage (docs/algorithm.md §6): when a robot decides that the scene it stands on
has changed, and which round that starts.

A watching robot reads its sensor every `sense_period` seconds, between rounds and during them.
A reading is its cell's grey in the newest projected frame, after measurement error drawn anew
for every reading (streams 10 and 11, keyed on the reading's number and the robot: with
probability rho_meas a uniform grey). Each robot judges its own readings only:

- A *window* is its last `change_window` (m) readings. A window is *coherent* when at least
  m - 1 of them lie within half the threshold of the window's median (one wild reading is
  allowed); the median is the window's level.
- The threshold is max(change_threshold, NOISE_FACTOR x sigma), at most MAX_THRESHOLD; sigma is
  the robot's noise: the lower quartile (which readings replaced by noise leave alone) of the
  differences between its readings of successive distinct frames, the last NOISE_DIFFERENCES
  of them within NOISE_HORIZON readings. A frame read again tells nothing of a camera's noise:
  readings of one frame (frames slower than readings, a round's frame read on joining) make no
  difference of their own. With fewer than MIN_DIFFERENCES of them (a still image, whose frames
  are its changes) a robot keeps the sigma it had, 0 at first. A camera whose frames flicker
  raises it; a clean projection leaves it at change_threshold. A robot judges nothing before
  it holds two windows of readings and, if the frames it read differed, a sigma (or
  NOISE_HORIZON readings: frames too few for one are a still image's).
- When a robot joins a round it reads the round's frame a window's worth of times, again while
  those readings are not coherent (SEED_TRIES windows at most); the coherent window's level is
  its *reference*; failing that, the first coherent window of the readings it takes later is.
  (So a scene that changes while a round starts is still a change against the scene the round
  camouflages.) One frame is one draw of a camera's noise, though, and a reference off by it
  would take the frames that follow for a change: the first coherent window of readings of
  later frames that is no change, and tight (m - 1 of its readings within half of
  change_threshold of its median, whatever the noise), is the robot's reference from then on.
- It notices a change when its newest window is coherent and its level differs from the
  reference by more than the threshold. A robot that is in no round yet notices the scene as
  soon as it has a reference.

A noticing robot starts the round named after the newest frame (rounds are named by the
projector's frame numbers, so that robots noticing one change together start the same round,
and a later frame's round supersedes an earlier one). What the rule costs in false alarms and
delays is measured in docs/algorithm.md §6 (`false_alarm_rate` below is the estimate the docs
check against a simulation).

`Watch` applies the rule to all the robots of a process at once (NumPy); `noticed` is the same
rule for one robot's readings, written plainly, which the tests hold the vectorised form to.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from camo_core.algorithm import rng
from camo_core.algorithm.params import CamoParams

NOISE_FACTOR = 6.0  # the threshold is at least this many times the readings' noise
MAX_THRESHOLD = 128.0  # grey levels: beyond this, noise this large hides any scene
SEED_MASK = (1 << 64) - 1


def round_seed(seed: int, round_: int) -> int:
    """The seed round `round_` of a run of `seed` draws from: `./camo sim --seed` with it on
    the round's frame gives the round bit for bit (round 0 keeps the run's seed)."""
    return (seed + round_) & SEED_MASK


@lru_cache(maxsize=16)
def params_of_round(params: CamoParams, round_: int) -> CamoParams:
    """The parameters a robot camouflages with in round `round_` (its seed: `round_seed`);
    shared by every robot of a process."""
    if round_ == 0:
        return params
    return replace(params, seed=round_seed(params.seed, round_))


def threshold(base: float, sigma: np.ndarray | float) -> np.ndarray:
    return np.minimum(np.maximum(base, NOISE_FACTOR * np.asarray(sigma)), MAX_THRESHOLD)


# A robot's noise is estimated from the differences of its readings of successive distinct
# frames: the last NOISE_DIFFERENCES of them, taken within the last NOISE_HORIZON readings (12.8 s
# at the default sense period), once there are MIN_DIFFERENCES (what two windows of 8 readings of
# a camera's frames hold). Fewer frames in the horizon (under 1.2 a second) are as likely a scene's
# changes (a still image's, `--images` in turn) as its noise: the estimate is kept as it was.
NOISE_DIFFERENCES = 64
NOISE_HORIZON = 128
MIN_DIFFERENCES = 15
SEED_TRIES = 8  # windows of its round's frame a robot reads at most for a coherent reference
# sigma from the lower quartile of |differences of successive readings|: a difference of two
# normal readings is normal with sqrt(2) sigma, whose |.| has its lower quartile at 0.3186 x that.
# A reading replaced by noise spoils two differences; the lower quartile stands while fewer
# than three quarters of them are spoilt (the median would fall at a half: often, at 15%).
QUARTILE_TO_SIGMA = 1.0 / (0.31864 * math.sqrt(2.0))


@dataclass(frozen=True)
class Judgement:
    """What a process's robots made of a reading: the robots (indices into the process's list)
    that noticed a change, and for each the frame its new level was first read in."""

    robots: np.ndarray
    changed_frames: np.ndarray


class Watch:
    """The change rule over the robots of one process (indices 0..n-1, robot ids `ids`)."""

    def __init__(
        self, ids: np.ndarray, params: CamoParams, window: int, change_threshold: float
    ) -> None:
        self.ids = np.asarray(ids, dtype=np.int64)
        self.params = params
        self.window = window
        self.base = float(change_threshold)
        n = len(self.ids)
        self.kept = window
        self.readings = np.zeros((n, self.kept))
        self.frames = np.zeros((n, self.kept), np.int64)  # the frame each reading was of
        self.reads = 0  # `read`s so far (every robot reads in each)
        self.since = np.zeros(n, np.int64)  # readings since the robot's last reset
        self.reference = np.full(n, np.nan)  # the reference level (NaN: none yet)
        self.reference_frame = np.full(n, -1, np.int64)  # the round's frame it was read from
        self.settling = np.zeros(n, bool)  # its reference is of one frame (`reset`) as yet
        self.taken = 0  # readings so far: the noise draws' number
        # The noise: |differences| of successive `read`s of distinct frames, a column for each
        # new frame read (every robot reads the same frame), the `read` it came at, and sigma.
        self.differences = np.zeros((n, NOISE_DIFFERENCES))
        self.difference_at = np.full(NOISE_DIFFERENCES, -NOISE_HORIZON - 1, np.int64)
        self._column = 0
        self._last: tuple[int, np.ndarray] | None = None  # the last `read`: frame, values
        self._counted = 0  # differences in the horizon when sigma was last estimated
        self.noise = np.zeros(n)
        # Whether the robots judge yet (`read`): once they have a noise, or their frames are a
        # still image's (none differed in two windows of readings, or too few in the horizon).
        self.ready = False
        self._differed = False

    def reset(self, robots, grid: np.ndarray | None = None, frame: int = -1) -> None:
        """These robots joined a round (or noticed): their reference is to be found anew. With
        `grid`, the round's frame (number `frame`), they read it a window's worth of times
        (each reading with its own measurement error), and a coherent window of those is their
        reference at once: the scene their round camouflages, not what is projected after it."""
        robots = np.asarray(robots, dtype=np.int64)
        self.since[robots] = 0
        self.reference[robots] = np.nan
        self.reference_frame[robots] = frame if grid is not None else -1
        self.settling[robots] = grid is not None
        if grid is None or not len(robots):
            return
        m = self.window
        self.since[robots] = m
        for _ in range(SEED_TRIES):  # a window spoilt by noise is read again
            for _ in range(m):
                values = self.values(grid, robots)
                self.readings[robots, :-1] = self.readings[robots, 1:]
                self.readings[robots, -1] = values
                self.frames[robots, :-1] = self.frames[robots, 1:]
                self.frames[robots, -1] = frame
            recent = self.readings[robots, -m:]
            level = np.median(recent, axis=1)
            limit = threshold(self.base, self.sigma()[robots])
            near = np.abs(recent - level[:, None]) <= limit[:, None] / 2
            coherent = near.sum(axis=1) >= m - 1
            self.reference[robots[coherent]] = level[coherent]
            robots = robots[~coherent]
            if not len(robots):
                break

    def sigma(self) -> np.ndarray:
        """Each robot's noise (0 until it has read MIN_DIFFERENCES + 1 frames in turn)."""
        return self.noise

    def _difference(self, values: np.ndarray, frame: int) -> None:
        """A `read` of frame `frame`: a difference for the noise if the last was of another."""
        last, self._last = self._last, (frame, values)
        new = last is not None and last[0] != frame
        if last is not None and new:
            self.differences[:, self._column] = np.abs(values - last[1])
            self.difference_at[self._column] = self.reads
            self._column = (self._column + 1) % NOISE_DIFFERENCES
        recent = self.difference_at > self.reads - NOISE_HORIZON
        counted = int(recent.sum())
        if counted >= MIN_DIFFERENCES and (new or counted != self._counted):
            quartile = np.quantile(self.differences[:, recent], 0.25, axis=1)
            self.noise = QUARTILE_TO_SIGMA * quartile
            self.ready = True
        self._counted = counted
        self._differed |= new
        if self.reads >= (NOISE_HORIZON if self._differed else 2 * self.window):
            self.ready = True

    def values(self, grid: np.ndarray, robots: np.ndarray | None = None) -> np.ndarray:
        """Every robot's reading of `grid` (rows x cols greys), or these robots' (indices),
        after measurement error."""
        ids = self.ids if robots is None else self.ids[robots]
        values = np.asarray(grid, dtype=np.float64).ravel()[ids]
        rho = self.params.rho_meas
        if rho > 0.0:
            seed = self.params.seed
            replaced = rng.uniform_array(seed, rng.STREAM_READING_REPLACED, self.taken, ids, 0)
            noise = rng.uniform_array(seed, rng.STREAM_READING_VALUE, self.taken, ids, 0)
            values = np.where(replaced < rho, np.floor(256.0 * noise), values)
        self.taken += 1
        return values

    def read(self, grid: np.ndarray, frame: int, idle: np.ndarray | None = None) -> Judgement:
        """A reading of frame `frame` for every robot; `idle` marks robots in no round yet."""
        values = self.values(grid)
        m = self.window
        self.readings[:, :-1] = self.readings[:, 1:]
        self.readings[:, -1] = values
        self.frames[:, :-1] = self.frames[:, 1:]
        self.frames[:, -1] = frame
        self.reads += 1
        self._difference(values, frame)
        self.since = np.minimum(self.since + 1, m)
        limit = threshold(self.base, self.sigma())
        recent = self.readings[:, -m:]
        level = np.median(recent, axis=1)
        near = np.abs(recent - level[:, None]) <= limit[:, None] / 2
        judged = (self.since >= m) & (self.reads >= 2 * m) & self.ready  # a noise too
        coherent = judged & (near.sum(axis=1) >= m - 1)
        unreferenced = np.isnan(self.reference)
        found = coherent & unreferenced
        with np.errstate(invalid="ignore"):  # NaN references compare False
            moved = coherent & ~unreferenced & (np.abs(level - self.reference) > limit)
        noticed = moved | (found & idle) if idle is not None else moved
        self.reference[found] = level[found]
        # A reference read from the round's one frame gives way to the first window of later
        # frames that is no change: several frames' level, steadier than one frame's (a
        # swarm starts a false round if any robot's reference is off). Tight by the base
        # threshold: a noise estimate still inflated by a few replaced readings would let a
        # window of them half through.
        later = (self.frames[:, -m:] > self.reference_frame[:, None]).all(axis=1)
        tight = (np.abs(recent - level[:, None]) <= self.base / 2).sum(axis=1) >= m - 1
        steady = coherent & tight & self.settling & ~moved & later
        self.reference[steady] = level[steady]
        self.settling[steady | found] = False
        robots = np.flatnonzero(noticed)
        # Where the change was first seen: the first reading at the new level of a frame after
        # the reference's (else of the window's last run at its level: a reading replaced by
        # noise can pass for one of the level, at worst a reading early).
        frames = self.frames[robots, self.kept - m :]
        later = near[robots] & (frames > self.reference_frame[robots, None])
        far = ~near[robots]
        last_far = np.where(far.any(axis=1), m - 1 - np.argmax(far[:, ::-1], axis=1), -1)
        start = np.where(last_far < m - 1, last_far + 1, np.argmax(near[robots], axis=1))
        start = np.where(later.any(axis=1), np.argmax(later, axis=1), start)
        changed = frames[np.arange(len(robots)), start]
        return Judgement(robots, changed)


def noticed(
    readings: list[float],
    window: int,
    change_threshold: float,
    idle: bool,
    frames: list[int] | None = None,
) -> int | None:
    """The plain rule for one robot's readings since it joined its round (and no more than
    those), reading k of frame `frames[k]` (by default each of a frame of its own): the index of
    the reading at which it notices a change (or, `idle`, the scene)."""
    frames = list(range(len(readings))) if frames is None else frames
    reference: float | None = None
    sigma, ready = 0.0, False
    differences: list[tuple[int, float]] = []  # (the reading it came at, |difference|)
    for k in range(len(readings)):
        if k and frames[k] != frames[k - 1]:
            differences.append((k, abs(readings[k] - readings[k - 1])))
        kept = [d for at, d in differences[-NOISE_DIFFERENCES:] if at > k - NOISE_HORIZON]
        if len(kept) >= MIN_DIFFERENCES:
            sigma, ready = QUARTILE_TO_SIGMA * float(np.quantile(kept, 0.25)), True
        ready = ready or k + 1 >= (NOISE_HORIZON if differences else 2 * window)
        limit = float(threshold(change_threshold, sigma))
        if k < 2 * window - 1 or not ready:  # a window, and a noise (or a still image)
            continue
        recent = readings[k - window + 1 : k + 1]
        level = float(np.median(recent))
        if sum(abs(x - level) <= limit / 2 for x in recent) < window - 1:
            continue
        if reference is None:
            reference = level
            if idle:
                return k
        elif abs(level - reference) > limit:
            return k
    return None


def false_alarm_rate(rho_meas: float, window: int, change_threshold: float) -> float:
    """An upper estimate of the chance that one reading makes a robot on an unchanged, noise-free
    scene notice a change: at least m - 1 of the window's m readings replaced by noise, and
    those m - 1 within one threshold of each other and away from the scene's grey."""
    band = min(1.0, change_threshold / 256.0)
    k = window - 1
    return math.comb(window, k) * rho_meas**k * band ** (k - 1)
