"""--colours K: the swarm shows K colours of its own choosing (docs/algorithm.md §2.7).

The pattern is the paper's, chosen from luminance and formed by the unchanged rule on one
binary layer; colour changes only what a robot shows. Each robot starts consensus with a
256-value vector: the one-hot of its colour's bin (4 x 4 x 4 bins of sRGB) and its colour in
CIELAB times that one-hot. Averaged over the swarm (by the p-vector's Metropolis steps, in the
same messages), the first 64 values are the swarm's colour histogram and the rest the bins'
sums of L*, a* and b*. From it every robot derives the same K-colour palette by a fixed rule,
k-means in CIELAB over the bins' mean colours (kmeans.py), and shows one of the two palette
colours that bracket its own colour in lightness: the nearer darker one where its pattern is
on, the nearer lighter one where it is off (brackets). The pattern stays visible as light and
dark, in the robot's own hues.

CIELAB conversions are scikit-image's, on one robot's colours at a time in every driver (a
conversion of a whole grid goes through a matrix product whose rounding may differ with the
array's size); the palette rule is one compiled function that every driver calls per robot.
So the reference simulator, the per-robot driver and the swarm compute the same bits.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import numpy as np

LEVELS_PER_CHANNEL = 4  # sRGB bins per channel
BIN_WIDTH = 256 // LEVELS_PER_CHANNEL
BINS = LEVELS_PER_CHANNEL**3
SIZE = 4 * BINS  # the averaged vector: the histogram, then the bins' sums of L*, a*, b*
GREY_TOLERANCE = 1e-6  # channels this close are one grey (CIELAB round trips of greys)

RGB = tuple[int, int, int]
Lab = tuple[float, float, float]


def bin_of(rgb: Sequence[float] | np.ndarray) -> int:
    """The histogram bin of an sRGB colour (channels 0..255)."""
    r, g, b = (min(LEVELS_PER_CHANNEL - 1, math.floor(c / BIN_WIDTH)) for c in rgb)
    return (r * LEVELS_PER_CHANNEL + g) * LEVELS_PER_CHANNEL + b


def lab_of(rgb: Sequence[float] | np.ndarray) -> Lab:
    """CIELAB (D65) of one sRGB colour (channels 0..255), by scikit-image, converted alone."""
    from skimage.color import rgb2lab  # only --colours and the colour distance need it

    lab = rgb2lab(np.array([[rgb]], dtype=np.float64) / 255.0)[0, 0]
    return float(lab[0]), float(lab[1]), float(lab[2])


def labs_of(rgb: np.ndarray) -> np.ndarray:
    """lab_of for every robot (... x 3), one robot at a time."""
    flat = np.asarray(rgb, dtype=np.float64).reshape(-1, 3)
    return np.array([lab_of(c) for c in flat]).reshape(np.shape(rgb))


def start_vector(rgb: Sequence[float] | np.ndarray) -> tuple[float, ...]:
    """What a robot averages: the one-hot of its colour's bin, then its L*, a*, b* there."""
    vector = [0.0] * SIZE
    b = bin_of(rgb)
    vector[b] = 1.0
    for channel, value in enumerate(lab_of(rgb)):
        vector[BINS * (1 + channel) + b] = value
    return tuple(vector)


def start_vectors(rgb: np.ndarray) -> np.ndarray:
    """start_vector for every robot (rgb ... x 3 -> ... x SIZE)."""
    flat = np.asarray(rgb, dtype=np.float64).reshape(-1, 3)
    out = np.array([start_vector(c) for c in flat]).reshape(-1, SIZE)
    return out.reshape((*np.shape(rgb)[:-1], SIZE))


# ---- the palette: k-means in CIELAB over the averaged histogram's bins (kmeans.py) ----------


def palette(vector: Sequence[float] | np.ndarray, k: int) -> np.ndarray:
    """kmeans.palette_lab of one robot's vector (any sequence of floats)."""
    from camo_core.algorithm.kmeans import palette_lab  # numba: only --colours needs it

    return palette_lab(np.asarray(vector, dtype=np.float64), k, BINS)


