"""Numba kernels: the inner loops of every simulator, compiled once and cached on disk.

Three families live here (docs/model.md, "The simulators"):

* ``gl_paper``: the multi-term revised Grunwald-Letnikov recursion of the paper's
  eq. 13/14 exactly as FOMCON's ``lsim`` computes it (implicit, full or truncated
  memory, O(N L)).
* ``fractional_integral_zoh`` + ``resonance_foh``: the split form. The fractional
  integral of a zero-order-held input is exact at the samples; the 2nd-order part
  is then discretized exactly for a piecewise-linear intermediate signal.
* ``state_march``: the exact sampled step response of the whole model, computed
  by marching the 2-state resonance exactly (matrix exponential) against the
  closed-form fractional integral t^alpha / Gamma(1+alpha). Quadrature on the
  first intervals, a Taylor expansion of t^alpha beyond them. Matrices come from
  ``creep_online.discretize``; this module holds only loops.
"""
from __future__ import annotations

import cmath

import numpy as np
from numba import njit

CACHE = True


@njit(cache=CACHE, nogil=True)
def gl_weights(order: float, n: int) -> np.ndarray:
    """Grunwald-Letnikov weights w_j = (-1)^j C(order, j), j = 0..n-1.

    Recursion w_0 = 1, w_j = w_{j-1} (1 - (order + 1) / j). A negative order
    gives the fractional integral's weights.
    """
    w = np.empty(n)
    if n == 0:
        return w
    w[0] = 1.0
    for j in range(1, n):
        w[j] = w[j - 1] * (1.0 - (order + 1.0) / j)
    return w


@njit(cache=CACHE, nogil=True)
def paper_weights(alpha: float, a1: float, a2: float, h: float, n: int) -> np.ndarray:
    """Combined eq. 13 weights W_j = sum_k a_k h^-eta_k w_j(eta_k).

    Terms (a_k, eta_k) = (1, alpha), (a1, alpha + 1), (a2, alpha + 2); W_0 is the
    denominator D of the recursion.
    """
    w0 = gl_weights(alpha, n)
    w1 = gl_weights(alpha + 1.0, n)
    w2 = gl_weights(alpha + 2.0, n)
    c0 = h ** (-alpha)
    c1 = a1 * h ** (-(alpha + 1.0))
    c2 = a2 * h ** (-(alpha + 2.0))
    out = np.empty(n)
    for j in range(n):
        out[j] = c0 * w0[j] + c1 * w1[j] + c2 * w2[j]
    return out


@njit(cache=CACHE, nogil=True)
def gl_paper(u: np.ndarray, h: float, alpha: float, a1: float, a2: float, memory: int) -> np.ndarray:
    """Eq. 13: y1[n] = (u[n] - sum_{j=1..min(n, L)} W_j y1[n-j]) / D, y1[0] = 0 (gain 1).

    ``memory`` = L <= 0 means full memory (O(N^2)), as FOMCON does. FOMCON never
    uses u[0]; neither does this.
    """
    n_samples = u.shape[0]
    length = n_samples if memory <= 0 else min(memory + 1, n_samples)
    w = paper_weights(alpha, a1, a2, h, length)
    d = w[0]
    y = np.zeros(n_samples)
    for n in range(1, n_samples):
        acc = 0.0
        jmax = min(n, length - 1)
        for j in range(1, jmax + 1):
            acc += w[j] * y[n - j]
        y[n] = (u[n] - acc) / d
    return y


@njit(cache=CACHE, nogil=True)
def zoh_integral_weights(alpha: float, h: float, gamma1: float, n: int) -> np.ndarray:
    """Exact fractional-integral weights for a zero-order-held input.

    c_j = h^alpha (j^alpha - (j-1)^alpha) / Gamma(1+alpha), j >= 1 (c_0 = 0): the
    integral of (t_n - tau)^(alpha-1)/Gamma(alpha) over the hold interval j
    samples back. ``gamma1`` is Gamma(1 + alpha) (numba has no gamma).
    """
    c = np.zeros(n)
    scale = h**alpha / gamma1
    prev = 0.0
    for j in range(1, n):
        cur = float(j) ** alpha
        c[j] = scale * (cur - prev)
        prev = cur
    return c


@njit(cache=CACHE, nogil=True)
def fractional_integral_zoh(u: np.ndarray, c: np.ndarray) -> np.ndarray:
    """z[n] = sum_{j=1..min(n, L)} c_j u[n-j]: direct (truncated if len(c) < N) convolution."""
    n_samples = u.shape[0]
    length = c.shape[0]
    z = np.zeros(n_samples)
    for n in range(1, n_samples):
        acc = 0.0
        jmax = min(n, length - 1)
        for j in range(1, jmax + 1):
            acc += c[j] * u[n - j]
        z[n] = acc
    return z


