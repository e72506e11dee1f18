"""A plant whose creep exponent and gain drift: test bench for tracking (docs/online.md).

``simulate_varying`` streams the input through the SOE state vector (exact for
a zero-order-held input, see ``kernels``) and, at every sample, reads the
output with that sample's parameters: ``y[n] = b[n] psi[n] . v(alpha[n])``.
This is the "frozen-time" time-varying model: at each instant the plant is the
creep model with the current parameters applied to the whole input history.
With constant parameters it equals ``creep_online.simulate.simulate``
(tested to < 1e-5 of the output range in tests/test_online_kernels.py).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from creep_online.online import kernels as K
from creep_online.online.soe import SOE_TOP, SoeBasis, pack_coefficients
from creep_online.simulate import uniform_step


@njit(cache=True)
def _varying(u: np.ndarray, alpha: np.ndarray, b: np.ndarray, st: np.ndarray, co: np.ndarray,
             lam: np.ndarray, dx: float, a1: float, a2: float) -> np.ndarray:
    n = u.shape[0]
    p = st.shape[0]
    v = np.empty(p)
    dv = np.empty(p)
    y = np.empty(n)
    last = -1.0
    for k in range(n):
        if alpha[k] != last:
            K.model_coefficients(alpha[k], lam, dx, a1, a2, v, dv)
            last = alpha[k]
        acc = 0.0
        for i in range(p):
            acc += st[i] * v[i]
        y[k] = b[k] * acc
        K.advance_state(st, co, u[k])
    return y


def simulate_varying(t: np.ndarray, u: np.ndarray, alpha: np.ndarray | float, a1: float, a2: float,
                     b: np.ndarray | float, horizon_s: float | None = None) -> np.ndarray:
    """Output of the creep model with per-sample alpha[n] and b[n] (zero initial state, ZOH input)."""
    h = uniform_step(t)
    u = np.ascontiguousarray(u, dtype=float)
    alpha = np.broadcast_to(np.asarray(alpha, dtype=float), u.shape).copy()
    b = np.broadcast_to(np.asarray(b, dtype=float), u.shape).copy()
    span = max(float(t[-1] - t[0]), 10 * h)
    basis = SoeBasis.build(h, horizon_s=horizon_s or 10 * span, top=SOE_TOP)
    co = pack_coefficients(basis, a1, a2)
    st = np.zeros(basis.size + 2)
    return _varying(u, alpha, b, st, co, basis.lam, basis.dx, a1, a2)


class PlantStream:
    """The same plant, fed chunk by chunk with persistent state (for endless streams in the bench)."""

    def __init__(self, h: float, alpha: float, a1: float, a2: float, b: float, horizon_s: float = 3600.0) -> None:
        self.basis = SoeBasis.build(h, horizon_s=horizon_s, top=SOE_TOP)
        self.co = pack_coefficients(self.basis, a1, a2)
        self.st = np.zeros(self.basis.size + 2)
        self.alpha, self.a1, self.a2, self.b = alpha, a1, a2, b

    def step_block(self, u: np.ndarray, alpha: np.ndarray | None = None, b: np.ndarray | None = None) -> np.ndarray:
        """Noise-free output for the next len(u) input samples (per-sample alpha and b if given)."""
        u = np.ascontiguousarray(u, dtype=float)
        alpha = np.full(u.size, self.alpha) if alpha is None else np.ascontiguousarray(alpha, dtype=float)
        b = np.full(u.size, self.b) if b is None else np.ascontiguousarray(b, dtype=float)
        return _varying(u, alpha, b, self.st, self.co, self.basis.lam, self.basis.dx, self.a1, self.a2)
