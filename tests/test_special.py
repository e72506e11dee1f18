"""The batch kernels' special functions and quadrature rules against scipy.special (an independent
implementation: series, recurrences and Newton-polished roots)."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.special as sc

from creep_online.special import digamma, gauss_jacobi, gauss_legendre, rgamma

# arguments the kernels meet (1 + alpha - k for alpha in (0, 1), k = 0, 1, 2, ...) and a wide spread around them
POINTS = np.concatenate([np.linspace(-6.95, 15.05, 881), [1e-6, 1e-3, 0.5, 1.0, 2.0, 9.999, 10.0, 47.3, 1e3, 1e6]])
POINTS = POINTS[(POINTS > 0) | (np.abs(POINTS - np.round(POINTS)) > 1e-6)]     # (the poles apart)


@pytest.mark.parametrize("x", POINTS[::40].tolist() + [-0.3, -1.5, 0.01])
def test_digamma_matches_scipy(x):
    assert digamma(x) == pytest.approx(sc.digamma(x), rel=1e-13, abs=1e-13)


def test_digamma_and_rgamma_at_every_point_and_at_the_poles():
    for x in POINTS:
        assert digamma(x) == pytest.approx(sc.digamma(x), rel=1e-13, abs=1e-13)
        assert rgamma(x) == pytest.approx(sc.rgamma(x), rel=1e-14, abs=1e-300)
    for pole in (0.0, -1.0, -4.0):
        assert np.isnan(digamma(pole)) and rgamma(pole) == 0.0
    assert rgamma(400.0) == 0.0                                   # Gamma overflows: 1/Gamma underflows


@pytest.mark.parametrize("n", [1, 2, 5, 16, 30])
@pytest.mark.parametrize("b", [0.0, 0.01, 0.3, 0.999, 1.7])
def test_gauss_jacobi_matches_scipy(n, b):
    x, w = gauss_jacobi(n, 0.0, b)
    xr, wr = sc.roots_jacobi(n, 0.0, b)
    np.testing.assert_allclose(x, xr, rtol=0, atol=1e-13)
    np.testing.assert_allclose(w, wr, rtol=1e-11)


def _jacobi_moment(a: float, b: float, degree: int) -> float:
    """int_-1^1 (1 - x)^a (1 + x)^b x^degree dx in closed form: x^d = sum_j C(d, j) (1 + x)^j (-1)^(d - j), and
    int (1 - x)^a (1 + x)^c dx = 2^(a + c + 1) B(a + 1, c + 1). (An alternating sum: it loses ~d bits, so the
    check below stays at low degrees; the rule against scipy's covers the larger n.)"""
    return sum(sc.comb(degree, j) * (-1) ** (degree - j) * 2 ** (a + b + j + 1) * sc.beta(a + 1, b + j + 1)
               for j in range(degree + 1))


def test_gauss_jacobi_integrates_the_weighted_polynomials_exactly():
    """An n-point rule is exact for polynomials of degree up to 2n - 1 against (1 - x)^a (1 + x)^b."""
    for a, b, n in ((0.0, 0.3, 6), (0.4, 0.25, 5), (0.0, 0.01, 4), (0.0, 0.999, 3)):
        x, w = gauss_jacobi(n, a, b)
        for degree in range(2 * n):
            assert np.sum(w * x**degree) == pytest.approx(_jacobi_moment(a, b, degree), rel=1e-9, abs=1e-10)
        assert np.sum(w * x ** (2 * n)) != pytest.approx(_jacobi_moment(a, b, 2 * n), rel=1e-9, abs=1e-10)


@pytest.mark.parametrize("n", [1, 3, 16])
def test_gauss_legendre_matches_scipy(n):
    x, w = gauss_legendre(n)
    xr, wr = sc.roots_legendre(n)
    np.testing.assert_allclose(x, xr, atol=1e-15)
    np.testing.assert_allclose(w, wr, rtol=1e-13)