# ---- what a robot shows ---------------------------------------------------------------------


def brackets(own: Sequence[float], palette: np.ndarray) -> tuple[int, int]:
    """(where on, where off): the palette colour nearest the robot's own (CIELAB, squared
    distance) among those no lighter than it, and among those no darker; the darkest and the
    lightest where none is. The first on a tie."""
    darker = lighter = -1
    near_darker = near_lighter = math.inf
    lightness = own[0]
    for index, colour in enumerate(palette.tolist()):
        d0, d1, d2 = own[0] - colour[0], own[1] - colour[1], own[2] - colour[2]
        distance = d0 * d0 + d1 * d1 + d2 * d2
        if colour[0] <= lightness and distance < near_darker:
            darker, near_darker = index, distance
        if colour[0] >= lightness and distance < near_lighter:
            lighter, near_lighter = index, distance
    return (darker if darker >= 0 else 0), (lighter if lighter >= 0 else len(palette) - 1)


def palette_rgb(palette: np.ndarray) -> tuple[RGB, ...]:
    """The palette as the sRGB colours robots show (0..255, halves round up), converted by
    scikit-image one robot's palette at a time; a colour whose channels agree within
    GREY_TOLERANCE (a grey's round trip through CIELAB) is that grey."""
    from skimage.color import lab2rgb

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # out-of-gamut means are clipped, and said to be
        rgb = lab2rgb(np.asarray(palette, dtype=np.float64).reshape(1, -1, 3))[0] * 255.0
    out: list[RGB] = []
    for r, g, b in rgb.tolist():
        if max(r, g, b) - min(r, g, b) < GREY_TOLERANCE:
            r = g = b = (r + g + b) / 3.0
        red, green, blue = (int(min(255, max(0, math.floor(c + 0.5)))) for c in (r, g, b))
        out.append((red, green, blue))
    return tuple(out)


def shown(state: int, shades: Sequence[int], colours: Sequence[Sequence[int]]) -> RGB:
    """The colour a robot shows: its darker bracket where its pattern is on, else its lighter."""
    r, g, b = colours[shades[0] if state == 1 else shades[1]]
    return int(r), int(g), int(b)


def shown_grid(states: np.ndarray, shades: np.ndarray, colours: np.ndarray) -> np.ndarray:
    """shown for every robot: states ..., shades ... x 2, colours ... x K x 3 -> ... x 3."""
    index = np.where(np.asarray(states) == 1, shades[..., 0], shades[..., 1])
    return np.take_along_axis(colours, index[..., None, None], axis=-2)[..., 0, :]


def robot_palette(
    vector: Sequence[float] | np.ndarray, own: Sequence[float] | np.ndarray, k: int
) -> tuple[tuple[RGB, ...], tuple[int, int]]:
    """One robot's palette as it shows it: (its K colours, sRGB, darkest first; its two
    brackets), from its averaged vector and its own colour (sRGB)."""
    lab = palette(vector, k)
    return palette_rgb(lab), brackets(lab_of(own), lab)


