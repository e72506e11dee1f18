"""Exact discretization of the resonance 1/(1 + a1 s + a2 s^2) and the exact step response.

Balanced state space: x = [y, y'/wn], x' = A x + B v with wn = 1/sqrt(a2),
A = [[0, wn], [-wn, -a1/a2]], B = [0, wn] (entries of similar size, unlike the
companion form, so the matrix exponential stays cheap and accurate).
Everything the kernels need (transition matrix, input integrals, quadrature
terms) is computed here with numpy/scipy, once per parameter set.
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from . import kernels
from .special import digamma, gauss_jacobi, gauss_legendre

#: Intervals integrated by Gauss quadrature before switching to the Taylor series.
HEAD_INTERVALS = 32
#: Gauss nodes per panel (Jacobi on the singular first panel, Legendre elsewhere).
HEAD_NODES = 16
#: Taylor terms for t^alpha beyond the head: error ~ C(alpha, 8) (1/32)^8 < 1e-14.
TAYLOR_TERMS = 8


def state_matrices(a1: float, a2: float) -> tuple[np.ndarray, np.ndarray]:
    """(A, B) of the resonance in the balanced state x = [y, y'/wn]."""
    wn = 1.0 / math.sqrt(a2)
    a = np.array([[0.0, wn], [-wn, -a1 / a2]])
    b = np.array([0.0, wn])
    return a, b


def resonance_poles(a1: float, a2: float) -> tuple[complex, complex]:
    """(slow, fast) roots of a2 s^2 + a1 s + 1, computed without cancellation."""
    root = np.sqrt(complex(a1 * a1 - 4.0 * a2))
    q = -0.5 * (a1 + root)
    return 1.0 / q, q / a2


def taylor_moments(a1: float, a2: float, h: float, terms: int = TAYLOR_TERMS) -> tuple[np.ndarray, np.ndarray]:
    """(Phi, M) with Phi = e^{A h} and M[m] = int_0^h e^{A(h-s)} B s^m / m! ds.

    One matrix exponential of the resonance augmented with a chain of
    integrators (Van Loan's method), by the compiled ``kernels.expm_small``
    (scipy's expm spent more time in Python than in arithmetic on 10 x 10).
    """
    e = kernels.expm_small(_integrator_chain(a1, a2, terms) * h)
    return np.ascontiguousarray(e[:2, :2]), np.ascontiguousarray(e[:2, 2:].T)


def _integrator_chain(a1: float, a2: float, terms: int) -> np.ndarray:
    """The resonance (A, B) augmented with a chain of ``terms`` integrators (Van Loan's matrix)."""
    a, b = state_matrices(a1, a2)
    size = 2 + terms
    f = np.zeros((size, size))
    f[:2, :2] = a
    f[:2, 2] = b
    for m in range(terms - 1):
        f[2 + m, 3 + m] = 1.0
    return f


@lru_cache(maxsize=64)
def _gauss(n: int, alpha: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Legendre nodes/weights and Jacobi nodes/weights for weight (1+x)^alpha on [-1, 1]."""
    xl, wl = _legendre(n)
    xj, wj = gauss_jacobi(n, 0.0, alpha)
    return xl, wl, xj, wj


@lru_cache(maxsize=8)
def _legendre(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Legendre nodes/weights, remembered apart from ``_gauss``: a fit asks for a new alpha at almost every
    evaluation, and the Legendre rule, which does not depend on it, is three quarters of the rules' time.
    (Shared arrays: the compiled kernels only read them.)"""
    return gauss_legendre(n)


def head_terms(alpha: float, a1: float, a2: float, h: float, n_head: int) -> np.ndarray:
    """int_0^h e^{A(h-s)} B v(k h + s) ds for k < n_head, v(t) = t^alpha / Gamma(1+alpha).

    Gauss quadrature on panels narrow enough for the fastest pole
    (|pole| * panel <= 4); Gauss-Jacobi absorbs the t^alpha singularity on the
    very first panel.
    """
    slow, fast = resonance_poles(a1, a2)
    panels = int(min(64, max(1, math.ceil(abs(fast) * h / 4.0))))
    xl, wl, xj, wj = _gauss(HEAD_NODES, float(alpha))
    return kernels.head_quadrature(alpha, slow, fast, 1.0 / math.sqrt(a2), a1 / a2, h, n_head,
                                   xl, wl, xj, wj, panels, math.gamma(1.0 + alpha))


def step_response_grid(alpha: float, a1: float, a2: float, h: float, n: int) -> np.ndarray:
    """Exact unit-step response S(k h), k = 0..n-1, of 1/(s^alpha (1 + a1 s + a2 s^2)).

    Exact up to quadrature and Taylor truncation (< 1e-13 relative, tested
    against inverse-Laplace references); O(n) with a small constant.
    """
    phi, moments = taylor_moments(a1, a2, h)
    head = head_terms(alpha, a1, a2, h, min(HEAD_INTERVALS, max(n - 1, 0)))
    return kernels.state_march(n, h, alpha, math.gamma(1.0 + alpha), phi, head, moments)


#: Relative step of the central differences of the head terms in a1 and a2 (error ~1e-10 relative).
HEAD_DIFF_STEP = 1e-5


def _augmented(a1: float, a2: float, terms: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(F, dF/da1, dF/da2): the resonance with its integrator chain, as in ``taylor_moments``."""
    f = _integrator_chain(a1, a2, terms)
    size = f.shape[0]
    wn = 1.0 / math.sqrt(a2)
    dwn = -0.5 * wn / a2
    d1 = np.zeros((size, size))
    d1[1, 1] = -1.0 / a2
    d2 = np.zeros((size, size))
    d2[0, 1], d2[1, 0], d2[1, 1], d2[1, 2] = dwn, -dwn, a1 / (a2 * a2), dwn
    return f, d1, d2


def taylor_moments_sensitivity(a1: float, a2: float, h: float,
                               terms: int = TAYLOR_TERMS) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(Phi, M, dPhi, dM): ``taylor_moments`` and their a1, a2 derivatives (leading axis 2).

    Complex step (Al-Mohy and Higham 2010): the derivative of exp(F h) in the
    direction E = dF/da_k is Im exp(F h + i eps E h) / eps, exact to O(eps^2)
    with no cancellation (eps ~1e-20 relative); one 10 x 10 complex
    exponential per direction, all in one compiled call
    (``kernels.expm_directional``), less than half the cost of Van Loan's
    20 x 20 block form.
    """
    f, d1, d2 = _augmented(a1, a2, terms)
    e, de = kernels.expm_directional(f * h, np.stack((d1 * h, d2 * h)))
    phi = np.ascontiguousarray(e[:2, :2])   # = taylor_moments' own, so that S matches the plain march bit for bit
    moments = np.ascontiguousarray(e[:2, 2:].T)
    return phi, moments, np.ascontiguousarray(de[:, :2, :2]), np.ascontiguousarray(de[:, :2, 2:].transpose(0, 2, 1))


def head_sensitivity(alpha: float, a1: float, a2: float, h: float, n_head: int) -> tuple[np.ndarray, np.ndarray]:
    """(head, dhead): ``head_terms`` and their derivatives in (alpha, a1, a2), shape (3, n_head, 2).

    alpha: the integrals of the derivative; a1, a2: central differences at a
    fixed panel count (``kernels.head_sensitivity``).
    """
    slow, fast = resonance_poles(a1, a2)
    panels = int(min(64, max(1, math.ceil(abs(fast) * h / 4.0))))
    xl, wl, xj, wj = _gauss(HEAD_NODES, float(alpha))
    out = kernels.head_sensitivity(alpha, a1, a2, h, n_head, xl, wl, xj, wj, panels, math.gamma(1.0 + alpha),
                                   float(digamma(1.0 + alpha)), HEAD_DIFF_STEP)
    return out[0], out[1:]


def step_response_sensitivity(alpha: float, a1: float, a2: float, h: float, n: int) -> np.ndarray:
    """``step_response_grid`` and its derivatives: rows S, dS/dalpha, dS/da1, dS/da2 at k h (shape (4, n)).

    Forward sensitivities of the exact march (``kernels.state_march_sensitivity``):
    one pass instead of a simulation per parameter for a finite-difference
    Jacobian, and exact up to the head's differences in a1, a2 (~1e-10).
    Row 0 equals ``step_response_grid`` bit for bit.
    """
    phi, moments, dphi, dmoments = taylor_moments_sensitivity(a1, a2, h)
    head, dhead = head_sensitivity(alpha, a1, a2, h, min(HEAD_INTERVALS, max(n - 1, 0)))
    return kernels.state_march_sensitivity(n, h, alpha, math.gamma(1.0 + alpha), float(digamma(1.0 + alpha)),
                                           phi, dphi, head, dhead, moments, dmoments)


def foh_matrices(a1: float, a2: float, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Phi, G0, G1) of the resonance for a piecewise-linear input (first-order hold)."""
    phi, moments = taylor_moments(a1, a2, h, terms=2)
    return phi, moments[0].copy(), moments[1].copy()


def foh_matrices_batch(a1: np.ndarray, a2: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Phi, G0, G1) of ``foh_matrices`` for arrays of (a1, a2) at once, in closed form.

    Phi = e^{A h} by Putzer with the slow pole first; G0 = A^-1 (Phi - I) B and
    G1 = A^-1 (G0 - h B) (integration by parts). Loses ~log10(1/(|pole| h))
    digits to cancellation: meant for starting grids, not for the fit itself.
    """
    a1 = np.asarray(a1, dtype=float)
    a2 = np.asarray(a2, dtype=float)
    wn = 1.0 / np.sqrt(a2)
    root = np.sqrt((a1 * a1 - 4.0 * a2).astype(complex))
    q = -0.5 * (a1 + root)
    l1, l2 = 1.0 / q, q / a2                      # slow, fast
    d = l2 - l1
    x = d * h
    small = np.abs(x) < 1e-4
    ratio = np.where(small, h * (1 + x / 2 + x * x / 6), np.expm1(x) / np.where(small, 1.0, d))
    e1 = np.exp(l1 * h)
    r = e1 * ratio
    n = a1.size
    a = np.zeros((n, 2, 2))
    a[:, 0, 1] = wn
    a[:, 1, 0] = -wn
    a[:, 1, 1] = -a1 / a2
    eye = np.eye(2)[None]
    phi = (e1[:, None, None] * eye + r[:, None, None] * (a - l1[:, None, None] * eye)).real
    b = np.zeros((n, 2))
    b[:, 1] = wn
    inv = np.zeros((n, 2, 2))                     # A^-1 = [[-a1/a2, -wn], [wn, 0]] / wn^2
    inv[:, 0, 0] = -a1 / a2 / wn**2
    inv[:, 0, 1] = -1.0 / wn
    inv[:, 1, 0] = 1.0 / wn
    g0 = np.einsum("nij,nj->ni", inv, np.einsum("nij,nj->ni", phi, b) - b)
    g1 = np.einsum("nij,nj->ni", inv, g0 - h * b)
    return np.ascontiguousarray(phi), np.ascontiguousarray(g0), np.ascontiguousarray(g1)
