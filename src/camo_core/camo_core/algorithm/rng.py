"""docs/algorithm.md §3: counter-based randomness, a pure function of (seed, stream, a, b, c).

Every random event of a run (a lost message, a noisy sensor) is drawn from
these, so the distributed swarm and the reference simulator agree bit for bit
whatever order messages arrive in. Scalar functions use Python integers; the
vectorised ones use NumPy uint64, whose arithmetic wraps like the mask does.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

MASK = (1 << 64) - 1

STREAM_HELLO = 1
STREAM_COLOR = 2
STREAM_CONSENSUS = 3
STREAM_STATE = 4
STREAM_SENSOR_REPLACED = 5
STREAM_SENSOR_VALUE = 6
STREAM_ENERGY = 7  # --threshold auto's consensus on texture energy
STREAM_RELAY = 8  # --orientation any's relayed states
STREAM_JITTER = 9  # --layout jitter:A's shifts (camo_core.algorithm.layout)
STREAM_READING_REPLACED = 10  # continuous camouflage: a watching robot's reading replaced by noise
STREAM_READING_VALUE = 11  # ... and the noise value

GOLDEN = 0x9E3779B97F4A7C15
M1 = 0xBF58476D1CE4E5B9
M2 = 0x94D049BB133111EB
INV_2_53 = 1.0 / float(1 << 53)


def mix(x: int) -> int:
    """SplitMix64 finaliser on a Python int."""
    x = (x + GOLDEN) & MASK
    x = ((x ^ (x >> 30)) * M1) & MASK
    x = ((x ^ (x >> 27)) * M2) & MASK
    return x ^ (x >> 31)


def prefix(seed: int, stream: int, a: int) -> int:
    """The part of the hash that depends on (seed, stream, a) only."""
    return mix(mix(mix(seed & MASK) ^ stream) ^ (a & MASK))


def uniform(seed: int, stream: int, a: int, b: int, c: int) -> float:
    """A float in [0, 1)."""
    return (mix(mix(prefix(seed, stream, a) ^ b) ^ c) >> 11) * INV_2_53


def lost(seed: int, stream: int, step: int, src: int, dst: int, rho_comm: float) -> bool:
    """Is the message of `stream` from `src` to `dst` at `step` lost?"""
    return rho_comm > 0.0 and uniform(seed, stream, step, src, dst) < rho_comm


# ---- vectorised (NumPy uint64; wrapping arithmetic is the mask) -------------

_GOLDEN_U = np.uint64(GOLDEN)
_M1_U = np.uint64(M1)
_M2_U = np.uint64(M2)
_S30, _S27, _S31, _S11 = (np.uint64(s) for s in (30, 27, 31, 11))


def mix_array(x: np.ndarray) -> np.ndarray:
    """SplitMix64 finaliser on a uint64 array (returns a new array)."""
    x = x + _GOLDEN_U
    x ^= x >> _S30
    x *= _M1_U
    x ^= x >> _S27
    x *= _M2_U
    x ^= x >> _S31
    return x


def uniform_array(
    seed: int, stream: int, a: int, b: npt.ArrayLike, c: npt.ArrayLike
) -> np.ndarray:
    """`uniform` over broadcast arrays of b and c."""
    h = mix_array(np.asarray(b, dtype=np.uint64) ^ np.uint64(prefix(seed, stream, a)))
    return to_unit(mix_array(h ^ np.asarray(c, dtype=np.uint64)))


def sender_hash(seed: int, stream: int, a: int, src: np.ndarray) -> np.ndarray:
    """mix(prefix ^ src): the sender half of the hash, shared by all its receivers."""
    return mix_array(np.asarray(src, dtype=np.uint64) ^ np.uint64(prefix(seed, stream, a)))


def to_unit(h: np.ndarray) -> np.ndarray:
    """Final hash to a float64 in [0, 1)."""
    return (h >> _S11).astype(np.float64) * INV_2_53