@njit(cache=CACHE, nogil=True)
def resonance_foh(z: np.ndarray, phi: np.ndarray, g0: np.ndarray, g1: np.ndarray, h: float) -> np.ndarray:
    """Exact response of 1/(1 + a1 s + a2 s^2) to the piecewise-linear interpolant of z.

    x_{n+1} = Phi x_n + G0 z_n + G1 (z_{n+1} - z_n) / h, y_n = x_n[0], x_0 = 0.
    """
    n_samples = z.shape[0]
    y = np.zeros(n_samples)
    x0 = 0.0
    x1 = 0.0
    for n in range(n_samples - 1):
        slope = (z[n + 1] - z[n]) / h
        nx0 = phi[0, 0] * x0 + phi[0, 1] * x1 + g0[0] * z[n] + g1[0] * slope
        nx1 = phi[1, 0] * x0 + phi[1, 1] * x1 + g0[1] * z[n] + g1[1] * slope
        x0 = nx0
        x1 = nx1
        y[n + 1] = x0
    return y


@njit(cache=CACHE, nogil=True)
def taylor_thresholds(n_terms: int) -> np.ndarray:
    """Sample index from which Taylor term m of the march's forcing is dropped: 10^(13/m).

    Term m of sum_m taylor[m] v^(m)(t_n) is ~n^-m / (m (m + 1)) of term 0, so the
    terms m >= M together stay below 1e-14 of it once n >= 10^(13/M): 8 terms
    on the first 72 samples, 4 from 1,778, 3 from 21,544, 2 from 3.2e6.
    """
    out = np.full(n_terms, np.inf)
    for m in range(1, n_terms):
        out[m] = 10.0 ** (13.0 / m)
    return out


@njit(cache=CACHE, nogil=True)
def state_march(n_samples: int, h: float, alpha: float, gamma1: float, phi: np.ndarray,
                head: np.ndarray, taylor: np.ndarray) -> np.ndarray:
    """Exact unit-step response S[n] = S(n h) of the whole model (gain 1).

    x' = A x + B v(t), v(t) = t^alpha / Gamma(1+alpha) (the exact fractional
    integral of a unit step), y = x[0]. Each interval is advanced exactly:
    x_{n+1} = Phi x_n + int_0^h e^{A(h-s)} B v(t_n + s) ds. The integral is
    ``head[n]`` (precomputed by quadrature) for the first len(head) intervals and
    the Taylor series sum_m taylor[m] v^(m)(t_n) beyond, where
    taylor[m] = int_0^h e^{A(h-s)} B s^m / m! ds and
    v^(m)(t) = v(t) prod_{i<m} (alpha - i) / t; its terms below 1e-14 of the
    first are dropped (``taylor_thresholds``). t^alpha is exp(alpha ln t), as in
    ``state_march_sensitivity``, which needs ln t anyway (a pow cost as much as
    both; the two differ by ~1e-15 relative).
    """
    s = np.zeros(n_samples)
    n_head = head.shape[0]
    n_terms = taylor.shape[0]
    thresholds = taylor_thresholds(n_terms)
    x0 = 0.0
    x1 = 0.0
    inv_gamma = 1.0 / gamma1
    for n in range(n_samples - 1):
        if n < n_head:
            f0 = head[n, 0]
            f1 = head[n, 1]
        else:
            while n_terms > 1 and n >= thresholds[n_terms - 1]:
                n_terms -= 1
            t = n * h
            deriv = np.exp(alpha * np.log(t)) * inv_gamma
            f0 = taylor[0, 0] * deriv
            f1 = taylor[0, 1] * deriv
            inv_t = 1.0 / t
            for m in range(1, n_terms):
                deriv *= (alpha - (m - 1)) * inv_t
                f0 += taylor[m, 0] * deriv
                f1 += taylor[m, 1] * deriv
        nx0 = phi[0, 0] * x0 + phi[0, 1] * x1 + f0
        nx1 = phi[1, 0] * x0 + phi[1, 1] * x1 + f1
        x0 = nx0
        x1 = nx1
        s[n + 1] = x0
    return s


@njit(cache=CACHE, nogil=True)
def superpose_steps(step_response: np.ndarray, index: np.ndarray, size: np.ndarray, n_samples: int) -> np.ndarray:
    """y[n] = sum_k size_k S[n - index_k] for n >= index_k: a sparse ZOH convolution."""
    y = np.zeros(n_samples)
    for k in range(index.shape[0]):
        i0 = index[k]
        a = size[k]
        for n in range(i0, n_samples):
            y[n] += a * step_response[n - i0]
    return y


@njit(cache=CACHE, nogil=True)
def superpose_steps_rows(step_responses: np.ndarray, index: np.ndarray, size: np.ndarray,
                         n_samples: int) -> np.ndarray:
    """``superpose_steps`` for each row of ``step_responses`` (k, >= n_samples): the same sums, one call."""
    y = np.zeros((step_responses.shape[0], n_samples))
    for r in range(step_responses.shape[0]):
        for k in range(index.shape[0]):
            i0 = index[k]
            a = size[k]
            for n in range(i0, n_samples):
                y[r, n] += a * step_responses[r, n - i0]
    return y


