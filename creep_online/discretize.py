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
from scipy.linalg import expm
from scipy.special import roots_jacobi, roots_legendre

from . import kernels

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


def _expm1_over(d: complex, tau: np.ndarray) -> np.ndarray:
    """(exp(d tau) - 1) / d, accurate as d tau -> 0 (the limit is tau)."""
    x = d * tau
    small = np.abs(x) < 1e-4
    out = np.empty_like(x, dtype=complex)
    xs = x[small]
    out[small] = tau[small] * (1.0 + xs / 2.0 + xs * xs / 6.0 + xs**3 / 24.0)
    big = ~small
    out[big] = np.expm1(x[big]) / d
    return out


def transition_times_b(a1: float, a2: float, tau: np.ndarray) -> np.ndarray:
    """e^{A tau} B for an array of times tau, shape (len(tau), 2), in closed form.

    Putzer: e^{A tau} = e^{l1 tau} I + r(tau) (A - l1 I) with
    r = (e^{l1 tau} - e^{l2 tau}) / (l1 - l2) = e^{l1 tau} (e^{d tau} - 1) / d,
    d = l2 - l1, l1 the slow pole: stable for repeated, complex and stiff poles.
    """
    tau = np.asarray(tau, dtype=float)
    a, b = state_matrices(a1, a2)
    l1, l2 = resonance_poles(a1, a2)
    e1 = np.exp(l1 * tau)
    r = e1 * _expm1_over(l2 - l1, tau)
    ab = a @ b
    out = np.empty((tau.size, 2))
    out[:, 0] = (e1 * b[0] + r * (ab[0] - l1 * b[0])).real
    out[:, 1] = (e1 * b[1] + r * (ab[1] - l1 * b[1])).real
    return out


def taylor_moments(a1: float, a2: float, h: float, terms: int = TAYLOR_TERMS) -> tuple[np.ndarray, np.ndarray]:
    """(Phi, M) with Phi = e^{A h} and M[m] = int_0^h e^{A(h-s)} B s^m / m! ds.

    One matrix exponential of the resonance augmented with a chain of
    integrators (Van Loan's method).
    """
    a, b = state_matrices(a1, a2)
    size = 2 + terms
    f = np.zeros((size, size))
    f[:2, :2] = a
    f[:2, 2] = b
    for m in range(terms - 1):
        f[2 + m, 3 + m] = 1.0
    e = expm(f * h)
    return np.ascontiguousarray(e[:2, :2]), np.ascontiguousarray(e[:2, 2:].T)


@lru_cache(maxsize=64)
def _gauss(n: int, alpha: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Legendre nodes/weights and Jacobi nodes/weights for weight (1+x)^alpha on [-1, 1]."""
    xl, wl = roots_legendre(n)
    xj, wj = roots_jacobi(n, 0.0, alpha)
    return xl, wl, xj, wj


def head_terms(alpha: float, a1: float, a2: float, h: float, n_head: int) -> np.ndarray:
    """int_0^h e^{A(h-s)} B v(k h + s) ds for k < n_head, v(t) = t^alpha / Gamma(1+alpha).

    Gauss quadrature on panels narrow enough for the fastest pole
    (|pole| * panel <= 4); Gauss-Jacobi absorbs the t^alpha singularity on the
    very first panel.
    """
    gamma1 = math.gamma(1.0 + alpha)
    fastest = max(abs(p) for p in resonance_poles(a1, a2))
    panels = int(min(64, max(1, math.ceil(fastest * h / 4.0))))
    width = h / panels
    xl, wl, xj, wj = _gauss(HEAD_NODES, float(alpha))
    # Legendre nodes in every panel: s in [0, h), weight width/2 * wl
    starts = np.arange(panels) * width
    s_leg = (starts[:, None] + (xl[None, :] + 1.0) * width / 2.0).ravel()
    w_leg = np.tile(wl * width / 2.0, panels)
    e_leg = transition_times_b(a1, a2, h - s_leg) * w_leg[:, None]
    k = np.arange(n_head, dtype=float)[:, None]
    out = (((k * h + s_leg[None, :]) ** alpha) @ e_leg) / gamma1
    # Interval 0, first panel: replace Legendre by Jacobi (weight s^alpha)
    s_jac = (xj + 1.0) * width / 2.0
    e_jac = transition_times_b(a1, a2, h - s_jac)
    first = (wj @ e_jac) * (width / 2.0) ** (1.0 + alpha) / gamma1
    first_leg = ((s_leg[:HEAD_NODES] ** alpha) @ e_leg[:HEAD_NODES]) / gamma1
    out[0] += first - first_leg
    return out


def step_response_grid(alpha: float, a1: float, a2: float, h: float, n: int) -> np.ndarray:
    """Exact unit-step response S(k h), k = 0..n-1, of 1/(s^alpha (1 + a1 s + a2 s^2)).

    Exact up to quadrature and Taylor truncation (< 1e-13 relative, tested
    against inverse-Laplace references); O(n) with a small constant.
    """
    phi, moments = taylor_moments(a1, a2, h)
    head = head_terms(alpha, a1, a2, h, min(HEAD_INTERVALS, max(n - 1, 0)))
    return kernels.state_march(n, h, alpha, math.gamma(1.0 + alpha), phi, head, moments)


def foh_matrices(a1: float, a2: float, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Phi, G0, G1) of the resonance for a piecewise-linear input (first-order hold)."""
    phi, moments = taylor_moments(a1, a2, h, terms=2)
    return phi, moments[0].copy(), moments[1].copy()
