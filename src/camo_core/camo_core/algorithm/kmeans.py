"""A robot's palette from its averaged colour vector: k-means in CIELAB over the histogram's
bins (docs/algorithm.md, colours), compiled by numba; imported only by runs with --colours."""

from __future__ import annotations

import numpy as np

from camo_core.algorithm.jit import njit

LLOYD_ROUNDS = 20  # k-means iterations from each start; a palette settles within a few


@njit(cache=True)
def _distance2(points, i, centres, k):
    d0 = points[i, 0] - centres[k, 0]
    d1 = points[i, 1] - centres[k, 1]
    d2 = points[i, 2] - centres[k, 2]
    return d0 * d0 + d1 * d1 + d2 * d2


@njit(cache=True)
def _nearest(points, i, centres):
    best, chosen = np.inf, 0
    for k in range(centres.shape[0]):
        d = _distance2(points, i, centres, k)
        if d < best:
            best, chosen = d, k
    return chosen, best


@njit(cache=True)
def _start_by_lightness(points, weights, k):
    """Centres at the weighted lightness quantiles (k + 1/2) / K: the bin where the weight,
    summed over the bins in order of lightness, first reaches each."""
    order = np.argsort(points[:, 0], kind="mergesort")
    total = 0.0
    for i in order:
        total = total + weights[i]
    centres = np.empty((k, 3))
    for c in range(k):
        target = (c + 0.5) / k * total
        reached = 0.0
        chosen = order[-1]
        for i in order:
            reached = reached + weights[i]
            if reached >= target:
                chosen = i
                break
        centres[c] = points[chosen]
    return centres


@njit(cache=True)
def _start_far_apart(points, weights, k):
    """Centres far apart: the heaviest bin, then each time the bin whose weight times its
    squared distance to the nearest centre so far is largest (the heaviest again if none)."""
    heaviest = np.argmax(weights)
    centres = np.empty((k, 3))
    centres[0] = points[heaviest]
    for c in range(1, k):
        best, chosen = 0.0, heaviest
        for i in range(points.shape[0]):
            _, d = _nearest(points, i, centres[:c])
            score = weights[i] * d
            if score > best:
                best, chosen = score, i
        centres[c] = points[chosen]
    return centres


@njit(cache=True)
def _lloyd(points, weights, sums, centres):
    """LLOYD_ROUNDS of k-means: each bin to its nearest centre, each centre to the mean colour
    of its bins (their sums over their shares, added in bin order; a centre without bins stays)."""
    k = centres.shape[0]
    for _ in range(LLOYD_ROUNDS):
        share = np.zeros(k)
        total = np.zeros((k, 3))
        for i in range(points.shape[0]):
            c, _ = _nearest(points, i, centres)
            share[c] = share[c] + weights[i]
            for ch in range(3):
                total[c, ch] = total[c, ch] + sums[i, ch]
        for c in range(k):
            if share[c] > 0.0:
                for ch in range(3):
                    centres[c, ch] = total[c, ch] / share[c]
    error = 0.0
    for i in range(points.shape[0]):
        _, d = _nearest(points, i, centres)
        error = error + weights[i] * d
    return centres, error


@njit(cache=True)
def palette_lab(vector, k, bins):
    """The K palette colours (K x 3, CIELAB, darkest first) from one robot's averaged vector
    (the shares of its `bins` colour bins, then their sums of L*, a* and b*):
    k-means over the bins' mean colours weighted by their shares, from two starts (lightness
    quantiles, then bins far apart); the start whose palette leaves the smaller weighted squared
    error is kept, the first on a tie."""
    n = 0
    for b in range(bins):
        if vector[b] > 0.0:
            n += 1
    if n == 0:  # nothing averaged (cannot happen in a run): mid grey
        out = np.zeros((k, 3))
        out[:, 0] = 50.0
        return out
    points = np.empty((n, 3))
    sums = np.empty((n, 3))
    weights = np.empty(n)
    i = 0
    for b in range(bins):
        if vector[b] > 0.0:
            weights[i] = vector[b]
            for ch in range(3):
                sums[i, ch] = vector[bins * (1 + ch) + b]
                points[i, ch] = sums[i, ch] / weights[i]
            i += 1
    first, first_error = _lloyd(points, weights, sums, _start_by_lightness(points, weights, k))
    second, second_error = _lloyd(points, weights, sums, _start_far_apart(points, weights, k))
    chosen = second if second_error < first_error else first
    return chosen[np.argsort(chosen[:, 0], kind="mergesort")].copy()
