"""The counter-based random streams, scalar and vectorised, agree."""

import numpy as np

from camo_core.algorithm import rng


def test_mix_matches_the_published_splitmix64_sequence():
    # SplitMix64 seeded with 0 yields 0xE220A8397B1DCDAF first: mix(0) is that output.
    assert rng.mix(0) == 0xE220A8397B1DCDAF
    assert rng.mix(0x9E3779B97F4A7C15) == 0x6E789E6AA1B965F4


def test_uniform_is_in_unit_interval_and_depends_on_every_argument():
    base = rng.uniform(1, 2, 3, 4, 5)
    assert 0.0 <= base < 1.0
    for changed in [
        (9, 2, 3, 4, 5),
        (1, 9, 3, 4, 5),
        (1, 2, 9, 4, 5),
        (1, 2, 3, 9, 5),
        (1, 2, 3, 4, 9),
    ]:
        assert rng.uniform(*changed) != base


def test_vectorised_uniform_equals_scalar_bit_for_bit():
    generator = np.random.default_rng(0)
    b = generator.integers(0, 2**32, 500, dtype=np.uint64)
    c = generator.integers(0, 2**32, 500, dtype=np.uint64)
    for seed, stream, a in [(0, 1, 0), (2**64 - 1, 3, 34), (12345, 6, 0)]:
        vector = rng.uniform_array(seed, stream, a, b, c)
        scalar = [rng.uniform(seed, stream, a, int(x), int(y)) for x, y in zip(b, c, strict=False)]
        assert vector.tolist() == scalar


def test_loss_rate_follows_rho():
    draws = rng.uniform_array(
        7, rng.STREAM_CONSENSUS, 0, np.arange(20000, dtype=np.uint64), np.uint64(1)
    )
    assert abs(np.mean(draws < 0.2) - 0.2) < 0.02
    assert not rng.lost(7, rng.STREAM_CONSENSUS, 0, 1, 2, 0.0)