@njit(cache=CACHE, nogil=True)
def foh_grid_costs(z: np.ndarray, y: np.ndarray, phi: np.ndarray, g0: np.ndarray, g1: np.ndarray,
                   h: float) -> np.ndarray:
    """For each resonance k: min over b of ||y - b s_k||^2, s_k = resonance_foh(z) with (phi, g0, g1)[k].

    All grid points march together, the grid innermost: the points are
    independent, so that loop runs in SIMD lanes (one point per sample
    outermost was a serial chain of dependent multiply-adds). Each point's
    arithmetic is ``resonance_foh``'s, in the same order.
    """
    n_grid = phi.shape[0]
    n = z.shape[0]
    yy = 0.0
    for i in range(n):
        yy += y[i] * y[i]
    p00, p01 = phi[:, 0, 0].copy(), phi[:, 0, 1].copy()
    p10, p11 = phi[:, 1, 0].copy(), phi[:, 1, 1].copy()
    c0, c1 = g0[:, 0].copy(), g0[:, 1].copy()
    d0, d1 = g1[:, 0].copy(), g1[:, 1].copy()
    x0 = np.zeros(n_grid)
    x1 = np.zeros(n_grid)
    ss = np.zeros(n_grid)
    sy = np.zeros(n_grid)
    for i in range(n - 1):
        zi = z[i]
        slope = (z[i + 1] - zi) / h
        yi = y[i + 1]
        for k in range(n_grid):
            nx0 = p00[k] * x0[k] + p01[k] * x1[k] + c0[k] * zi + d0[k] * slope
            nx1 = p10[k] * x0[k] + p11[k] * x1[k] + c1[k] * zi + d1[k] * slope
            x0[k] = nx0
            x1[k] = nx1
            ss[k] += nx0 * nx0
            sy[k] += nx0 * yi
    costs = np.empty(n_grid)
    for k in range(n_grid):
        costs[k] = yy - sy[k] * sy[k] / ss[k] if ss[k] > 0.0 else yy
    return costs


@njit(cache=CACHE, nogil=True)
def transition_b(slow: complex, fast: complex, wn: float, damp: float, tau: float) -> tuple[float, float]:
    """e^{A tau} B for the balanced resonance A = [[0, wn], [-wn, -damp]], B = [0, wn].

    Putzer with the slow pole first: e^{A tau} = e^{l1 tau} I + r (A - l1 I),
    r = e^{l1 tau} (e^{d tau} - 1) / d, d = l2 - l1, with a series for small d tau.
    """
    d = fast - slow
    x = d * tau
    if abs(x) < 1e-4:
        ratio = tau * (1.0 + x / 2.0 + x * x / 6.0 + x * x * x / 24.0)
    else:
        ratio = (cmath.exp(x) - 1.0) / d
    e1 = cmath.exp(slow * tau)
    r = e1 * ratio
    # B = [0, wn], A B = [wn^2, -damp wn]
    return (r * (wn * wn)).real, (e1 * wn + r * (-damp * wn - slow * wn)).real


@njit(cache=CACHE, nogil=True)
def head_quadrature(alpha: float, slow: complex, fast: complex, wn: float, damp: float, h: float,
                    n_head: int, xl: np.ndarray, wl: np.ndarray, xj: np.ndarray, wj: np.ndarray,
                    panels: int, gamma1: float) -> np.ndarray:
    """int_0^h e^{A(h-s)} B (k h + s)^alpha / Gamma(1+alpha) ds for k < n_head.

    Gauss-Legendre on ``panels`` panels per interval; on interval 0's first
    panel Gauss-Jacobi with weight s^alpha takes the singularity.
    """
    out = np.zeros((n_head, 2))
    width = h / panels
    for p in range(panels):
        for i in range(xl.shape[0]):
            s = p * width + (xl[i] + 1.0) * width / 2.0
            w = wl[i] * width / 2.0
            e0, e1 = transition_b(slow, fast, wn, damp, h - s)
            for k in range(n_head):
                if k == 0 and p == 0:
                    continue
                v = w * (k * h + s) ** alpha
                out[k, 0] += v * e0
                out[k, 1] += v * e1
    scale = (width / 2.0) ** (1.0 + alpha)
    for i in range(xj.shape[0]):
        s = (xj[i] + 1.0) * width / 2.0
        e0, e1 = transition_b(slow, fast, wn, damp, h - s)
        out[0, 0] += wj[i] * scale * e0
        out[0, 1] += wj[i] * scale * e1
    for k in range(n_head):
        out[k, 0] /= gamma1
        out[k, 1] /= gamma1
    return out


