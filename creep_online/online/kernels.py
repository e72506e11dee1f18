"""Numba kernels of the online estimator: everything that runs per sample or per window.

State vector ``psi`` (length P = K + 3) at sample n, all driven by the
zero-order-held input u[0..n-1] only (the plant is strictly proper):

* ``psi[0:K+1]``: the SOE nodes ``zeta_i`` (``creep_online.online.soe``), alpha-
  and resonance-independent;
* ``psi[K+1], psi[K+2]``: ``x0 = H2 u`` and ``x1 = d/dt H2 u`` with
  ``H2 = 1/(1 + a1 s + a2 s^2)``, discretized exactly (ZOH).

By partial fractions, ``H2 / (s + lam) = A/(s + lam) + (A (a2 lam - a1) - A a2 s) H2``
with ``A = 1/(a2 lam^2 - a1 lam + 1)``, so the model output is *exactly* linear
in psi: ``y_hat = b psi . v(alpha; a1, a2)`` (see ``model_coefficients``). A new
alpha or b changes only v, never the states.

Coefficient array ``co`` (layout fixed by ``pack_coefficients``):
``co[0:Q]`` node decay, ``co[Q:2Q]`` node input gain (Q = K+1),
``co[2Q:2Q+4]`` Phi (row major), ``co[2Q+4:2Q+6]`` Gamma of the resonance.

Scalar array ``sc``: see the ``SC_*`` indices.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

CACHE = True

# indices into the scalar work array ``sc``
SC_SYY = 0        # sum of weighted y^2 (times g)
SC_G = 1          # g = 1 / (forget^n): statistics are accumulated with weight g
SC_FORGET = 2     # forgetting factor per sample (1 = growing window)
SC_NEFF = 3       # effective number of samples in the statistics (true scale)
SC_E2 = 4         # short exponential mean of the squared prediction error
SC_Y2 = 5         # short exponential mean of y^2 around its short mean
SC_YM = 6         # short exponential mean of y
SC_MON = 7        # smoothing factor of the monitor means (per sample)
SC_LAST = 8       # last prediction
SC_AVGK = 9       # smoothing factor of the eq. 12 averages
SC_YAVG = 10      # short average of y (eq. 12, "f")
SC_SIZE = 12


@njit(cache=CACHE)
def model_coefficients(alpha: float, lam: np.ndarray, dx: float, a1: float, a2: float,
                       v: np.ndarray, dv: np.ndarray) -> None:
    """v(alpha) and dv/dalpha such that y_hat = b psi . v (unit gain).

    SOE weights w_i = sin(pi a)/pi dx lam_i^(1-a) (integrator and direct term
    from the geometric continuation of the trapezoid sum, see soe.py); their
    alpha derivatives are analytic.
    """
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
    sum_x0 = d
    dsum_x0 = d * dld
    sum_a = 0.0
    dsum_a = 0.0
    for i in range(q):
        if i == 0:
            w = w0
            dw = w0 * dlw0
            li = 0.0
        else:
            li = lam[i]
            w = s * dx * li ** (1.0 - alpha)
            dw = w * (pc - math.log(li))
        a = 1.0 / (a2 * li * li - a1 * li + 1.0)
        v[i] = w * a
        dv[i] = dw * a
        sum_x0 += w * a * (a2 * li - a1)
        dsum_x0 += dw * a * (a2 * li - a1)
        sum_a += w * a
        dsum_a += dw * a
    v[q] = sum_x0
    v[q + 1] = -a2 * sum_a
    dv[q] = dsum_x0
    dv[q + 1] = -a2 * dsum_a


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


@njit(cache=CACHE)
def _step(u: float, y: float, st: np.ndarray, co: np.ndarray, v: np.ndarray, S: np.ndarray,
          sy: np.ndarray, sc: np.ndarray, avg: np.ndarray, accumulate: bool) -> float:
    """One sample: prediction, statistics update (if ``accumulate``), state advance."""
    p = st.shape[0]
    pred = 0.0
    for i in range(p):
        pred += st[i] * v[i]
    missing = y != y   # NaN output: a dropped sample, the state still advances with the held input
    if accumulate and not missing:
        f = sc[SC_FORGET]
        g = sc[SC_G]
        if f < 1.0:
            g = g / f
            if g > 1e20:  # renormalise (keeps det() in Gauss-Newton far from overflow)
                inv = 1.0 / g
                for i in range(p):
                    sy[i] *= inv
                    for j in range(i, p):
                        S[i, j] *= inv
                sc[SC_SYY] *= inv
                g = 1.0
            sc[SC_G] = g
        for i in range(p):
            gi = g * st[i]
            sy[i] += gi * y
            for j in range(i, p):
                S[i, j] += gi * st[j]
        sc[SC_SYY] += g * y * y
        sc[SC_NEFF] = sc[SC_NEFF] * f + 1.0
        k = sc[SC_AVGK]
        for i in range(p):
            avg[i] += k * (st[i] - avg[i])
        sc[SC_YAVG] += k * (y - sc[SC_YAVG])
    sc[SC_LAST] = pred
    if missing:
        m = 0.0
    else:
        m = sc[SC_MON]
    # prediction-error monitor (divergence detection)
    e = 0.0 if missing else y - pred
    sc[SC_E2] += m * (e * e - sc[SC_E2])
    sc[SC_YM] += m * ((sc[SC_YM] if missing else y) - sc[SC_YM])
    dy = 0.0 if missing else y - sc[SC_YM]
    if not missing:
        sc[SC_Y2] += m * (dy * dy - sc[SC_Y2])
    # advance: nodes and resonance, exact for a zero-order-held u
    advance_state(st, co, u)
    return pred


@njit(cache=CACHE)
def track_one(u: float, y: float, st: np.ndarray, co: np.ndarray, v: np.ndarray, S: np.ndarray,
              sy: np.ndarray, sc: np.ndarray, avg: np.ndarray, accumulate: bool) -> float:
    """Single-sample entry point (returns the prediction for this sample)."""
    return _step(u, y, st, co, v, S, sy, sc, avg, accumulate)


@njit(cache=CACHE)
def track_block(u: np.ndarray, y: np.ndarray, st: np.ndarray, co: np.ndarray, v: np.ndarray,
                S: np.ndarray, sy: np.ndarray, sc: np.ndarray, avg: np.ndarray, accumulate: bool,
                pred: np.ndarray) -> None:
    """Many samples; pred[k] receives the prediction of sample k (pass a length-0 array to skip)."""
    keep = pred.shape[0] == u.shape[0]
    for k in range(u.shape[0]):
        pk = _step(u[k], y[k], st, co, v, S, sy, sc, avg, accumulate)
        if keep:
            pred[k] = pk


@njit(cache=CACHE)
def predict_next(u: float, st: np.ndarray, co: np.ndarray, v: np.ndarray) -> float:
    """Model output at the next sample if u is held from now on (states not changed)."""
    p = st.shape[0]
    q = p - 2
    acc = 0.0
    for i in range(q):
        acc += (co[i] * st[i] + co[q + i] * u) * v[i]
    b0 = 2 * q
    x0 = st[q]
    x1 = st[q + 1]
    acc += (co[b0] * x0 + co[b0 + 1] * x1 + co[b0 + 4] * u) * v[q]
    acc += (co[b0 + 2] * x0 + co[b0 + 3] * x1 + co[b0 + 5] * u) * v[q + 1]
    return acc


@njit(cache=CACHE)
def _sym_mul(S: np.ndarray, x: np.ndarray, out: np.ndarray) -> None:
    """out = S x for S symmetric, stored in its upper triangle."""
    p = x.shape[0]
    for i in range(p):
        out[i] = 0.0
    for i in range(p):
        out[i] += S[i, i] * x[i]
        for j in range(i + 1, p):
            s = S[i, j]
            out[i] += s * x[j]
            out[j] += s * x[i]


@njit(cache=CACHE)
def window_cost(alpha: float, S: np.ndarray, sy: np.ndarray, syy: float, lam: np.ndarray, dx: float,
                a1: float, a2: float) -> tuple:
    """(J, b): windowed output-error cost with the gain projected out, for this alpha (exact)."""
    p = sy.shape[0]
    v = np.empty(p)
    dv = np.empty(p)
    model_coefficients(alpha, lam, dx, a1, a2, v, dv)
    sv = np.empty(p)
    _sym_mul(S, v, sv)
    m = 0.0
    n = 0.0
    for i in range(p):
        m += v[i] * sv[i]
        n += v[i] * sy[i]
    if m <= 0.0:
        return syy, 0.0
    return syy - n * n / m, n / m


@njit(cache=CACHE)
def _quadratic_forms(S, sy, v, dv, sv, sdv):
    """(v'Sv, v'sy, dv'Sv, dv'S dv, dv'sy): the window cost and its alpha-derivatives' pieces."""
    _sym_mul(S, v, sv)
    _sym_mul(S, dv, sdv)
    m = 0.0
    n = 0.0
    mv = 0.0
    mdd = 0.0
    nd = 0.0
    for i in range(v.shape[0]):
        m += v[i] * sv[i]
        n += v[i] * sy[i]
        mv += dv[i] * sv[i]
        mdd += dv[i] * sdv[i]
        nd += dv[i] * sy[i]
    return m, n, mv, mdd, nd


@njit(cache=CACHE)
def gauss_newton_alpha(alpha: float, b: float, S: np.ndarray, sy: np.ndarray, syy: float,
                       lam: np.ndarray, dx: float, a1: float, a2: float, lo: float, hi: float,
                       iters: int, out: np.ndarray) -> None:
    """Layer 1 on the window: minimise J(alpha, b) = sum w_n (y_n - b psi_n . v(alpha))^2.

    Gauss-Newton on (b, alpha) with exact statistics, step halving on
    non-decrease, alpha kept in [lo, hi]. ``out`` = [alpha, b, J, var_alpha
    (unscaled), var_b (unscaled), cov_ab (unscaled), iterations, ok]. The
    unscaled covariance is inv(GN matrix); multiply by sigma^2.
    """
    p = sy.shape[0]
    v = np.empty(p)
    dv = np.empty(p)
    sv = np.empty(p)
    sdv = np.empty(p)
    cost = 0.0
    h00 = h01 = h11 = 0.0
    it = 0
    ok = 1.0
    for it in range(iters + 1):
        model_coefficients(alpha, lam, dx, a1, a2, v, dv)
        m, n, mv, mdd, nd = _quadratic_forms(S, sy, v, dv, sv, sdv)
        cost = syy - 2.0 * b * n + b * b * m
        h00 = m
        h01 = b * mv
        h11 = b * b * mdd
        if it == iters:
            break
        g0 = b * m - n
        g1 = b * (b * mv - nd)
        det = h00 * h11 - h01 * h01
        if not (det > 1e-300 * (abs(h00 * h11) + 1e-300)) or m <= 0.0:
            ok = 0.0
            break
        db = -(h11 * g0 - h01 * g1) / det
        da = -(-h01 * g0 + h00 * g1) / det
        # step halving until the cost does not increase
        step = 1.0
        accepted = False
        for _ in range(12):
            an = min(max(alpha + step * da, lo), hi)
            bn = b + step * db
            model_coefficients(an, lam, dx, a1, a2, v, dv)
            _sym_mul(S, v, sv)
            mn = 0.0
            nn = 0.0
            for i in range(p):
                mn += v[i] * sv[i]
                nn += v[i] * sy[i]
            cn = syy - 2.0 * bn * nn + bn * bn * mn
            if cn <= cost:
                accepted = True
                break
            step *= 0.5
        if not accepted:
            break
        moved = abs(an - alpha)
        alpha = an
        b = bn
        if moved < 1e-10:
            model_coefficients(alpha, lam, dx, a1, a2, v, dv)
            m, n, mv, mdd, nd = _quadratic_forms(S, sy, v, dv, sv, sdv)
            cost = syy - 2.0 * b * n + b * b * m
            h00 = m
            h01 = b * mv
            h11 = b * b * mdd
            break
    det = h00 * h11 - h01 * h01
    out[0] = alpha
    out[1] = b
    out[2] = cost
    if det > 0.0:
        out[3] = h00 / det
        out[4] = h11 / det
        out[5] = -h01 / det
    else:
        out[3] = math.inf
        out[4] = math.inf
        out[5] = 0.0
    out[6] = it
    out[7] = ok


# --------------------------------------------------------------------------- Remark 3, "carry on"
@njit(cache=CACHE)
def rpem_block(u: np.ndarray, y: np.ndarray, st: np.ndarray, co: np.ndarray, lam: np.ndarray, dx: float,
               a1: float, a2: float, theta: np.ndarray, P: np.ndarray, forget: float, lo: float,
               hi: float, every: int, counter: np.ndarray, pmax: float) -> None:
    """Recursive prediction-error (Gauss-Newton) update of theta = (alpha, b): the "carry on" option.

    Each sample's prediction and sensitivity use the alpha current at that
    sample; the past is never re-evaluated (the information matrix keeps the
    regressors computed with older alphas). v(alpha) is refreshed every
    ``every`` samples. Covariance P is kept symmetric and bounded by ``pmax`` in trace (anti-windup).
    """
    p = st.shape[0]
    v = np.empty(p)
    dv = np.empty(p)
    model_coefficients(theta[0], lam, dx, a1, a2, v, dv)
    for k in range(u.shape[0]):
        counter[0] += 1
        if counter[0] % every == 0:
            model_coefficients(theta[0], lam, dx, a1, a2, v, dv)
        g = 0.0
        gd = 0.0
        for i in range(p):
            g += st[i] * v[i]
            gd += st[i] * dv[i]
        alpha = theta[0]
        b = theta[1]
        if y[k] == y[k]:   # a NaN output (dropped sample) only advances the state
            e = y[k] - b * g
            f0 = b * gd   # d y_hat / d alpha
            f1 = g        # d y_hat / d b
            pf0 = P[0, 0] * f0 + P[0, 1] * f1
            pf1 = P[1, 0] * f0 + P[1, 1] * f1
            den = forget + f0 * pf0 + f1 * pf1
            k0 = pf0 / den
            k1 = pf1 / den
            theta[0] = min(max(alpha + k0 * e, lo), hi)
            theta[1] = b + k1 * e
            p00 = (P[0, 0] - k0 * pf0) / forget
            p01 = (P[0, 1] - k0 * pf1) / forget
            p11 = (P[1, 1] - k1 * pf1) / forget
            # anti-windup: cap the trace
            tr = p00 + p11
            if tr > pmax:
                p00 *= pmax / tr
                p01 *= pmax / tr
                p11 *= pmax / tr
            P[0, 0] = p00
            P[0, 1] = p01
            P[1, 0] = p01
            P[1, 1] = p11
        advance_state(st, co, u[k])


# --------------------------------------------------------------------------- layer 2 (phase 1)
@njit(cache=CACHE)
def node_history(u: np.ndarray, decay: np.ndarray, gain: np.ndarray, zeta: np.ndarray,
                 out: np.ndarray) -> None:
    """out[k] = node states before sample k is applied (then advanced with u[k]); zeta updated."""
    q = zeta.shape[0]
    for k in range(u.shape[0]):
        for i in range(q):
            out[k, i] = zeta[i]
            zeta[i] = decay[i] * zeta[i] + gain[i] * u[k]


@njit(cache=CACHE)
def layer2_shape(hist: np.ndarray, vz: np.ndarray, u: np.ndarray, phi: np.ndarray, gam: np.ndarray,
                 vx0: float, vx1: float, out: np.ndarray) -> None:
    """Unit-gain model output over the buffer for one (a1, a2): nodes . vz + vx0 x0 + vx1 x1."""
    q = vz.shape[0]
    x0 = 0.0
    x1 = 0.0
    for k in range(u.shape[0]):
        acc = vx0 * x0 + vx1 * x1
        for i in range(q):
            acc += hist[k, i] * vz[i]
        out[k] = acc
        n0 = phi[0, 0] * x0 + phi[0, 1] * x1 + gam[0] * u[k]
        x1 = phi[1, 0] * x0 + phi[1, 1] * x1 + gam[1] * u[k]
        x0 = n0


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