def palettes(vectors: np.ndarray, own: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """robot_palette for every robot (vectors ... x SIZE, own ... x 3): colours ... x K x 3
    and shades ... x 2, one robot at a time."""
    shape = vectors.shape[:-1]
    flat_vectors = vectors.reshape(-1, SIZE)
    flat_own = np.asarray(own, dtype=np.float64).reshape(-1, 3)
    colours = np.zeros((len(flat_vectors), k, 3), np.int64)
    shades = np.zeros((len(flat_vectors), 2), np.int64)
    for robot, (vector, rgb) in enumerate(zip(flat_vectors, flat_own, strict=True)):
        colours[robot], shades[robot] = robot_palette(vector, rgb, k)
    return colours.reshape((*shape, k, 3)), shades.reshape((*shape, 2))


def colour_distance(shown: np.ndarray, sensed: np.ndarray) -> float:
    """The mean CIEDE2000 difference (scikit-image's) between the colours robots show and
    those they sensed (sRGB ... x 3, 0..255), over the robots given; `shown` may be n greys
    (each the colour of three equal channels).

    A swarm shows a few palette colours over a few hundred sensed ones, so the difference is
    worked out once for each distinct (sensed, shown) pair and spread back to every robot:
    the same numbers, summed in the same order, as working it out robot by robot."""
    from skimage.color import deltaE_ciede2000, rgb2lab

    shown = np.asarray(shown, dtype=np.float64)
    sensed = np.asarray(sensed, dtype=np.float64).reshape(-1, 3)
    if shown.size == 0:
        return 0.0
    if shown.ndim == 1 and _greys(sensed):  # greys shown, greys sensed: one column each
        pairs = np.stack([sensed[:, 0], shown], axis=1)
        first, each = _distinct_rows(pairs) or (slice(None), slice(None))
        sensed, shown = (np.repeat(pairs[first, None, k, None], 3, axis=-1) for k in (0, 1))
    else:
        shown = shown.reshape(-1, 3) if shown.ndim > 1 else np.repeat(shown[:, None], 3, axis=1)
        pairs = np.concatenate([sensed, shown], axis=1)
        first, each = _distinct_rows(pairs) or (slice(None), slice(None))
        sensed, shown = pairs[first, None, :3], pairs[first, None, 3:]
    differences = deltaE_ciede2000(rgb2lab(sensed / 255.0), rgb2lab(shown / 255.0))[:, 0]
    return float(np.mean(differences[each]))


def _greys(rgb: np.ndarray) -> bool:
    """Every colour (n x 3) a grey: its three channels equal."""
    return bool((rgb[:, 0] == rgb[:, 1]).all() and (rgb[:, 1] == rgb[:, 2]).all())


def _distinct_rows(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """(first, each): the index of one row of every distinct value in `rows` (n x m float64)
    and, for every row, which of them it equals (rows == rows[first][each], bit for bit); None
    where more than half the rows are distinct. Rows are told apart by a 64-bit hash of their
    bits, checked afterwards: if two different rows ever shared a hash, None."""
    bits = np.ascontiguousarray(rows).view(np.uint64)
    key = _row_keys(bits)
    sample = key[:: max(1, len(key) // 4096)]
    if len(np.unique_values(sample)) > len(sample) // 2:
        return None  # mostly distinct (noisy colours): not worth a table
    distinct = np.sort(np.unique_values(key))  # by hashing: no sort of all n keys
    if len(distinct) > len(rows) // 2:
        return None
    each = _index_of(distinct, key)
    first = np.empty(len(distinct), np.intp)
    first[each] = np.arange(len(rows))
    if not np.array_equal(bits[first][each], bits):
        return None
    return first, each


LOOKUP_BITS = 22  # the largest table _index_of builds: 4M entries, 16 MB


def _index_of(distinct: np.ndarray, key: np.ndarray) -> np.ndarray:
    """Where each key (a hash, uniformly spread) is in `distinct` (sorted, holding every key).
    A binary search of each of a million keys takes 50 ms; a table indexed by some of a key's
    bits takes 2, where the distinct keys differ in those bits: tried on three slices of the
    bits, for up to about two thousand distinct keys (nearly always one of them fits)."""
    bits = min(LOOKUP_BITS, 2 * len(distinct).bit_length() + 2)
    if len(distinct) ** 2 < 1 << bits:  # a collision in a slice is unlikely
        mask = np.uint64((1 << bits) - 1)
        for shift in map(np.uint64, (64 - bits, 0, (64 - bits) // 2)):
            slots = (distinct >> shift) & mask
            if len(np.unique_values(slots)) == len(distinct):
                table = np.empty(1 << bits, np.int32)
                table[slots] = np.arange(len(distinct), dtype=np.int32)
                return table[(key >> shift) & mask]
    return np.searchsorted(distinct, key)


def _row_keys(bits: np.ndarray) -> np.ndarray:
    """A 64-bit hash of each row of `bits` (n x m uint64)."""
    key = np.zeros(len(bits), np.uint64)
    for column in bits.T:  # FNV-style: fold in a column, multiply (mod 2^64), mix high bits down
        key ^= column
        key *= np.uint64(0x100000001B3)
        key ^= key >> np.uint64(29)
    return key