@njit(cache=CACHE, nogil=True)
def foh_grid_costs_projected(z: np.ndarray, y_perp: np.ndarray, q: np.ndarray, phi: np.ndarray, g0: np.ndarray,
                             g1: np.ndarray, h: float) -> np.ndarray:
    """``foh_grid_costs`` with fixed nuisance columns projected out.

    ``q`` (n x k) is an orthonormal basis of the nuisance columns (offset,
    free response) and ``y_perp`` the data with them projected out. For each
    resonance the cost is min over b of ||y_perp - b P s||^2 with
    P s . P s = s.s - sum_j (s.q_j)^2, accumulated in one pass.
    """
    n_grid = phi.shape[0]
    n = z.shape[0]
    k_cols = q.shape[1]
    yy = 0.0
    for i in range(n):
        yy += y_perp[i] * y_perp[i]
    costs = np.empty(n_grid)
    sq = np.empty(k_cols)
    for k in range(n_grid):
        x0 = 0.0
        x1 = 0.0
        ss = 0.0
        sy = 0.0
        for j in range(k_cols):
            sq[j] = 0.0
        for i in range(n - 1):
            slope = (z[i + 1] - z[i]) / h
            nx0 = phi[k, 0, 0] * x0 + phi[k, 0, 1] * x1 + g0[k, 0] * z[i] + g1[k, 0] * slope
            nx1 = phi[k, 1, 0] * x0 + phi[k, 1, 1] * x1 + g0[k, 1] * z[i] + g1[k, 1] * slope
            x0 = nx0
            x1 = nx1
            ss += x0 * x0
            sy += x0 * y_perp[i + 1]
            for j in range(k_cols):
                sq[j] += x0 * q[i + 1, j]
        for j in range(k_cols):
            ss -= sq[j] * sq[j]
        costs[k] = yy - sy * sy / ss if ss > 1e-300 else yy
    return costs


@njit(cache=CACHE, nogil=True)
def foh_grid_costs_free(z: np.ndarray, y_perp: np.ndarray, q: np.ndarray, phi: np.ndarray, g0: np.ndarray,
                        g1: np.ndarray, h: float) -> np.ndarray:
    """``foh_grid_costs_projected`` with the resonance's two free modes also fitted per grid point.

    For a record taken in operation the resonance's initial state rings on;
    its two modes (x marched from [1, 0] and [0, 1]) depend on the grid
    point, so they join the forced response s in a 3-column least squares
    after the fixed columns ``q`` are projected out: cost = |y_perp|^2 -
    v' G^-1 v with G the projected Gram matrix of (s, m1, m2).
    """
    n_grid = phi.shape[0]
    n = z.shape[0]
    k_cols = q.shape[1]
    yy = 0.0
    for i in range(n):
        yy += y_perp[i] * y_perp[i]
    costs = np.empty(n_grid)
    cq = np.zeros((3, k_cols))
    for k in range(n_grid):
        x = np.zeros((3, 2))
        x[1, 0] = 1.0
        x[2, 1] = 1.0
        gram = np.zeros((3, 3))
        v = np.zeros(3)
        cq[:, :] = 0.0
        # sample 0: only the free modes are non-zero (m1 = 1, m2 = 0)
        gram[1, 1] += 1.0
        v[1] += y_perp[0]
        for j in range(k_cols):
            cq[1, j] += q[0, j]
        for i in range(n - 1):
            slope = (z[i + 1] - z[i]) / h
            for c in range(3):
                f0 = 0.0
                f1 = 0.0
                if c == 0:
                    f0 = g0[k, 0] * z[i] + g1[k, 0] * slope
                    f1 = g0[k, 1] * z[i] + g1[k, 1] * slope
                nx0 = phi[k, 0, 0] * x[c, 0] + phi[k, 0, 1] * x[c, 1] + f0
                nx1 = phi[k, 1, 0] * x[c, 0] + phi[k, 1, 1] * x[c, 1] + f1
                x[c, 0] = nx0
                x[c, 1] = nx1
            for a in range(3):
                xa = x[a, 0]
                v[a] += xa * y_perp[i + 1]
                for b in range(a, 3):
                    gram[a, b] += xa * x[b, 0]
                for j in range(k_cols):
                    cq[a, j] += xa * q[i + 1, j]
        for a in range(3):
            for b in range(a, 3):
                acc = gram[a, b]
                for j in range(k_cols):
                    acc -= cq[a, j] * cq[b, j]
                gram[a, b] = acc
                gram[b, a] = acc
        scale = np.sqrt(np.abs(np.diag(gram)))
        for a in range(3):
            if not scale[a] > 1e-150:     # a column that is zero here (no input change in the window): left unscaled
                scale[a] = 1.0
        gs = gram / np.outer(scale, scale)
        vs = v / scale
        for a in range(3):
            gs[a, a] += 1e-10
        sol = np.linalg.solve(gs, vs)
        costs[k] = yy - np.dot(vs, sol)
    return costs


