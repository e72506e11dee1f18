"""Numba kernels of the creep compensator (``compensator.py``): one command per call, O(K) work.

State ``st`` (length 3 + 3K): the reference filter ``x = [x1, x2, x3]`` (three
first-order lags of time constant tau; ``x3`` is the filtered reference), then
three banks of SOE nodes, ``z[k, i] = 1/(s + lam_i) g_k`` for
``g_k = tau^k d^k/dt^k x3`` (k = 1, 2, 3). None of it depends on the model:
the model enters only through the output coefficients (``output_coefficients``),
so adapting to a new model is a recomputation of O(K) numbers, not a replay.

Discretisation (``co``, exact for a zero-order-held reference, built once by
``compensator.node_discretization``), per node i and bank k::

    z[k,i] <- e_i z[k,i] + M[i,k] . x + m[i,k] r
    x      <- Phi x + Gam r

and the command is the *interval average* of the continuous inverse over the
coming sample (what a zero-order hold should deliver, so the plant sees no
half-sample lag): ``u = Wz . z + Ux . x + Ur r``.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

CACHE = True


@njit(cache=CACHE)
def soe_weights(beta: float, lam: np.ndarray, dx: float, w: np.ndarray) -> float:
    """SOE weights of the fractional integral of order beta (``SoeBasis.weights``); returns the direct term."""
    q = lam.shape[0]
    s = math.sin(math.pi * beta) / math.pi
    for i in range(1, q):
        w[i] = s * dx * lam[i] ** (1.0 - beta)
    lo = lam[1] * math.exp(-dx)
    w[0] = s * dx * lo ** (1.0 - beta) / (-math.expm1(-(1.0 - beta) * dx))
    hi = lam[q - 1] * math.exp(dx)
    return s * dx * hi ** (-beta) / (-math.expm1(-beta * dx))


@njit(cache=CACHE)
def output_coefficients(alpha: float, a1: float, a2: float, b: float, tau: float, lam: np.ndarray, dx: float,
                        pz: np.ndarray, P: np.ndarray, pr: np.ndarray, Ax: np.ndarray, ax: np.ndarray,
                        C: np.ndarray, d: np.ndarray, Wz: np.ndarray, Ux: np.ndarray) -> float:
    """(Wz, Ux) filled in, Ur returned: u = (1/b) I^(1-alpha) [(1 + a1 s + a2 s^2) s x3], interval-averaged.

    ``I^beta v = D v + sum_i w_i z_i`` (SOE), ``v = sum_k c_k g_k`` with
    ``c = (1, a1/tau, a2/tau^2)/tau``; ``pz, P, pr`` average the nodes over a
    sample, ``Ax, ax`` the filter states, and ``g_k = C[k] . x + d[k] r``.
    """
    q = lam.shape[0]
    w = np.empty(q)
    big_d = soe_weights(1.0 - alpha, lam, dx, w)
    c0 = 1.0 / (tau * b)
    c = np.array([c0, c0 * a1 / tau, c0 * a2 / (tau * tau)])
    Ux[:] = 0.0
    ur = 0.0
    for i in range(q):
        for k in range(3):
            f = w[i] * c[k]
            Wz[k, i] = f * pz[i]
            for j in range(3):
                Ux[j] += f * P[i, k, j]
            ur += f * pr[i, k]
    for k in range(3):      # the direct term D v, averaged: v = sum_k c_k (C[k] . x + d[k] r)
        f = big_d * c[k]
        for j in range(3):
            cx = 0.0
            for m in range(3):
                cx += C[k, m] * Ax[m, j]
            Ux[j] += f * cx
        ca = 0.0
        for m in range(3):
            ca += C[k, m] * ax[m]
        ur += f * (ca + d[k])
    return ur


@njit(cache=CACHE)
def play_step(p: np.ndarray, r: np.ndarray, w: np.ndarray, w0: float, v: float) -> float:
    """Prandtl-Ishlinskii operator ``w0 v + sum_i w_i play_{r_i}[v]``, one sample (states p updated)."""
    out = w0 * v
    for i in range(p.shape[0]):
        pi = max(v - r[i], min(v + r[i], p[i]))
        p[i] = pi
        out += w[i] * pi
    return out


@njit(cache=CACHE)
def command_step(st: np.ndarray, e: np.ndarray, M: np.ndarray, m: np.ndarray, phi: np.ndarray, gam: np.ndarray,
                 Wz: np.ndarray, Ux: np.ndarray, ur: float, r: float, u_min: float, u_max: float,
                 anti_windup: bool, hy: np.ndarray, hy_on: bool, out: np.ndarray) -> float:
    """One sample: the command for reference r, clipped to [u_min, u_max]; the states advanced.

    Anti-windup: when the command is clipped, the states advance with the
    reference the clipped command actually achieves (``r_eff``, solved from
    ``u = base + Ur r_eff``), so the compensator's memory is the plant's, not
    a history the actuator never delivered. ``out = [r_eff, clipped, v]``.
    Hysteresis (``hy_on``): ``hy`` packs the inverse and forward PI operators
    (``compensator.pack_hysteresis``); the creep inverse gives v, the inverse
    PI turns it into u, and a clipped u is mapped back by the forward PI.
    """
    q = e.shape[0]
    x0 = st[0]
    x1 = st[1]
    x2 = st[2]
    base = Ux[0] * x0 + Ux[1] * x1 + Ux[2] * x2
    for k in range(3):
        o = 3 + k * q
        for i in range(q):
            base += Wz[k, i] * st[o + i]
    v = base + ur * r
    r_eff = r
    clipped = 0.0
    if hy_on:
        u, v_eff = _hysteresis(hy, v, u_min, u_max)
        if v_eff != v:
            clipped = 1.0
            if anti_windup and ur != 0.0:
                r_eff = (v_eff - base) / ur
            v = v_eff
    else:
        u = min(max(v, u_min), u_max)
        if u != v:
            clipped = 1.0
            if anti_windup and ur != 0.0:
                r_eff = (u - base) / ur
            v = u
    for k in range(3):
        o = 3 + k * q
        for i in range(q):
            st[o + i] = e[i] * st[o + i] + M[i, k, 0] * x0 + M[i, k, 1] * x1 + M[i, k, 2] * x2 + m[i, k] * r_eff
    st[0] = phi[0, 0] * x0 + phi[0, 1] * x1 + phi[0, 2] * x2 + gam[0] * r_eff
    st[1] = phi[1, 0] * x0 + phi[1, 1] * x1 + phi[1, 2] * x2 + gam[1] * r_eff
    st[2] = phi[2, 0] * x0 + phi[2, 1] * x1 + phi[2, 2] * x2 + gam[2] * r_eff
    out[0] = r_eff
    out[1] = clipped
    out[2] = v
    return u


#: The packed buffer of ``command_packed`` (one array instead of sixteen arguments): scalars first, then
#: st (3 + 3K), e (K), M (9K), m (3K), phi (9), gam (3), Wz (3K), Ux (3). Indices of the scalars:
P_Q, P_UR, P_LO, P_HI, P_AW, P_HY, P_OFF, P_CLIPS = range(8)
P_HEAD = 8


def pack_slices(q: int) -> dict[str, tuple[int, int, tuple[int, ...]]]:
    """{name: (start, stop, shape)} of each array in the packed buffer for K = q nodes."""
    out, o = {}, P_HEAD
    for name, shape in (("st", (3 + 3 * q,)), ("e", (q,)), ("M", (q, 3, 3)), ("m", (q, 3)), ("phi", (3, 3)),
                        ("gam", (3,)), ("Wz", (3, q)), ("Ux", (3,))):
        size = int(np.prod(shape))
        out[name] = (o, o + size, shape)
        o += size
    out["size"] = (o, o, ())
    return out


@njit(cache=CACHE)
def command_packed(buf: np.ndarray, hy: np.ndarray, r: float, out: np.ndarray) -> float:
    """``command_step`` on the packed buffer (``pack_slices``), reference minus the output offset; counts clips.

    Why: numba's dispatcher checks the type of every argument on each call from Python, ~0.14 us per
    argument; four arguments instead of sixteen take ~1.4 us off each ``command()`` and, with fewer objects
    touched per call, most of its CPU tail (bench_compensator ``cost``).
    """
    q = int(buf[P_Q])
    o = P_HEAD
    st = buf[o:o + 3 + 3 * q]
    o += 3 + 3 * q
    e = buf[o:o + q]
    o += q
    M = buf[o:o + 9 * q].reshape((q, 3, 3))
    o += 9 * q
    m = buf[o:o + 3 * q].reshape((q, 3))
    o += 3 * q
    phi = buf[o:o + 9].reshape((3, 3))
    o += 9
    gam = buf[o:o + 3]
    o += 3
    Wz = buf[o:o + 3 * q].reshape((3, q))
    o += 3 * q
    Ux = buf[o:o + 3]
    u = command_step(st, e, M, m, phi, gam, Wz, Ux, buf[P_UR], r - buf[P_OFF], buf[P_LO], buf[P_HI],
                     buf[P_AW] != 0.0, hy, buf[P_HY] != 0.0, out)
    buf[P_CLIPS] += out[1]
    return u


@njit(cache=CACHE)
def _hysteresis(hy: np.ndarray, v: float, u_min: float, u_max: float) -> tuple[float, float]:
    """(u, v_delivered): the inverse PI of v, clipped; a clipped u goes back through the forward PI.

    ``hy`` = [n, w0_inv, w0_fwd, r_inv(n), w_inv(n), p_inv(n), r_fwd(n), w_fwd(n), p_fwd(n), started].
    Both operator sets start centred-or-as-fitted on their first input (states set by the caller).
    """
    n = int(hy[0])
    o = 3
    r_inv = hy[o:o + n]
    w_inv = hy[o + n:o + 2 * n]
    p_inv = hy[o + 2 * n:o + 3 * n]
    r_fwd = hy[o + 3 * n:o + 4 * n]
    w_fwd = hy[o + 4 * n:o + 5 * n]
    p_fwd = hy[o + 5 * n:o + 6 * n]
    if hy[o + 6 * n] == 0.0:         # first sample: the states rest at the variant's offsets around v and u
        for i in range(n):
            p_inv[i] += v
        u0 = hy[1] * v
        for i in range(n):
            u0 += w_inv[i] * p_inv[i]
        for i in range(n):
            p_fwd[i] += u0
        hy[o + 6 * n] = 1.0
    saved = p_inv.copy()
    u = play_step(p_inv, r_inv, w_inv, hy[1], v)
    uc = min(max(u, u_min), u_max)
    if uc == u:
        play_step(p_fwd, r_fwd, w_fwd, hy[2], u)
        return u, v
    v_eff = play_step(p_fwd, r_fwd, w_fwd, hy[2], uc)
    p_inv[:] = saved
    play_step(p_inv, r_inv, w_inv, hy[1], v_eff)
    return uc, v_eff


@njit(cache=CACHE)
def command_block(st: np.ndarray, e: np.ndarray, M: np.ndarray, m: np.ndarray, phi: np.ndarray, gam: np.ndarray,
                  Wz: np.ndarray, Ux: np.ndarray, ur: float, r: np.ndarray, u_min: float, u_max: float,
                  anti_windup: bool, hy: np.ndarray, hy_on: bool, u: np.ndarray, r_eff: np.ndarray) -> int:
    """``command_step`` over a block of references; returns the number of clipped samples."""
    out = np.empty(3)
    clipped = 0
    for n in range(r.shape[0]):
        u[n] = command_step(st, e, M, m, phi, gam, Wz, Ux, ur, r[n], u_min, u_max, anti_windup, hy, hy_on, out)
        r_eff[n] = out[0]
        clipped += int(out[1])
    return clipped


@njit(cache=CACHE)
def replay(st: np.ndarray, e: np.ndarray, M: np.ndarray, m: np.ndarray, phi: np.ndarray, gam: np.ndarray,
           Wz: np.ndarray, Ux: np.ndarray, ur: float, applied: np.ndarray, hy: np.ndarray, hy_on: bool) -> None:
    """Advance the states through commands the plant already received (anti-windup with u pinned to each).

    Each past sample is a command clipped to ``[applied[n], applied[n]]``: the
    states move with the reference that command achieves under the current
    model, so the compensator continues from the plant's real history.
    """
    out = np.empty(3)
    for n in range(applied.shape[0]):
        command_step(st, e, M, m, phi, gam, Wz, Ux, ur, 0.0, applied[n], applied[n], True, hy, hy_on, out)
