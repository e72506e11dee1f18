"""``kernels.expm_small`` (the compiled matrix exponential behind ``taylor_moments``) against scipy.linalg.expm.

scipy's expm (Pade 13, scaling and squaring) is the independent reference; the
two agree to rounding: the largest difference on these matrices is ~2e-13 of
the largest entry, and it is scipy's (an extended-precision Taylor reference
puts expm_small within 5e-15), so 1e-12 is the bound. The complex-step
derivatives of (Phi, M) are compared with the same complex step taken through
scipy's expm (the previous implementation) to 1e-10 of their peak.
"""
import math

import numpy as np
import pytest
from scipy.linalg import expm

from creep_online import kernels
from creep_online.discretize import _augmented, _integrator_chain, taylor_moments_sensitivity

#: (fn_hz, zeta, h): slow and fast, light and heavy damping, |A h| from ~1e-4 to ~100 (many squarings).
CASES = [(6.0, 0.12, 0.005), (350.0, 0.08, 1e-4), (100.0, 0.01, 1e-3), (10.0, 1.5, 1e-3),
         (2000.0, 0.3, 1e-3), (400.0, 3.0, 1e-3), (1.0, 0.02, 1e-5), (5000.0, 2.0, 1e-2)]


def _resonance(fn: float, zeta: float) -> tuple[float, float]:
    wn = 2 * math.pi * fn
    return 2 * zeta / wn, 1 / wn**2


def _relative(a: np.ndarray, ref: np.ndarray) -> float:
    return float(np.max(np.abs(a - ref)) / np.max(np.abs(ref)))


@pytest.mark.parametrize("fn, zeta, h", CASES)
def test_expm_small_matches_scipy_on_the_augmented_resonance(fn, zeta, h):
    f = _integrator_chain(*_resonance(fn, zeta), 8) * h
    assert _relative(kernels.expm_small(f), expm(f)) < 1e-12


def test_expm_small_matches_scipy_on_random_and_complex_matrices():
    rng = np.random.default_rng(3)
    for size in (1, 2, 4, 10):
        for scale in (1e-3, 0.4, 3.0, 40.0):
            x = rng.standard_normal((size, size)) * scale
            assert _relative(kernels.expm_small(x), expm(x)) < 1e-12, (size, scale)
            z = x + 1j * rng.standard_normal((size, size)) * scale
            assert _relative(kernels.expm_small(z), expm(z)) < 1e-12, (size, scale)
    assert np.array_equal(kernels.expm_small(np.zeros((3, 3))), np.eye(3))


@pytest.mark.parametrize("fn, zeta, h", CASES)
def test_taylor_moment_derivatives_match_the_complex_step_through_scipy(fn, zeta, h):
    a1, a2 = _resonance(fn, zeta)
    _, _, dphi, dm = taylor_moments_sensitivity(a1, a2, h)
    f, *dfs = _augmented(a1, a2, 8)
    for k, df in enumerate(dfs):
        eps = 1e-20 * np.max(np.abs(f)) / np.max(np.abs(df))
        e = expm(f * h + 1j * eps * (df * h)).imag / eps
        assert _relative(dphi[k], e[:2, :2]) < 1e-10, k
        assert _relative(dm[k], e[:2, 2:].T) < 1e-10, k


def test_expm_directional_is_expm_small_and_its_complex_step_bit_for_bit():
    """The directional kernel's exponential is ``expm_small``'s, and each derivative is the complex step
    through ``expm_small`` itself (Im e^(x + i eps E) / eps), to the last bit, on random and resonance matrices."""
    rng = np.random.default_rng(11)
    cases = [rng.standard_normal((size, size)) * scale for size in (2, 4, 10) for scale in (1e-3, 0.4, 40.0)]
    cases += [_integrator_chain(*_resonance(fn, zeta), 8) * h for fn, zeta, h in CASES]
    for x in cases:
        directions = rng.standard_normal((3, *x.shape))
        e, d = kernels.expm_directional(x, directions)
        assert np.array_equal(e, kernels.expm_small(x))
        size = max(np.max(np.abs(x)), 1e-300)
        for k, direction in enumerate(directions):
            eps = 1e-20 * size / max(np.max(np.abs(direction)), 1e-300)
            assert np.array_equal(d[k], kernels.expm_small(x + 1j * eps * direction).imag / eps), k