@njit(cache=CACHE, nogil=True)
def state_march_sensitivity(n_samples: int, h: float, alpha: float, gamma1: float, psi1: float, phi: np.ndarray,
                            dphi: np.ndarray, head: np.ndarray, dhead: np.ndarray, taylor: np.ndarray,
                            dtaylor: np.ndarray) -> np.ndarray:
    """``state_march`` and its forward sensitivities: rows S, dS/dalpha, dS/da1, dS/da2 (shape (4, n)).

    The march x_{n+1} = Phi x_n + f_n is differentiated term by term:
    dx_{n+1} = Phi dx_n + dPhi x_n + df_n, with dPhi = 0 for alpha. ``dphi``
    (2, 2, 2) and ``dtaylor`` (2, terms, 2) are the a1 and a2 derivatives of
    ``phi`` and ``taylor``; ``dhead`` (3, n_head, 2) those of ``head`` for
    (alpha, a1, a2). Beyond the head, d v^(m)/d alpha = v^(m) (ln t - psi1) +
    v(t) t^-m dP_m with P_m = prod_{i<m} (alpha - i) and psi1 = digamma(1 + alpha).
    Row 0 is ``state_march``'s S bit for bit (same operations in the same order,
    the same Taylor terms kept).
    Scalars only in the loop (small arrays there kept it twice as slow).
    """
    out = np.zeros((4, n_samples))
    n_head = head.shape[0]
    n_terms = taylor.shape[0]
    dpm = np.zeros(n_terms)        # dP_m / d alpha
    pm = 1.0
    for m in range(1, n_terms):
        dpm[m] = dpm[m - 1] * (alpha - (m - 1)) + pm
        pm *= alpha - (m - 1)
    thresholds = taylor_thresholds(n_terms)      # the terms kept, as state_march keeps them
    p00, p01, p10, p11 = phi[0, 0], phi[0, 1], phi[1, 0], phi[1, 1]
    q00, q01, q10, q11 = dphi[0, 0, 0], dphi[0, 0, 1], dphi[0, 1, 0], dphi[0, 1, 1]
    r00, r01, r10, r11 = dphi[1, 0, 0], dphi[1, 0, 1], dphi[1, 1, 0], dphi[1, 1, 1]
    x0 = x1 = 0.0
    a0 = a1 = 0.0                  # dx/d alpha
    b0 = b1 = 0.0                  # dx/d a1
    c0 = c1 = 0.0                  # dx/d a2
    inv_gamma = 1.0 / gamma1
    for n in range(n_samples - 1):
        if n < n_head:
            f0, f1 = head[n, 0], head[n, 1]
            fa0, fa1 = dhead[0, n, 0], dhead[0, n, 1]
            fb0, fb1 = dhead[1, n, 0], dhead[1, n, 1]
            fc0, fc1 = dhead[2, n, 0], dhead[2, n, 1]
        else:
            t = n * h
            ln_t = np.log(t)
            deriv = np.exp(alpha * ln_t) * inv_gamma
            plain = deriv              # v(t) t^-m, for the dP_m term
            log_t = ln_t - psi1
            f0 = taylor[0, 0] * deriv
            f1 = taylor[0, 1] * deriv
            ea0 = ea1 = 0.0
            fb0 = dtaylor[0, 0, 0] * deriv
            fb1 = dtaylor[0, 0, 1] * deriv
            fc0 = dtaylor[1, 0, 0] * deriv
            fc1 = dtaylor[1, 0, 1] * deriv
            inv_t = 1.0 / t
            while n_terms > 1 and n >= thresholds[n_terms - 1]:
                n_terms -= 1
            for m in range(1, n_terms):
                deriv *= (alpha - (m - 1)) * inv_t
                f0 += taylor[m, 0] * deriv
                f1 += taylor[m, 1] * deriv
                plain *= inv_t
                ea0 += taylor[m, 0] * (plain * dpm[m])
                ea1 += taylor[m, 1] * (plain * dpm[m])
                fb0 += dtaylor[0, m, 0] * deriv
                fb1 += dtaylor[0, m, 1] * deriv
                fc0 += dtaylor[1, m, 0] * deriv
                fc1 += dtaylor[1, m, 1] * deriv
            fa0 = f0 * log_t + ea0
            fa1 = f1 * log_t + ea1
        na0 = p00 * a0 + p01 * a1 + fa0
        na1 = p10 * a0 + p11 * a1 + fa1
        nb0 = p00 * b0 + p01 * b1 + q00 * x0 + q01 * x1 + fb0
        nb1 = p10 * b0 + p11 * b1 + q10 * x0 + q11 * x1 + fb1
        nc0 = p00 * c0 + p01 * c1 + r00 * x0 + r01 * x1 + fc0
        nc1 = p10 * c0 + p11 * c1 + r10 * x0 + r11 * x1 + fc1
        nx0 = phi[0, 0] * x0 + phi[0, 1] * x1 + f0
        nx1 = phi[1, 0] * x0 + phi[1, 1] * x1 + f1
        x0, x1, a0, a1, b0, b1, c0, c1 = nx0, nx1, na0, na1, nb0, nb1, nc0, nc1
        out[0, n + 1] = x0
        out[1, n + 1] = a0
        out[2, n + 1] = b0
        out[3, n + 1] = c0
    return out


@njit(cache=CACHE, nogil=True)
def _poles(a1: float, a2: float) -> tuple[complex, complex]:
    """(slow, fast) roots of a2 s^2 + a1 s + 1, as ``discretize.resonance_poles``."""
    root = cmath.sqrt(complex(a1 * a1 - 4.0 * a2))
    q = -0.5 * (a1 + root)
    return 1.0 / q, q / a2


