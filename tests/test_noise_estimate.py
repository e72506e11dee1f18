"""``metrics.noise_std_estimate`` (compiled for finite data) against numpy's MAD of the second differences.

The reference is the plain numpy expression it replaced; both compute the same
per-element differences and exact median selections, so they must agree bit
for bit on odd and even lengths, ties, constant and noisy signals.
"""
import numpy as np
import pytest

from creep_online.metrics import noise_std_estimate


def _reference(y: np.ndarray) -> float:
    d2 = np.diff(y, 2) / np.sqrt(6.0)
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))))


@pytest.mark.parametrize("n", [4, 5, 6, 7, 100, 1001, 12000, 100001])
def test_equals_the_numpy_mad_bit_for_bit(n):
    rng = np.random.default_rng(n)
    for y in (np.cumsum(rng.standard_normal(n)) * 0.01 + rng.standard_normal(n) * 1e-3,
              np.round(rng.standard_normal(n), 1),           # many ties
              np.full(n, 3.0), np.arange(n, dtype=float) ** 2):
        assert noise_std_estimate(y) == _reference(y)


def test_non_finite_and_short_inputs_keep_numpy_semantics():
    y = np.array([0.0, 1.0, np.nan, 2.0, 5.0, 1.0])
    assert np.isnan(noise_std_estimate(y)) and np.isnan(_reference(y))
    assert np.isnan(noise_std_estimate(np.ones(3)))
    assert noise_std_estimate([0.0, 1.0, 4.0, 9.0, 16.0]) == _reference(np.array([0.0, 1.0, 4.0, 9.0, 16.0]))


def test_increments_equal_numpys_diff_with_prepend():
    from creep_online.simulate import increments
    rng = np.random.default_rng(3)
    for u in (rng.standard_normal(1001), np.array([-0.0, 1.0, np.nan, np.inf, 2.0]), np.array([5.0]), np.array([])):
        assert np.array_equal(increments(u), np.diff(u, prepend=0.0), equal_nan=True)
        assert np.array_equal(np.signbit(increments(u)), np.signbit(np.diff(u, prepend=0.0)))
