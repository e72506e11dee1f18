"""The special functions and quadrature rules the batch kernels need, in plain Python and numpy.

``identify`` needs the digamma function, 1/Gamma and Gauss-Legendre / Gauss-Jacobi rules at a handful of
scalar points. ``scipy.special`` has them, but importing it is a large share of a cold ``identify``'s
start-up; these few lines cost nothing to load and agree with it to rounding (the tests compare them).
"""
from __future__ import annotations

import math

import numpy as np

#: Below this argument the digamma function is shifted up by its recurrence before the asymptotic series:
#: from here the series' first omitted term is under 1e-15 of the value.
_DIGAMMA_SERIES_FROM = 10.0
#: The asymptotic series' coefficients B_2k / (2k), k = 1..7 (Bernoulli numbers).
_DIGAMMA_SERIES = (1.0 / 12.0, -1.0 / 120.0, 1.0 / 252.0, -1.0 / 240.0, 1.0 / 132.0, -691.0 / 32760.0,
                   1.0 / 12.0)


def digamma(x: float) -> float:
    """psi(x) = d ln Gamma(x) / dx for a real scalar (NaN at the poles x = 0, -1, -2, ...)."""
    x = float(x)
    if x <= 0.0 and x == math.floor(x):
        return math.nan
    if x < 0.5:                            # reflection: psi(1 - x) - psi(x) = pi cot(pi x)
        return digamma(1.0 - x) - math.pi / math.tan(math.pi * x)
    shift = 0.0
    while x < _DIGAMMA_SERIES_FROM:        # recurrence: psi(x) = psi(x + 1) - 1/x
        shift -= 1.0 / x
        x += 1.0
    inv2 = 1.0 / (x * x)
    series, power = 0.0, inv2
    for c in _DIGAMMA_SERIES:
        series += c * power
        power *= inv2
    return shift + math.log(x) - 0.5 / x - series


def rgamma(x: float) -> float:
    """1/Gamma(x) for a real scalar: 0 at the poles of Gamma (x = 0, -1, -2, ...) and where Gamma overflows."""
    x = float(x)
    if x <= 0.0 and x == math.floor(x):
        return 0.0
    try:
        return 1.0 / math.gamma(x)
    except OverflowError:
        return 0.0


def gauss_legendre(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights of the n-point Gauss-Legendre rule on [-1, 1]."""
    return np.polynomial.legendre.leggauss(n)


def gauss_jacobi(n: int, a: float, b: float) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights of the n-point Gauss-Jacobi rule on [-1, 1] for the weight (1 - x)^a (1 + x)^b
    (a, b > -1), by the Golub-Welsch eigenvalue method on the Jacobi polynomials' three-term recurrence."""
    k = np.arange(n, dtype=float)
    s = 2.0 * k + a + b
    with np.errstate(invalid="ignore", divide="ignore"):
        diag = (b * b - a * a) / (s * (s + 2.0))
    if n and abs(a + b) < 1e-300:          # (k = 0 with a + b = 0: the limit of the formula)
        diag[0] = (b - a) / (a + b + 2.0)
    j = k[1:]
    sj = s[1:]
    off = np.sqrt(4.0 * j * (j + a) * (j + b) * (j + a + b) / (sj * sj * (sj + 1.0) * (sj - 1.0)))
    nodes, vectors = np.linalg.eigh(np.diag(diag) + np.diag(off, 1) + np.diag(off, -1))
    mass = 2.0 ** (a + b + 1.0) * math.exp(math.lgamma(a + 1.0) + math.lgamma(b + 1.0) - math.lgamma(a + b + 2.0))
    return nodes, mass * vectors[0] ** 2