@njit(cache=CACHE, nogil=True)
def _log_singular_panel(alpha: float, slow: complex, fast: complex, wn: float, damp: float, h: float,
                        width: float, xl: np.ndarray, wl: np.ndarray) -> tuple[float, float]:
    """int_0^width s^alpha ln(s) e^{A(h-s)} B ds (the head's alpha derivative on its singular first panel).

    On [0, w0], with |A| w0 <= 1, the series e^{A(h-s)} B = sum_j (-A)^j e^{A h} B
    s^j / j! is integrated exactly: int_0^w0 s^b ln s ds = w0^(b+1) (ln w0 / (b+1)
    - 1/(b+1)^2), b = alpha + j (terms below 1e-18 within ~25). Beyond w0 the
    integrand is smooth on each of the doubling pieces [w0 2^i, w0 2^(i+1)]
    up to ``width``: Gauss-Legendre (stiff resonances need the pieces; at most
    ~log2(|A| width) of them).
    """
    norm = wn + abs(damp)                        # infinity norm of A = [[0, wn], [-wn, -damp]]
    w0 = width
    for _ in range(200):
        if w0 * norm <= 1.0:
            break
        w0 *= 0.5
    g0, g1 = transition_b(slow, fast, wn, damp, h)   # e^{A h} B, then (-A)^j e^{A h} B / j!
    log_w = np.log(w0)
    acc0 = 0.0
    acc1 = 0.0
    for j in range(60):
        beta1 = alpha + j + 1.0
        c = w0**beta1 * (log_w / beta1 - 1.0 / (beta1 * beta1))
        acc0 += c * g0
        acc1 += c * g1
        if j > 4 and abs(c) * (abs(g0) + abs(g1)) <= 1e-18 * (abs(acc0) + abs(acc1)):
            break
        n0 = -(wn * g1) / (j + 1.0)                  # -A g / (j+1)
        n1 = -(-wn * g0 - damp * g1) / (j + 1.0)
        g0 = n0
        g1 = n1
    lo = w0
    while lo < width * (1.0 - 1e-12):
        hi = min(2.0 * lo, width)
        for i in range(xl.shape[0]):
            s = lo + (xl[i] + 1.0) * (hi - lo) / 2.0
            v = wl[i] * (hi - lo) / 2.0 * s**alpha * np.log(s)
            e0, e1 = transition_b(slow, fast, wn, damp, h - s)
            acc0 += v * e0
            acc1 += v * e1
        lo = hi
    return acc0, acc1


@njit(cache=CACHE, nogil=True)
def head_sensitivity(alpha: float, a1: float, a2: float, h: float, n_head: int, xl: np.ndarray, wl: np.ndarray,
                     xj: np.ndarray, wj: np.ndarray, panels: int, gamma1: float, psi1: float,
                     rel_step: float) -> np.ndarray:
    """``head_quadrature``'s terms and their derivatives: shape (4, n_head, 2), rows head, d/d(alpha, a1, a2).

    The same panels and nodes as ``head_quadrature`` (whose result row 0
    reproduces). alpha: the integrals of the derivative, with ln(k h + s) -
    psi1 in the integrand (``_log_singular_panel`` on interval 0's first panel,
    where ln s is singular). a1, a2: central
    differences with relative step ``rel_step``, the powers (k h + s)^alpha
    shared by the four perturbed heads.
    """
    sets = np.array([[a1, a2], [a1 * (1 + rel_step), a2], [a1 * (1 - rel_step), a2],
                     [a1, a2 * (1 + rel_step)], [a1, a2 * (1 - rel_step)]])
    n_sets = sets.shape[0]
    poles = np.empty((n_sets, 2), dtype=np.complex128)
    for j in range(n_sets):
        poles[j, 0], poles[j, 1] = _poles(sets[j, 0], sets[j, 1])
    acc = np.zeros((n_sets + 1, n_head, 2))     # heads of the five sets, then the alpha integral
    e = np.empty((n_sets, 2))
    width = h / panels
    for p in range(panels):
        for i in range(xl.shape[0]):
            s = p * width + (xl[i] + 1.0) * width / 2.0
            w = wl[i] * width / 2.0
            for j in range(n_sets):
                e[j, 0], e[j, 1] = transition_b(poles[j, 0], poles[j, 1], 1.0 / np.sqrt(sets[j, 1]),
                                                sets[j, 0] / sets[j, 1], h - s)
            for k in range(n_head):
                if k == 0 and p == 0:
                    continue
                tk = k * h + s
                v = w * tk**alpha
                for j in range(n_sets):
                    acc[j, k, 0] += v * e[j, 0]
                    acc[j, k, 1] += v * e[j, 1]
                lv = v * np.log(tk)
                acc[n_sets, k, 0] += lv * e[0, 0]
                acc[n_sets, k, 1] += lv * e[0, 1]
    scale = (width / 2.0) ** (1.0 + alpha)
    for i in range(xj.shape[0]):
        s = (xj[i] + 1.0) * width / 2.0
        for j in range(n_sets):
            e0, e1 = transition_b(poles[j, 0], poles[j, 1], 1.0 / np.sqrt(sets[j, 1]), sets[j, 0] / sets[j, 1], h - s)
            acc[j, 0, 0] += wj[i] * scale * e0
            acc[j, 0, 1] += wj[i] * scale * e1
    a0, a1_ = _log_singular_panel(alpha, poles[0, 0], poles[0, 1], 1.0 / np.sqrt(a2), a1 / a2, h, width, xl, wl)
    acc[n_sets, 0, 0] += a0
    acc[n_sets, 0, 1] += a1_
    out = np.empty((4, n_head, 2))
    for k in range(n_head):
        for c in range(2):
            head = acc[0, k, c] / gamma1
            out[0, k, c] = head
            out[1, k, c] = acc[n_sets, k, c] / gamma1 - psi1 * head
            out[2, k, c] = (acc[1, k, c] - acc[2, k, c]) / gamma1 / (2.0 * rel_step * a1)
            out[3, k, c] = (acc[3, k, c] - acc[4, k, c]) / gamma1 / (2.0 * rel_step * a2)
    return out


