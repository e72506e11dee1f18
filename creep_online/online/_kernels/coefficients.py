"""Numba kernels shared by the online code: the exact model coefficients and the exact state step.

State vector ``psi`` (length P = K + 3), driven by the zero-order-held input:

* ``psi[0:K+1]``: the SOE nodes ``zeta_i`` (``creep_online.online.soe``), alpha-
  and resonance-independent;
* ``psi[K+1], psi[K+2]``: ``x0 = H2 u`` and ``x1 = d/dt H2 u`` with
  ``H2 = 1/(1 + a1 s + a2 s^2)``, discretized exactly (ZOH).

By partial fractions, ``H2 / (s + lam) = A/(s + lam) + (A (a2 lam - a1) - A a2 s) H2``
with ``A = 1/(a2 lam^2 - a1 lam + 1)``, so the model output is *exactly* linear
in psi: ``y_hat = b psi . v(alpha; a1, a2)`` (see ``model_coefficients``). The
tracker (``window.py``) extends psi with the resonance sensitivities; the
drifting test plant (``plant.py``) and the start-up search use these kernels.
``truncated_gl_block`` is the truncated-memory alternative measured in
``bench/bench_online.py`` (it loses creep; the estimator does not use it).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

CACHE = True

@njit(cache=CACHE)
def model_coefficients(alpha: float, lam: np.ndarray, dx: float, a1: float, a2: float,
                       v: np.ndarray, dv: np.ndarray) -> None:
    """v(alpha) and dv/dalpha such that y_hat = b psi . v (unit gain).

    SOE weights w_i = sin(pi a)/pi dx lam_i^(1-a) (integrator and direct term
    from the geometric continuation of the trapezoid sum, see soe.py); their
    alpha derivatives are analytic. In two parts the re-fit runs as separate slices (``node_coefficients``
    over ranges of nodes, then ``coefficient_sums``); here in one call.
    """
    node_coefficients(alpha, lam, dx, a1, a2, v, dv, 0, lam.shape[0])
    coefficient_sums(alpha, lam, dx, a1, a2, v, dv)


@njit(cache=CACHE, inline="always")
def _soe_ends(alpha: float, lam: np.ndarray, dx: float) -> tuple:
    """(s, d ln s/d alpha, the integrator's weight w0 and d ln w0/d alpha, the direct term d and d ln d/d alpha)."""
    q = lam.shape[0]
    s = math.sin(math.pi * alpha) / math.pi
    pc = math.pi * math.cos(math.pi * alpha) / math.sin(math.pi * alpha)  # d ln s / d alpha
    lo = lam[1] * math.exp(-dx)
    hi = lam[q - 1] * math.exp(dx)
    e0 = math.exp(-(1.0 - alpha) * dx)
    w0 = s * dx * lo ** (1.0 - alpha) / (1.0 - e0)
    dlw0 = pc - math.log(lo) + dx * e0 / (1.0 - e0)
    e1 = math.exp(-alpha * dx)
    d = s * dx * hi ** (-alpha) / (1.0 - e1)
    dld = pc - math.log(hi) - dx * e1 / (1.0 - e1)
    return s, pc, w0, dlw0, d, dld


@njit(cache=CACHE)
def node_coefficients(alpha: float, lam: np.ndarray, dx: float, a1: float, a2: float, v: np.ndarray,
                      dv: np.ndarray, i0: int, i1: int) -> None:
    """``model_coefficients``' node entries v[i], dv[i] for nodes i0..i1 (a power each, and a logarithm for dv;
    an empty dv: v alone)."""
    s, pc, w0, dlw0, _, _ = _soe_ends(alpha, lam, dx)
    derivative = dv.shape[0] > 0
    for i in range(i0, i1):
        if i == 0:
            w = w0
            li = 0.0
        else:
            li = lam[i]
            w = s * dx * li ** (1.0 - alpha)
        a = 1.0 / (a2 * li * li - a1 * li + 1.0)
        v[i] = w * a
        if derivative:
            dw = w0 * dlw0 if i == 0 else w * (pc - math.log(li))
            dv[i] = dw * a


@njit(cache=CACHE)
def coefficient_sums(alpha: float, lam: np.ndarray, dx: float, a1: float, a2: float, v: np.ndarray,
                     dv: np.ndarray) -> None:
    """``model_coefficients``' two resonance entries (v[q], v[q + 1] and their derivatives) from the node entries:
    the sums of w_i a_i (a2 lam_i - a1) and of w_i a_i, in node order (an empty dv: v's alone)."""
    q = lam.shape[0]
    _, _, _, _, d, dld = _soe_ends(alpha, lam, dx)
    derivative = dv.shape[0] > 0
    sum_x0 = d
    dsum_x0 = d * dld
    sum_a = 0.0
    dsum_a = 0.0
    for i in range(q):
        li = lam[i] if i > 0 else 0.0
        sum_x0 += v[i] * (a2 * li - a1)
        sum_a += v[i]
        if derivative:
            dsum_x0 += dv[i] * (a2 * li - a1)
            dsum_a += dv[i]
    v[q] = sum_x0
    v[q + 1] = -a2 * sum_a
    if derivative:
        dv[q] = dsum_x0
        dv[q + 1] = -a2 * dsum_a


@njit(cache=CACHE)
def model_values(alpha: float, lam: np.ndarray, dx: float, a1: float, a2: float, v: np.ndarray) -> None:
    """``model_coefficients``' v alone, the same arithmetic operation for operation: without dv/dalpha it
    takes no logarithm per node (the re-fit's trial coefficients, ``window.full_coefficients_into``)."""
    node_coefficients(alpha, lam, dx, a1, a2, v, v[:0], 0, lam.shape[0])     # (an empty dv: no derivative)
    coefficient_sums(alpha, lam, dx, a1, a2, v, v[:0])


@njit(cache=CACHE)
def advance_state(st: np.ndarray, co: np.ndarray, u: float) -> None:
    """One sample of the state: SOE nodes and the resonance pair, exact for a zero-order-held u.

    ``co`` packs the node decays, node gains, then the resonance's 2x2
    transition and 2-vector input (``soe.pack_coefficients``).
    """
    q = st.shape[0] - 2
    for i in range(q):
        st[i] = co[i] * st[i] + co[q + i] * u
    b0 = 2 * q
    x0 = st[q]
    x1 = st[q + 1]
    st[q] = co[b0] * x0 + co[b0 + 1] * x1 + co[b0 + 4] * u
    st[q + 1] = co[b0 + 2] * x0 + co[b0 + 3] * x1 + co[b0 + 5] * u


# --------------------------------------------------------------------------- start-up search
@njit(cache=CACHE)
def node_history(u: np.ndarray, decay: np.ndarray, gain: np.ndarray, zeta: np.ndarray,
                 out: np.ndarray, start: int = 0, stop: int = -1) -> None:
    """out[k] = node states before sample k is applied (then advanced with u[k]), for k from ``start`` to ``stop``
    (-1: the end of u); zeta updated. (A range, not slices: the search calls it from cold Python.)"""
    q = zeta.shape[0]
    for k in range(start, u.shape[0] if stop < 0 else stop):
        for i in range(q):
            out[k, i] = zeta[i]
            zeta[i] = decay[i] * zeta[i] + gain[i] * u[k]


# --------------------------------------------------------------------------- truncated memory (Remark 3 study)
@njit(cache=CACHE)
def truncated_gl_block(u: np.ndarray, ring: np.ndarray, pos: np.ndarray, c: np.ndarray,
                       out: np.ndarray) -> None:
    """Truncated-memory fractional integral with a ring buffer: z[n] = sum_{j=1..L} c_j u[n-j].

    ``c`` are the exact ZOH (Grunwald-Letnikov-type) weights
    (``creep_online.kernels.zoh_integral_weights``), length L+1 with c_0 = 0;
    ``ring`` holds the last L inputs, ``pos[0]`` the slot of the newest.
    O(L) per sample; the tail beyond L samples is dropped.
    """
    length = ring.shape[0]
    for k in range(u.shape[0]):
        acc = 0.0
        j = 1
        idx = pos[0]
        while j <= length:
            acc += c[j] * ring[idx]
            idx -= 1
            if idx < 0:
                idx = length - 1
            j += 1
        out[k] = acc
        p = pos[0] + 1
        if p == length:
            p = 0
        ring[p] = u[k]
        pos[0] = p