@njit(cache=CACHE, nogil=True)
def projected_normal_equations(s: np.ndarray, ds: np.ndarray, r: np.ndarray, b: float,
                               free_offset: bool) -> tuple[np.ndarray, np.ndarray]:
    """(J J', J r) of the projected residual's Jacobian J without forming it (two passes, no temporaries).

    J's row k is c0_k s + c1_k - b ds_k (``identification._projected_jacobian``):
    the first pass gathers s.s, sum s, ds_k.s, sum ds_k and ds_k.r, which give
    (c0, c1) from the 2x2 (or 1x1 without the offset) projection; the second
    accumulates J J' and J r. Three parameters (ds of shape (3, n)), spelled
    out in scalars: the loops over rows with small arrays cost 4x more.
    """
    n = ds.shape[1]
    ss = st = 0.0
    sd0 = sd1 = sd2 = dt0 = dt1 = dt2 = rd0 = rd1 = rd2 = 0.0
    for i in range(n):
        si = s[i]
        ri = r[i]
        d0, d1, d2 = ds[0, i], ds[1, i], ds[2, i]
        ss += si * si
        st += si
        sd0 += d0 * si
        sd1 += d1 * si
        sd2 += d2 * si
        dt0 += d0
        dt1 += d1
        dt2 += d2
        rd0 += d0 * ri
        rd1 += d1 * ri
        rd2 += d2 * ri
    sd = np.array([sd0, sd1, sd2])
    dt = np.array([dt0, dt1, dt2])
    rd = np.array([rd0, rd1, rd2])
    c0 = np.zeros(3)
    c1 = np.zeros(3)
    if free_offset:
        det = ss * n - st * st
        if det != 0.0:
            for k in range(3):
                x0 = b * sd[k] - rd[k]
                x1 = b * dt[k]
                c0[k] = (n * x0 - st * x1) / det
                c1[k] = (ss * x1 - st * x0) / det
    elif ss > 0.0:
        for k in range(3):
            c0[k] = (b * sd[k] - rd[k]) / ss
    e0, e1, e2 = c0[0], c0[1], c0[2]
    f0, f1, f2 = c1[0], c1[1], c1[2]
    a00 = a01 = a02 = a11 = a12 = a22 = g0 = g1 = g2 = 0.0
    for i in range(n):
        si = s[i]
        ri = r[i]
        j0 = e0 * si + f0 - b * ds[0, i]
        j1 = e1 * si + f1 - b * ds[1, i]
        j2 = e2 * si + f2 - b * ds[2, i]
        g0 += j0 * ri
        g1 += j1 * ri
        g2 += j2 * ri
        a00 += j0 * j0
        a01 += j0 * j1
        a02 += j0 * j2
        a11 += j1 * j1
        a12 += j1 * j2
        a22 += j2 * j2
    a = np.array([[a00, a01, a02], [a01, a11, a12], [a02, a12, a22]])
    return a, np.array([g0, g1, g2])


#: Taylor degree of ``expm_small`` after scaling to 1-norm <= 1/2: truncation < 0.5^17 / 17! ~ 2e-20.
EXPM_DEGREE = 16


@njit(cache=CACHE, nogil=True)
def _matmul_into(out: np.ndarray, x: np.ndarray, y: np.ndarray) -> None:
    """out = x @ y for small square matrices (real or complex) without allocating.

    Zero entries of x are skipped: Van Loan's augmented matrix and its powers
    are block upper triangular (over half zeros), so this halves the work.
    """
    n = x.shape[0]
    out[:, :] = 0.0
    for i in range(n):
        for k in range(n):
            xik = x[i, k]
            if xik == 0.0:
                continue
            for j in range(n):
                out[i, j] += xik * y[k, j]


@njit(cache=CACHE, nogil=True)
def expm_small(x: np.ndarray) -> np.ndarray:
    """e^x of a small square matrix (real, or complex for the complex step): scaling and squaring with a
    degree-16 Taylor polynomial (Horner).

    scipy.linalg.expm costs ~0.1-0.2 ms per 10 x 10 call in Python overhead; this costs a few
    microseconds. The scaling is chosen from the real part's 1-norm only, so a complex-step
    perturbation ~1e-20 never changes the algorithm's branch and the imaginary part stays the
    exact derivative.
    """
    n = x.shape[0]
    norm = 0.0
    for j in range(n):
        col = 0.0
        for i in range(n):
            col += abs(x[i, j].real)
        norm = max(norm, col)
    squarings = 0
    while norm > 0.5 and squarings < 1000:
        norm *= 0.5
        squarings += 1
    scale = 0.5**squarings
    xs = x * scale
    out = np.zeros_like(xs)
    tmp = np.zeros_like(xs)
    for i in range(n):
        out[i, i] = 1.0
    for m in range(EXPM_DEGREE, 0, -1):      # out = I + xs / m * out, from the highest term down
        _matmul_into(tmp, xs, out)
        for i in range(n):
            for j in range(n):
                out[i, j] = tmp[i, j] / m
            out[i, i] += 1.0
    for _ in range(squarings):
        _matmul_into(tmp, out, out)
        _copy_into(out, tmp)
    return out


@njit(cache=CACHE, nogil=True)
def _copy_into(out: np.ndarray, x: np.ndarray) -> None:
    """out[:, :] = x for arrays of one shape, element by element.

    A slice assignment's shape check formats its error message with numba's string
    functions: that doubles the exponentials' compiled code and the time to load it from the cache.
    """
    for i in range(x.shape[0]):
        for j in range(x.shape[1]):
            out[i, j] = x[i, j]


@njit(cache=CACHE, nogil=True)
def expm_directional(x: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(e^x, D) with D[k] the derivative of e^x in the direction directions[k], by the complex step.

    Im e^(x + i eps E) / eps (Al-Mohy and Higham 2010) is exact to O(eps^2) with
    no cancellation; eps ~1e-20 relative to the size of x over that of E. One
    compiled call instead of a Python loop of exponentials; e^x is
    ``expm_small(x)`` itself, so callers match the plain exponential bit for bit.
    """
    e = expm_small(x)
    size = max(np.max(np.abs(x)), 1e-300)
    out = np.empty(directions.shape)
    for k in range(directions.shape[0]):
        eps = 1e-20 * size / max(np.max(np.abs(directions[k])), 1e-300)
        step = expm_small(x + 1j * eps * directions[k])
        for i in range(step.shape[0]):          # out[k] = step.imag / eps, without a slice assignment
            for j in range(step.shape[1]):
                out[k, i, j] = step[i, j].imag / eps
    return e, out


@njit(cache=CACHE, nogil=True)
def second_differences(y: np.ndarray) -> np.ndarray:
    """``np.diff(y, 2) / sqrt(6)`` bit for bit (the same two subtractions and the division per element)
    in one pass and one buffer: numpy's two passes and temporaries cost ~1 ms per 100,000 samples."""
    n = y.size - 2
    out = np.empty(max(n, 0))
    root6 = np.sqrt(6.0)
    for i in range(n):
        out[i] = ((y[i + 2] - y[i + 1]) - (y[i + 1] - y[i])) / root6
    return out


@njit(cache=CACHE, nogil=True)
def play_rows(u: np.ndarray, r: np.ndarray, p0: np.ndarray) -> np.ndarray:
    """Play (backlash) operator outputs, one row per threshold r_i: p[n] = max(u[n] - r_i, min(u[n] + r_i, p[n-1])),
    p[-1] = p0 (``effects.hysteresis.play_operators``: the same operations, updated where the input changes)."""
    out = np.empty((r.size, u.size))
    p = p0.copy()
    for n in range(u.size):
        if n == 0 or u[n] != u[n - 1]:
            for i in range(r.size):
                p[i] = max(u[n] - r[i], min(u[n] + r[i], p[i]))
        for i in range(r.size):
            out[i, n] = p[i]
    return out


@njit(cache=CACHE, nogil=True)
def first_order_filter(b0: float, b1: float, a1: float, x: np.ndarray) -> np.ndarray:
    """Each row of the 2-d ``x`` through y[n] = b0 x[n] + b1 x[n-1] - a1 y[n-1] from rest: ``scipy.signal.lfilter(
    [b0, b1], [1, a1], x, axis=-1)`` bit for bit (its transposed direct form: the same products and sums in the
    same order), without importing scipy.signal (and scipy.stats with it, ~24 MB resident)."""
    out = np.empty_like(x)
    for r in range(x.shape[0]):
        z = 0.0
        for n in range(x.shape[1]):
            xn = x[r, n]
            yn = z + b0 * xn
            out[r, n] = yn
            z = xn * b1 - yn * a1
    return out
