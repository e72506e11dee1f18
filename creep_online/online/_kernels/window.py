"""Numba kernels of the four-parameter tracker: one regressor, one set of window statistics.

The model output is linear in one regressor ``phi`` whose entries depend on
none of alpha, b or the offset, and on the resonance only through a fixed
*linearization point* ``(a1l, a2l)``:

========================  =====================================================
``phi[0:Q]``              SOE nodes ``zeta_i`` of the input (``soe.py``)
``phi[Q], phi[Q+1]``      ``x = [H2 u, d/dt H2 u]`` at ``(a1l, a2l)`` (ZOH-exact)
``phi[Q+2], phi[Q+3]``    ``dx/da1`` (sensitivity states)
``phi[Q+4], phi[Q+5]``    ``dx/da2``
``phi[Q+6]``              1 (the output offset)
``phi[Q+7:Q+7+M]``        free responses ``exp(-mu_j t)`` (streams that start in
                          operation: the unknown past input's fading memory)
``phi[P-R:]``             drift regressors (R = 0-2): ``tau * pm`` and ``tau * pd``
                          with ``tau = t - t_ref`` (s, <= 0 inside the window after
                          a re-reference), ``pm`` the model part of the prediction
                          and ``pd`` its alpha-derivative at the current estimate
========================  =====================================================

Drift: with the gain and alpha moving linearly inside the window, ``b(t) =
b (1 + beta tau)`` and ``alpha(t) = alpha + alpha_dot tau``, the output is to
first order ``phi . m + beta tau pm + alpha_dot tau pd``. The two drift
columns are *pseudo-linear* regressors (``pm``, ``pd`` are computed with the
estimate of their sample's time, as in extended least squares): they cost two
statistics columns and one extra dot product per sample, and beta (relative
gain rate, 1/s) and alpha_dot (1/s) are two more linear parameters. Moving the
reference ``t_ref`` to the newest sample (``rereference``, at every re-fit)
makes ``alpha`` and ``b`` in theta the values at the newest sample, not the
window averages.

By partial fractions (``kernels.model_coefficients``) the exact output is
``b (zeta . v_z(alpha, a) + x(a) . v_x(alpha, a))``; with ``x(a) = x(al) +
dx/da (a - al)`` to first order the output for *any* (alpha, a1, a2, b, c, d)
near the linearization point is ``phi . m`` with a coefficient vector ``m``
(``coefficients``). The exponentially forgotten statistics ``S = sum g phi
phi^T``, ``sy``, ``syy`` therefore give the window's output-error cost, its
gradient and its Gauss-Newton matrix for all parameters at once, in O(P^2)
(``lm_normal``, ``lm_trial``). The tracker re-linearizes (replays its history) when the
resonance moves away from the linearization point.

Statistics are accumulated with a growing weight ``g = forget^-n`` (no O(P^2)
decay per sample) and renormalised; the true statistics are ``S / g``.

Statistics: ``S`` is symmetric and held in its upper triangle (``j >= i``). Every
reader takes that triangle (``symmetrize``, ``_upper_times``, the fits); below the
diagonal is scratch: the per-sample update fills the whole matrix (its
rectangular loop vectorizes), the block and replay updates only the triangle,
over each row's columns with an unsigned index that LLVM vectorizes (``_columns``).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, uint64

from . import coefficients as kernels
from .coefficients import model_coefficients

CACHE = True

#: A mask value of ``trial_point``: the parameter moves with LINEAR_DAMPING x the others' damping. For the offset
#: and free responses of a stream in operation (``fit_machine.allocate``): the output is linear in them and their
#: columns are nearly collinear over a window (rates 0.01-30 /s against the constant), so the Marquardt damping
#: of the others (mu >= 1e-7 x the diagonal) held their weakest combinations for seconds (mid_operation seed
#: 13 at 80 dB: the window at 1.4-1.5x the floor where the exact optimum at the same estimate was 1.0x). It
#: still grows with mu: a factor that fails (a short window, the columns collinear to rounding) damps them too.
LINEAR = 2.0
LINEAR_DAMPING = 1e-5
#: In the covariance their own block is left out of the condition test (``covariance_inverse``): the free
#: responses' near-collinear block alone put the condition number beyond what the inverse is trusted at
#: (1e13), and every variance, alpha's too, read inf ("not determined") for seconds at the noise floor
#: (mid_operation seeds 1 and 13 at 80 dB: 6.6-7.1 of the last 9 s). Where the factor itself fails in
#: rounding they carry this prior, relative to their own information (``covariance_factor``): it holds their
#: undetermined combinations, so a parameter that leans on them reads a smaller variance than the exact
#: least squares (synthetic step responses on 3-6 s windows: alpha's -13 to -21 %; on 12 s, -0.3 %).
LINEAR_PRIOR = 1e-9

#: Offsets of the regressor entries after the Q SOE nodes (``layout``).
from .layout import (FREE, ONE, RESONANCE, S1, S2, X0, co_at, co_size, free_decay_in_co,  # noqa: E402,F401
                     md_at, offsets, resonance_in_co, ztail_at)
from . import hysteresis as HK  # noqa: E402

# indices into the scalar work array ``sc``
SC_G = 0          # weight of the next sample (forget^-n, renormalised)
SC_FORGET = 1     # forgetting factor per sample
SC_SYY = 2        # sum g y^2
SC_NEFF = 3       # effective number of samples (true scale)
SC_PRED = 4       # prediction of the latest sample
SC_SCALE = 5      # robust scale of the innovations (Huber mean of |e|, times 1.25)
SC_NOISE = 6      # robust scale of the output noise (from second differences)
SC_Y1 = 7         # previous output
SC_Y2 = 8         # output before that
SC_GATE = 9       # gate width in robust scales (0: gate off)
SC_OUTLIERS = 10  # outputs rejected by the gate (count)
SC_RUN = 11       # recent rejections (decaying count, ~20 ms)
SC_BURST = 12     # longest run treated as outliers; longer runs are accepted (a shift)
SC_SHIFTS = 13    # gate-exceeding outputs accepted because rejections were dense
SC_STILL = 14     # consecutive samples with an unchanged output
SC_PMOVE = 15     # |prediction change| accumulated while the output stayed still
SC_SCALEK = 16    # smoothing factor of the robust scales
SC_E2 = 17        # short mean of e^2 (live error monitor)
SC_MONK = 18      # smoothing factor of the live monitor
SC_ACC = 19       # 1: accumulate statistics, 0: states only (frozen / lead-in)
SC_NY = 20        # outputs seen (for the noise estimator's start)
SC_PSTART = 21    # prediction when the output last changed
SC_RPOS = 22      # next write position in the history ring
SC_RCOUNT = 23    # samples in the ring
SC_RSTART = 24    # sample index (since the tracker's start) of the oldest sample in the ring
SC_NQ = 25        # number of SOE nodes Q
SC_N = 26         # samples fed
SC_DUE = 27       # sample count at which the caller has scheduled work (status flag 8)
SC_STUCK = 28     # 1 while the output is frozen although the prediction moves
SC_STUCKN = 29    # samples an output must stay frozen to count as stuck
SC_NM = 30        # number of free-response columns M
SC_A1L = 31       # linearization point a1 of the resonance states
SC_A2L = 32       # linearization point a2
SC_GDECAY = 33    # per-sample decay of the rejection count
SC_SINCE = 34     # samples since the input last changed
SC_HOLD = 35      # after an input change the gate widens for this many samples (two settling times)
SC_BABS = 36      # |b| (set by the caller when the estimate changes)
SC_TSCALE = 37    # |b du| of the last input change: how far a mismatched model can miss a transient
SC_ULAST = 38     # the previous input
SC_REPRATE = 39   # long-run rate of outputs exactly equal to the previous one (~0 for a noisy sensor)
SC_REPK = 40      # smoothing factor of that rate (~10 s)
SC_TREF = 41      # sample index at which the drift regressors' time tau is zero
SC_H = 42         # sampling step (s)
SC_NR = 43        # number of drift columns R (0, 1: gain rate, 2: gain and alpha rates)
SC_NH = 44        # number of hysteresis columns K (``hysteresis.py``; before the drift columns)
SC_SIZE = 45


@njit(cache=CACHE)
def resonance_step(a1: float, a2: float, h: float, out: np.ndarray) -> None:
    """ZOH discretization of 1/(1 + a1 s + a2 s^2) in the state [y, y']: out = Phi (4, row major), Gamma (2).

    Closed form of the 2x2 matrix exponential, A = [[0, 1], [-1/a2, -a1/a2]]:
    e^{Ah} = e^{sh} (c I + k (A - s I)) with s = -a1/(2 a2) and c, k from the
    discriminant (cos/sin, cosh/sinh, or the repeated-root limit).
    Gamma = A^-1 (Phi - I) B with B = [0, 1/a2].
    """
    s = -a1 / (2.0 * a2)
    d = s * s - 1.0 / a2
    if d > 1e-14 * s * s:
        q = math.sqrt(d)
        c = math.cosh(q * h)
        k = math.sinh(q * h) / q
    elif d < -1e-14 * s * s:
        q = math.sqrt(-d)
        c = math.cos(q * h)
        k = math.sin(q * h) / q
    else:
        c = 1.0
        k = h
    e = math.exp(s * h)
    p00 = e * (c - k * s)
    p01 = e * k
    p10 = e * k * (-1.0 / a2)
    p11 = e * (c + k * (-a1 / a2 - s))
    out[0] = p00
    out[1] = p01
    out[2] = p10
    out[3] = p11
    # A^-1 = [[-a1, -a2], [1, 0]]; (Phi - I) B = [p01 / a2, (p11 - 1) / a2]
    b0 = p01 / a2
    b1 = (p11 - 1.0) / a2
    out[4] = -a1 * b0 - a2 * b1
    out[5] = b0


@njit(cache=CACHE)
def resonance_coefficients(a1: float, a2: float, h: float, out: np.ndarray) -> None:
    """``out[0:6]`` Phi, Gamma at (a1, a2); ``out[6:12]`` and ``out[12:18]`` their a1- and a2-derivatives.

    The derivatives are central differences of the closed form (relative step
    1e-5: error ~1e-10, far below what a sensitivity needs).
    """
    resonance_step(a1, a2, h, out[0:6])
    tmp_p = np.empty(6)
    tmp_m = np.empty(6)
    for j in range(2):
        da = (a1 if j == 0 else a2) * 1e-5
        if j == 0:
            resonance_step(a1 + da, a2, h, tmp_p)
            resonance_step(a1 - da, a2, h, tmp_m)
        else:
            resonance_step(a1, a2 + da, h, tmp_p)
            resonance_step(a1, a2 - da, h, tmp_m)
        for i in range(6):
            out[6 + 6 * j + i] = (tmp_p[i] - tmp_m[i]) / (2.0 * da)


@njit(cache=CACHE)
def advance(phi: np.ndarray, co: np.ndarray, q: int, u: float) -> None:
    """Advance the regressor by one sample of the zero-order-held input u (exact for the nodes and x).

    ``co`` = [node decays (Q), node gains (Q), resonance Phi, Gamma and their
    a1-, a2-derivatives (18, ``resonance_coefficients``), free-response decays (M)].
    """
    for i in range(q):
        phi[i] = co[i] * phi[i] + co[q + i] * u
    r = resonance_in_co(q)
    x0 = phi[q]
    x1 = phi[q + 1]
    for j in range(2):
        o = r + 6 + 6 * j
        s0 = phi[q + 2 + 2 * j]
        s1 = phi[q + 3 + 2 * j]
        phi[q + 2 + 2 * j] = co[r] * s0 + co[r + 1] * s1 + co[o] * x0 + co[o + 1] * x1 + co[o + 4] * u
        phi[q + 3 + 2 * j] = co[r + 2] * s0 + co[r + 3] * s1 + co[o + 2] * x0 + co[o + 3] * x1 + co[o + 5] * u
    phi[q] = co[r] * x0 + co[r + 1] * x1 + co[r + 4] * u
    phi[q + 1] = co[r + 2] * x0 + co[r + 3] * x1 + co[r + 5] * u
    f = free_decay_in_co(q)
    for j in range(co.shape[0] - f):
        phi[q + FREE + j] *= co[f + j]


@njit(cache=CACHE)
def coefficients(alpha: float, a1: float, a2: float, a1l: float, a2l: float, lam: np.ndarray,
                 dx: float, k: np.ndarray, dk: np.ndarray) -> None:
    """Unit-gain coefficient vector k (output = b phi . k) and dk/dalpha, for (alpha, a1, a2).

    Only the model part (first Q + 6 entries) is written; the offset and free
    responses are separate linear parameters.
    """
    q = lam.shape[0]
    v = np.empty(q + 2)
    dv = np.empty(q + 2)
    model_coefficients(alpha, lam, dx, a1, a2, v, dv)
    for i in range(q + 2):
        k[i] = v[i]
        dk[i] = dv[i]
    d1 = a1 - a1l
    d2 = a2 - a2l
    for j in range(2):
        k[q + 2 + j] = d1 * v[q + j]
        dk[q + 2 + j] = d1 * dv[q + j]
        k[q + 4 + j] = d2 * v[q + j]
        dk[q + 4 + j] = d2 * dv[q + j]


@njit(cache=CACHE)
def full_coefficients(theta: np.ndarray, a1l: float, a2l: float, lam: np.ndarray, dx: float,
                      m: np.ndarray) -> None:
    """m such that the model output is phi . m; theta = [alpha, ln a1, ln a2, b, c, d_1..d_M]."""
    full_coefficients_into(theta, a1l, a2l, lam, dx, m, np.empty(lam.shape[0] + 2))


@njit(cache=CACHE)
def full_coefficients_into(theta: np.ndarray, a1l: float, a2l: float, lam: np.ndarray, dx: float, m: np.ndarray,
                           v: np.ndarray) -> None:
    """``full_coefficients`` with the caller's scratch v (Q + 2): the re-fit's trial point allocates nothing.
    Only the model's values are computed (``kernels.model_values``): the alpha-derivative that ``coefficients``
    adds took a logarithm per node, for nothing here (with four temporaries, about a third of the slice)."""
    q = lam.shape[0]
    p = m.shape[0]
    a1 = math.exp(theta[1])
    a2 = math.exp(theta[2])
    kernels.model_values(theta[0], lam, dx, a1, a2, v)
    b = theta[3]
    for i in range(q + 2):
        m[i] = b * v[i]
    d1 = a1 - a1l
    d2 = a2 - a2l
    for j in range(2):
        m[q + 2 + j] = b * (d1 * v[q + j])
        m[q + 4 + j] = b * (d2 * v[q + j])
    for i in range(q + ONE, p):
        m[i] = theta[4 + i - q - ONE]


@njit(cache=CACHE)
def drift_coefficients(theta: np.ndarray, a1l: float, a2l: float, lam: np.ndarray, dx: float,
                       md: np.ndarray) -> None:
    """md = b dk/dalpha over the model part (Q + 6 entries): the alpha-derivative of the model output's coefficients."""
    q = lam.shape[0]
    k = np.zeros(q + ONE)
    dk = np.zeros(q + ONE)
    coefficients(theta[0], math.exp(theta[1]), math.exp(theta[2]), a1l, a2l, lam, dx, k, dk)
    b = theta[3]
    for i in range(q + ONE):
        md[i] = b * dk[i]


@njit(cache=CACHE, inline="always")
def parts(st: np.ndarray) -> tuple:
    """(Q, P, m, sy, md) of a state array (``layout``), read from its header: the node count, the
    regressor's length, the model coefficients, the statistics' sy and the alpha-derivative md."""
    q = int(st[SC_NQ])
    nm = int(st[SC_NM])
    nr = int(st[SC_NR]) + int(st[SC_NH])
    p = q + FREE + nm + nr
    o = SC_SIZE
    md = md_at(q, nm, nr)
    return q, p, st[o + p:o + 2 * p], st[o + 2 * p:o + 3 * p], st[md:md + q + ONE]


@njit(cache=CACHE)
def set_estimate(theta: np.ndarray, st: np.ndarray, lam: np.ndarray, dx: float) -> None:
    """The prediction's coefficients m (and md with the alpha rate) for theta, and what the output gate
    needs to know of the estimate: |b| and the settling hold after an input change (two settling
    times, 20 samples to 2 s). One kernel: it runs after every re-fit, when Python glue is cold."""
    sc = st[:SC_SIZE]
    q, p, m, sy, md = parts(st)
    a1l, a2l = sc[SC_A1L], sc[SC_A2L]
    full_coefficients(theta, a1l, a2l, lam, dx, m)
    if int(sc[SC_NR]) > 1:
        drift_coefficients(theta, a1l, a2l, lam, dx, md)
    if int(sc[SC_NH]) > 0:               # the hysteresis columns are unit-gain: they divide by this b (and the start
        nh = int(sc[SC_NH])              # columns weigh the plays with the weights)
        HK.set_gain(st, HK.block_at(q, int(sc[SC_NM]), int(sc[SC_NR]), nh), nh, theta, 5 + int(sc[SC_NM]))
    sc[SC_BABS] = abs(theta[3])
    settle = 8.0 * math.exp(theta[2]) / math.exp(theta[1])
    h = sc[SC_H]
    sc[SC_HOLD] = min(max(20.0, 2.0 * settle / h), 2.0 / h)


@njit(cache=CACHE)
def rereference(st: np.ndarray, S: np.ndarray, n_new: float) -> None:
    """Move the drift columns' time origin to sample ``n_new`` in the statistics (S, sy).

    A drift column is ``tau * h`` with the helper ``h = phi . v`` (``v`` = the
    model coefficients m, or md for alpha); moving the origin by T seconds is
    ``tau * h - T h``, a linear map of the regressor, applied here to S and sy
    with the helper statistics ``S v`` computed from the current v (the same
    pseudo-linear approximation as the columns themselves).
    """
    sc = st[:SC_SIZE]
    nr = int(sc[SC_NR])
    t = (n_new - sc[SC_TREF]) * sc[SC_H]
    sc[SC_TREF] = n_new
    if nr == 0 or t == 0.0:
        return
    q, p, m, sy, md = parts(st)
    nv = q + ONE
    V = np.zeros((nv, nr))
    V[:, 0] = m[:nv]
    if nr > 1:
        V[:, 1] = md
    Gt = np.empty((nr, p))           # (full(S) @ V)^T, from the upper triangle
    _upper_times(S, V, Gt)
    vg = np.zeros((nr, nr))
    for k in range(nr):
        for l in range(nr):
            for j in range(nv):
                vg[k, l] += V[j, k] * Gt[l, j]
    r0 = p - nr
    for l in range(nr):
        j = r0 + l
        for i in range(j + 1):
            v = S[i, j] - t * Gt[l, i]
            if i >= r0:
                k = i - r0
                v += -t * Gt[k, j] + t * t * vg[k, l]
            S[i, j] = v
            S[j, i] = v                  # the statistics are kept whole (see _accumulate)
    vs = np.zeros(nr)
    for k in range(nr):
        for j in range(nv):
            vs[k] += V[j, k] * sy[j]
    for k in range(nr):
        sy[r0 + k] -= t * vs[k]


@njit(cache=CACHE)
def _upper_times(S: np.ndarray, V: np.ndarray, Gt: np.ndarray) -> None:
    """Gt = (full(S)[:, :n] @ V)^T (n = rows of V, one or two columns) from S's upper triangle; each
    sum over j in ascending order.

    One pass over S with the sums in local variables: written as ``G[i, k] += ...`` in the innermost
    loop, the compiler kept them in memory (the arrays might alias) and the 51 x 48 x 2 product took
    ~18 us, more than a whole Levenberg-Marquardt step; this takes ~2 us."""
    n, nr = V.shape
    p = Gt.shape[1]
    two = nr > 1
    for i in range(p):
        t0 = 0.0
        t1 = 0.0
        for j in range(min(i, n)):       # below the diagonal: S[j, i]
            sij = S[j, i]
            t0 += sij * V[j, 0]
            if two:
                t1 += sij * V[j, 1]
        for j in range(i, n):
            sij = S[i, j]
            t0 += sij * V[j, 0]
            if two:
                t1 += sij * V[j, 1]
        Gt[0, i] = t0
        if two:
            Gt[1, i] = t1


@njit(cache=CACHE)
def move_origin(st: np.ndarray, S: np.ndarray, shift: np.ndarray) -> None:
    """Move the drift columns' time origin to the newest sample (``rereference``: alpha and b of the next
    fit are then the values now) and add the move to ``shift`` (rows 0..Q+5, one column per rate), the
    running total the change test brings its snapshot up to. A kernel rather than numpy steps: run once
    per re-fit, the interpreter's and numpy's code paths are cold by then, and those few lines cost
    ~80 us at 10 kHz."""
    sc = st[:SC_SIZE]
    nr = int(sc[SC_NR])
    n_new = sc[SC_N]
    t = (n_new - sc[SC_TREF]) * sc[SC_H]
    if nr > 0 and t != 0.0:
        q, p, m, sy, md = parts(st)
        for i in range(q + ONE):
            shift[i, 0] += t * m[i]
        if nr > 1:
            for i in range(q + ONE):
                shift[i, 1] += t * md[i]
    rereference(st, S, n_new)


@njit(cache=CACHE)
def scaled_statistics(st: np.ndarray, S: np.ndarray, F: np.ndarray, fy: np.ndarray) -> float:
    """F = S / g (full symmetric, from the upper triangle), fy = sy / g; returns fyy = syy / g."""
    sc = st[:SC_SIZE]
    q, p, m, sy, md = parts(st)
    g = sc[SC_G]
    symmetrize(S, F, 1.0 / g)
    for i in range(p):
        fy[i] = sy[i] / g
    return sc[SC_SYY] / g


@njit(cache=CACHE)
def snapshot(st: np.ndarray, S: np.ndarray, shift: np.ndarray, theta: np.ndarray, S0: np.ndarray,
             sy0: np.ndarray, shift0: np.ndarray, theta0: np.ndarray) -> tuple:
    """Copy what the change test needs of this instant into preallocated arrays; returns (syy, g).

    Runs on the per-sample path every ``test_every`` samples: four numpy copies from Python cost
    ~50 us there (cold code), this ~3 us. Only S's upper triangle is copied (all ``since_statistics``
    reads): half the memory written into a slot that is cold by then."""
    sc = st[:SC_SIZE]
    q, p, m, sy, md = parts(st)
    for i in range(p):
        for j in range(i, p):
            S0[i, j] = S[i, j]
    sy0[:] = sy
    shift0[:, :] = shift
    theta0[:] = theta
    return sc[SC_SYY], sc[SC_G]


@njit(cache=CACHE)
def since_statistics(st: np.ndarray, S: np.ndarray, S0: np.ndarray, sy0: np.ndarray, syy0: float,
                     shift: np.ndarray, shift0: np.ndarray, R: np.ndarray, ry: np.ndarray) -> float:
    """Statistics of the samples since a snapshot (S0, sy0, syy0, shift0; S0's upper triangle) at true scale, for
    the change test: R (full symmetric), ry; returns ryy. ``since_difference`` at this instant, then
    ``since_finish`` (the change test runs them as two slices: only the first reads the live statistics)."""
    ryy = since_difference(st, S, S0, sy0, syy0, R, ry)
    return since_finish(st, S0, sy0, shift, shift0, R, ry, ryy, st[SC_G])


@njit(cache=CACHE)
def since_difference(st: np.ndarray, S: np.ndarray, S0: np.ndarray, sy0: np.ndarray, syy0: float,
                     R: np.ndarray, ry: np.ndarray) -> float:
    """The live statistics minus a snapshot's, as accumulated (weight g, the snapshot at its own drift origin):
    R's upper triangle, ry; returns ryy."""
    q, p, m, sy, md = parts(st)
    for i in range(p):
        for j in range(i, p):
            R[i, j] = S[i, j] - S0[i, j]
        ry[i] = sy[i] - sy0[i]
    return st[SC_SYY] - syy0


@njit(cache=CACHE)
def since_finish(st: np.ndarray, S0: np.ndarray, sy0: np.ndarray, shift: np.ndarray, shift0: np.ndarray,
                 R: np.ndarray, ry: np.ndarray, ryy: float, g: float) -> float:
    """``since_difference``'s result with the snapshot moved to the live drift origin and scaled by the weight g
    of its instant: R full symmetric, ry, and the returned ryy at true scale. Reads only the state's sizes.
    ``since_moved``, then ``since_scaled`` over every row (the change test runs them as slices)."""
    since_moved(st, S0, sy0, shift, shift0, R, ry)
    return since_scaled(R, ry, ryy, g, 0, R.shape[0])


@njit(cache=CACHE)
def since_moved(st: np.ndarray, S0: np.ndarray, sy0: np.ndarray, shift: np.ndarray, shift0: np.ndarray,
                R: np.ndarray, ry: np.ndarray) -> None:
    """The first part of ``since_finish``: the snapshot moved to the live drift origin (R's upper triangle, ry).

    A move of the origin is the regressor map x -> x (I - E), E holding t v in the rate columns' rows
    0..nv-1; two such maps compose additively (E fills only rate columns and reads none: E_i E_j = 0), so
    every move since the snapshot is one map with D = shift - shift0, applied as ``rereference`` applies
    one; only the rate rows and columns change.
    """
    sc = st[:SC_SIZE]
    nr = int(sc[SC_NR])
    q, p, m, sy, md = parts(st)
    if nr > 0:
        nv, r0 = q + ONE, p - nr
        D = shift - shift0
        G = np.empty((p, nr))            # full(S0)[:, :nv] @ D from S0's upper triangle (``_upper_times``)
        for i in range(p):
            for k in range(nr):
                t = 0.0
                for j in range(min(i, nv)):
                    t += S0[j, i] * D[j, k]
                for j in range(i, nv):
                    t += S0[i, j] * D[j, k]
                G[i, k] = t
        for k in range(nr):              # dS[:, r0:] += G, dS[r0:, :] += G^T, dS[r0:, r0:] -= D^T G[:nv]
            j = r0 + k
            for i in range(j + 1):
                v = R[i, j] + G[i, k]
                if i >= r0:
                    c = 0.0
                    for l in range(nv):
                        c += D[l, i - r0] * G[l, k]
                    v += G[j, i - r0] - c
                R[i, j] = v
            c = 0.0
            for l in range(nv):
                c += D[l, k] * sy0[l]
            ry[j] += c


@njit(cache=CACHE)
def since_scaled(R: np.ndarray, ry: np.ndarray, ryy: float, g: float, i0: int, i1: int) -> float:
    """The last part of ``since_finish``, rows i0..i1: R's upper triangle mirrored and R, ry scaled by 1/g (the
    weight of the snapshot's instant); returns ryy / g. Rows are independent (row i writes R[i, i:] and
    R[i:, i], reads only R[i, i:])."""
    inv = 1.0 / g
    for i in range(i0, i1):
        for j in range(i, R.shape[0]):
            v = R[i, j] * inv
            R[i, j] = v
            R[j, i] = v
        ry[i] = ry[i] / g
    return ryy / g


@njit(cache=CACHE)
def warm_rows(A: np.ndarray, B: np.ndarray, i0: int, i1: int) -> float:
    """Rows i0..i1 of A read (their sum returned: a value the caller keeps, so the reads stay) and of B zeroed:
    brings a cold operand and a cold target of a stage that must run in one slice into the cache a few samples
    ahead, in slices (the re-fit's frozen statistics F, a change test's snapshot and its difference)."""
    s = 0.0
    for i in range(i0, i1):
        for j in range(A.shape[1]):
            s += A[i, j]
        for j in range(B.shape[1]):
            B[i, j] = 0.0
    return s


@njit(cache=CACHE)
def gn_gain(H: np.ndarray, g: np.ndarray, mask: np.ndarray, A: np.ndarray, r: np.ndarray, x: np.ndarray) -> float:
    """g^T H^-1 g over the parameters with mask != 0 (the cost reduction of a full Gauss-Newton step); 0 if singular.
    (``_gain`` without a prior.)"""
    return _gain(H, g, mask, A, r, x, 0.0)


@njit(cache=CACHE)
def linear_gain(H: np.ndarray, g: np.ndarray, mask: np.ndarray, A: np.ndarray, r: np.ndarray, x: np.ndarray) -> float:
    """``gn_gain`` with the ``LINEAR`` parameters' relative prior LINEAR_PRIOR (the covariance's where its factor
    fails): eight free responses are nearly collinear over a window (their block alone put the covariance's
    condition beyond 1e13, 5b0c485), so a pivot may fall below 1e-13, where ``gn_gain`` reads 0 (the wide
    test's two gains, ``refit``; both with the same prior)."""
    return _gain(H, g, mask, A, r, x, LINEAR_PRIOR)


@njit(cache=CACHE)
def _gain(H: np.ndarray, g: np.ndarray, mask: np.ndarray, A: np.ndarray, r: np.ndarray, x: np.ndarray,
          prior: float) -> float:
    """g^T H^-1 g over the parameters with mask != 0 (the cost reduction of a full Gauss-Newton step); 0 if singular.
    ``prior`` (> 0) is added to the scaled diagonal of the parameters whose mask is ``LINEAR``.

    In preallocated scratch (A: k x k, r and x: k, k = H's size) with a hand-written Cholesky: the score test
    runs inside the per-sample kernel's slices, where LAPACK's eigvalsh and solve (numba's wrappers allocate and
    check) took 58-120 us with cold caches, one call over 25 us every fifth calm re-fit. H is scaled to a unit
    diagonal first; "singular" is a Cholesky pivot at or below 1e-13 (every pivot is at least the smallest
    eigenvalue, and the largest is at least 1: what passed the former eigenvalue test, ratio above 1e-13,
    passes this one).
    """
    n = 0
    for i in range(mask.shape[0]):
        if mask[i] != 0.0 and H[i, i] != 0.0:
            x[n] = i                     # the free parameters' indices (x is overwritten by the solve below)
            n += 1                       # (one whose column is zero over the window adds nothing: g[i] = 0 too)
    for a in range(n):
        ia = int(x[a])
        da = math.sqrt(abs(H[ia, ia])) + 1e-300
        r[a] = g[ia] / da
        for c in range(a + 1):
            ic = int(x[c])
            dc = math.sqrt(abs(H[ic, ic])) + 1e-300
            v = H[ia, ic] / (da * dc) if da * dc > 0.0 else H[ia, ic] / da / dc   # (da dc may underflow)
            if not math.isfinite(v) or not math.isfinite(r[a]):
                return 0.0
            A[a, c] = v
        if prior > 0.0 and mask[ia] == LINEAR:
            A[a, a] += prior
    if not cholesky_factor(A, A, n, 1e-13):   # in place: the lower triangle becomes the factor
        return 0.0
    forward_substitution(A, r, x, n)     # L z = r (z in x)
    gain = 0.0                           # r^T (L L^T)^-1 r = |z|^2
    for i in range(n):
        gain += x[i] * x[i]
    return gain if math.isfinite(gain) else 0.0


@njit(cache=CACHE)
def drift_gain(H: np.ndarray, g: np.ndarray, free: np.ndarray, r0: int, rates: bool, A: np.ndarray,
               mask: np.ndarray, r: np.ndarray, x: np.ndarray) -> float:
    """One half of ``drift_score``: the Gauss-Newton gain over ``free`` (its entries from r0 on ignored) with the
    drift rates (parameters r0..) freed (``rates``) or fixed; scratch A (k x k), mask, r, x (k each)."""
    k = H.shape[0]
    for i in range(k):
        mask[i] = free[i] if i < r0 else (1.0 if rates else 0.0)
    return gn_gain(H, g, mask, A, r, x)


@njit(cache=CACHE)
def drift_score(H: np.ndarray, g: np.ndarray, free: np.ndarray, r0: int) -> float:
    """Cost reduction that freeing the drift rates (parameters r0..) would add to a Gauss-Newton step.

    ``free`` marks the parameters fitted without the rates (their entries from r0 on are ignored).
    """
    k = H.shape[0]
    A, mask, r, x = np.empty((k, k)), np.empty(k), np.empty(k), np.empty(k)
    return drift_gain(H, g, free, r0, True, A, mask, r, x) - drift_gain(H, g, free, r0, False, A, mask, r, x)


def layout(q: int, n_free: int, n_rate: int = 0, n_hyst: int = 0) -> dict:
    """Offsets of the parts of the flat state array ``st`` (one array: fewer arguments per numba call).

    ``st`` = [scalars (SC_SIZE) | regressor phi (P) | coefficients m (P) | sy (P) |
    co (2Q + 18 + M: node decays and gains, resonance, free-response decays) |
    ztail (Q: node states before the oldest remembered sample) |
    md (Q + 6: alpha-derivative of the model coefficients, b dk/dalpha) |
    hyst (the hysteresis columns' block, ``hysteresis.py``; none without them)].
    """
    return offsets(q, n_free, n_rate, n_hyst)


@njit(cache=CACHE)
def start_state(st: np.ndarray, decay: np.ndarray, gain: np.ndarray, free_decay: np.ndarray, forget: float,
                h: float, a1l: float, a2l: float, n_rate: int, n_hyst: int = 0) -> None:
    """A fresh state array's header, coefficients and constant regressor entries (both trackers; the parts at
    ``layout``'s offsets). One kernel: the trackers' jobs build fresh states from cold Python.

    ``decay``/``gain``: the SOE nodes' per-sample decay and input gain; ``free_decay``: the free
    responses' per-sample decay; the resonance coefficients at the linearization point (a1l, a2l); ``n_hyst``
    hysteresis columns (``hysteresis.py``: their thresholds are set apart).
    """
    q, n_free = decay.shape[0], free_decay.shape[0]
    st[SC_NQ] = q
    st[SC_NM] = n_free
    st[SC_G] = 1.0
    st[SC_FORGET] = forget
    st[SC_H] = h
    st[SC_NR] = n_rate
    st[SC_NH] = n_hyst
    co = co_at(q, n_free, n_rate + n_hyst)
    st[co:co + q] = decay
    st[co + q:co + 2 * q] = gain
    f = co + free_decay_in_co(q)
    st[f:f + n_free] = free_decay
    linearize(st, a1l, a2l)
    st[SC_SIZE + q + ONE] = 1.0
    st[SC_SIZE + q + FREE:SC_SIZE + q + FREE + n_free] = 1.0


@njit(cache=CACHE)
def replay_origin(st: np.ndarray, ztail: np.ndarray, free_rates: np.ndarray, oldest: int, tref: float) -> None:
    """A replay's fresh state (``start_state``) placed at the ring's oldest remembered sample: the node states the
    ring's tail holds, the free responses decayed to that sample (rates in 1/s), its index and the drift origin.
    One kernel: as numpy from cold Python, in the replay's set-up, ~30 us of one update()."""
    q = ztail.shape[0]
    h = st[SC_H]
    phi = SC_SIZE
    for i in range(q):
        st[phi + i] = ztail[i]
    for j in range(free_rates.shape[0]):
        st[phi + q + FREE + j] = math.exp(-free_rates[j] * h * oldest)
    st[SC_N] = oldest
    st[SC_TREF] = tref


@njit(cache=CACHE)
def linearize(st: np.ndarray, a1l: float, a2l: float) -> None:
    """A fresh state array's linearization point (a1l, a2l) and its resonance coefficients (``start_state``'s
    part that depends on the estimate)."""
    q = int(st[SC_NQ])
    res = co_at(q, int(st[SC_NM]), int(st[SC_NR]) + int(st[SC_NH])) + resonance_in_co(q)
    st[SC_A1L] = a1l
    st[SC_A2L] = a2l
    resonance_coefficients(a1l, a2l, st[SC_H], st[res:res + RESONANCE])


@njit(cache=CACHE)
def start_at(values: np.ndarray, theta: np.ndarray, copy: np.ndarray, st: np.ndarray, lam: np.ndarray,
             dx: float) -> None:
    """theta = ``values`` padded with zeros (and into ``copy``), and a fresh state array linearized at its
    resonance with its coefficients (``linearize``, ``set_estimate``): one kernel for the tracker's start, in
    the update() that ends the start-up search (numba's exp is libm's, as math.exp)."""
    theta[:] = 0.0
    theta[:values.shape[0]] = values
    copy[:] = theta
    linearize(st, math.exp(theta[1]), math.exp(theta[2]))
    set_estimate(theta, st, lam, dx)


def set_monitors(sc: np.ndarray, h: float, gate: float, burst: int, stuck: int) -> None:
    """The output gate, the stuck-output test and the monitors' smoothing (both trackers), statistics on."""
    sc[SC_GATE] = gate
    sc[SC_BURST] = burst
    sc[SC_GDECAY] = math.exp(-1.0 / max(5.0, 0.02 / h))
    sc[SC_STUCKN] = stuck
    sc[SC_SCALEK] = min(1.0, h / 0.5)
    sc[SC_MONK] = min(1.0, h / 0.2)
    sc[SC_REPK] = min(1.0, h / 10.0)
    sc[SC_ACC] = 1.0


#: The online kernels' fast-math flags: none. With reassociation or contraction a kernel's machine code depends on
#: whether the kernels it calls were compiled in the same process (and inlined) or loaded from numba's cache, and on
#: whether the CPU fuses multiply-adds, so the same record would give estimates that differ by ~1e-7 (and decisions
#: that hang on those bits) with the cache's history and the machine. IEEE arithmetic makes every estimate a function
#: of the data alone (``tests/test_online_reproducible.py``).
FAST: set[str] = set()


@njit(cache=CACHE, inline="always")
def _columns(i: int, p: int) -> range:
    """Columns i to p - 1 as an unsigned range: numba wraps a signed index that may be negative (a select per
    access), which keeps LLVM from vectorizing a loop that does not start at 0; an unsigned one cannot be."""
    return range(uint64(i), uint64(p))


@njit(cache=CACHE, fastmath=FAST)
def _accumulate(y: float, phi: np.ndarray, S: np.ndarray, sy: np.ndarray, sc: np.ndarray) -> None:
    """S += g phi phi^T, sy += g phi y, with the growing weight g = forget^-n.

    The whole matrix, not its upper triangle: the rectangular loop vectorizes
    and takes about a third of the time of the scalar triangular one (0.35 vs 1.0 us
    at P = 49), although it does twice the multiply-adds; rows this short, one
    at a time, gain nothing from a vectorized triangle (``_columns``): 1.0 vs 0.6 us.
    """
    p = phi.shape[0]
    f = sc[SC_FORGET]
    g = sc[SC_G]
    if f < 1.0:
        g = g / f
        if g > 1e100:
            _rescale(S, sy, sc, 1.0 / g)
            g = 1.0
        sc[SC_G] = g
    for i in range(p):
        gi = g * phi[i]
        sy[i] += gi * y
        for j in range(p):
            S[i, j] += gi * phi[j]
    sc[SC_SYY] += g * y * y
    sc[SC_NEFF] = sc[SC_NEFF] * f + 1.0


#: Second differences (evenly spread over the start-up buffer) whose median starts the noise monitor (``noise_seed``).
NOISE_SEED_ROWS = 2048


@njit(cache=CACHE)
def noise_seed(y: np.ndarray, n: int, scratch: np.ndarray) -> float:
    """The output noise's standard deviation from the median absolute second difference of up to NOISE_SEED_ROWS
    samples spread over y[:n] (the start-up buffer; ``scratch`` holds them): where the monitor (``_monitor``)
    starts. A buffer that opens with a step's transient (a record whose input moves at its first samples) made the
    monitor start at the transient's second differences, up to 5x the noise, shrinking over seconds; the window
    read "good" at 0.4x that floor with alpha 18 % off (close unmodelled modes). Outputs that are NaN are skipped;
    0 without enough of them. In two calls (``noise_differences``, then ``noise_level``) where each must be short."""
    return noise_level(scratch, noise_differences(y, n, scratch))


@njit(cache=CACHE)
def noise_differences(y: np.ndarray, n: int, scratch: np.ndarray) -> int:
    """``noise_seed``'s first half: the absolute second differences of up to NOISE_SEED_ROWS samples spread over
    y[:n], NaN skipped, into ``scratch``; returns how many."""
    m = min(NOISE_SEED_ROWS, scratch.shape[0], n - 2)
    if m < 8:
        return 0
    step = (n - 2) / m
    k = 0
    for j in range(m):
        i = int(j * step) + 2
        d = abs(y[i] - 2.0 * y[i - 1] + y[i - 2])
        if d == d:
            scratch[k] = d
            k += 1
    return k


@njit(cache=CACHE)
def noise_level(scratch: np.ndarray, k: int) -> float:
    """``noise_seed``'s second half: the noise's standard deviation from the median of scratch[:k] (0 if k < 8),
    selected in place (scratch[:k] is reordered): ``np.median``'s copy and its two selections were ~25 us of one
    update() at the tracker's start."""
    k = min(k, scratch.shape[0])          # (compiled code does not check bounds)
    if k < 8:
        return 0.0
    half = k // 2
    upper = _select(scratch, half, k)
    if k % 2:
        median = upper
    else:                                  # (the lower middle: the largest of the half below the selected one)
        lower = scratch[0]
        for i in range(1, half):
            if scratch[i] > lower:
                lower = scratch[i]
        median = (lower + upper) / 2
    return median / (0.6745 * math.sqrt(6.0))


@njit(cache=CACHE)
def _select(a: np.ndarray, j: int, n: int) -> float:
    """The j-th smallest of a[:n] (0-based), by quickselect in place: afterwards a[:j] holds the ones at or below
    it. The partitions are branch-free (Lomuto's with the swap always made and the boundary advanced by the
    comparison's 0 or 1): on noise, whose comparisons no predictor can learn, a branching partition spent ~25 us of
    one update() in mispredictions. Values equal to the pivot are gathered next to it (a buffer of ties, e.g. a
    quantized output at rest, stays linear). Median-of-three pivots; no NaN (the caller skips them)."""
    lo, hi = 0, n - 1
    while lo < hi:
        mid = (lo + hi) // 2               # the median of a[lo], a[mid], a[hi] as the pivot, moved to a[hi]
        if a[mid] < a[lo]:
            a[mid], a[lo] = a[lo], a[mid]
        if a[hi] < a[lo]:
            a[hi], a[lo] = a[lo], a[hi]
        if a[mid] < a[hi]:
            a[mid], a[hi] = a[hi], a[mid]
        pivot = a[hi]
        s = lo
        for i in range(lo, hi):            # a[lo:s] < pivot <= a[s:i]
            v = a[i]
            a[i] = a[s]
            a[s] = v
            s += v < pivot
        a[hi] = a[s]
        a[s] = pivot
        if j < s:
            hi = s - 1
            continue
        e = s + 1
        for i in range(s + 1, hi + 1):     # the ties next to the pivot: a[s:e] == pivot <= a[e:i]
            v = a[i]
            a[i] = a[e]
            a[e] = v
            e += v <= pivot
        if j < e:
            return pivot
        lo = e
    return a[lo]


@njit(cache=CACHE)
def oldest_mark(at: np.ndarray) -> int:
    """The index of the smallest entry of ``at`` (the first if tied): the node mark to overwrite (-1 unused)."""
    row = 0
    for r in range(1, at.shape[0]):
        if at[r] < at[row]:
            row = r
    return row


@njit(cache=CACHE)
def newest_mark(at: np.ndarray, oldest: int, latest: int) -> int:
    """The index of the largest entry of ``at`` within [oldest, latest], or -1 (the node marks' samples, -1 unused)."""
    row, newest = -1, -1
    for r in range(at.shape[0]):
        a = at[r]
        if oldest <= a <= latest and a > newest:
            row, newest = r, a
    return row


def restart_monitors(sc: np.ndarray, noise: float) -> None:
    """The output monitors as at a stream's first sample, the noise level at ``noise``: after samples that are not the
    sensor's (a lead-in of still outputs: no noise, every output a repeat)."""
    sc[SC_NOISE] = noise
    sc[SC_STILL] = 0.0
    sc[SC_PMOVE] = 0.0
    sc[SC_REPRATE] = 0.0


@njit(cache=CACHE, fastmath=FAST)
def _monitor(y: float, pred: float, sc: np.ndarray) -> None:
    """Noise floor (second differences), frozen-output detector."""
    if sc[SC_NY] >= 2.0:
        d2 = abs(y - 2.0 * sc[SC_Y1] + sc[SC_Y2]) * 0.5117    # sqrt(pi/2)/sqrt(6): white noise
        nz = sc[SC_NOISE]
        if nz > 0.0:
            sc[SC_NOISE] = nz + sc[SC_SCALEK] * (min(d2, 3.0 * nz) - nz)
        else:
            sc[SC_NOISE] = d2
    repeat = sc[SC_NY] >= 1.0 and y == sc[SC_Y1]
    sc[SC_REPRATE] += sc[SC_REPK] * ((1.0 if repeat else 0.0) - sc[SC_REPRATE])
    if repeat:
        sc[SC_STILL] += 1.0
        sc[SC_PMOVE] = max(sc[SC_PMOVE], abs(pred - sc[SC_PSTART]))
        moved = sc[SC_PMOVE] > 5.0 * sc[SC_NOISE] + 1e-300
        # a sensor whose outputs almost never repeat exactly does not repeat for STUCKN samples
        # while the input or the prediction moves: frozen, even if only creep moves the model
        rate = sc[SC_REPRATE] - sc[SC_STILL] * sc[SC_REPK]      # without the current run
        implausible = rate < 0.02 and (sc[SC_SINCE] < sc[SC_STILL]
                                       or sc[SC_PMOVE] > 0.5 * sc[SC_NOISE] + 1e-300)
        sc[SC_STUCK] = 1.0 if sc[SC_STILL] >= sc[SC_STUCKN] and (moved or implausible) else 0.0
    else:
        sc[SC_STILL] = 0.0
        sc[SC_PMOVE] = 0.0
        sc[SC_PSTART] = pred
        sc[SC_STUCK] = 0.0
    sc[SC_Y2] = sc[SC_Y1]
    sc[SC_Y1] = y
    sc[SC_NY] += 1.0


@njit(cache=CACHE, fastmath=FAST)
def _drift_regressors(phi: np.ndarray, m: np.ndarray, md: np.ndarray, sc: np.ndarray, q: int, p: int,
                      nr: int) -> float:
    """Set the drift columns of phi for the sample with index ``sc[SC_N]``; returns the model part of the prediction."""
    pm = 0.0
    for i in range(q + ONE):
        pm += phi[i] * m[i]
    if nr > 0:
        tau = (sc[SC_N] - sc[SC_TREF]) * sc[SC_H]
        phi[p - nr] = tau * pm
        if nr > 1:
            pd = 0.0
            for i in range(q + ONE):
                pd += phi[i] * md[i]
            phi[p - nr + 1] = tau * pd
    return pm


@njit(cache=CACHE, fastmath=FAST)
def gate(y: float, pred: float, sc: np.ndarray) -> int:
    """Monitor the output, gate it on its innovation, update the robust scales (shared by both trackers).

    Returns 0 accepted, 2 rejected as an outlier, 3 beyond the gate but
    accepted (rejections were dense: a shift or a change, not an outlier).
    """
    status = 0
    e = y - pred
    scale = sc[SC_SCALE]
    _monitor(y, pred, sc)
    width = sc[SC_GATE] * scale
    if sc[SC_SINCE] < sc[SC_HOLD]:
        # just after an input step a model that is slightly off misses the transient by up to
        # about its size: those samples are the informative ones, not outliers
        width += 2.0 * sc[SC_TSCALE]
    sc[SC_RUN] *= sc[SC_GDECAY]
    if sc[SC_GATE] > 0.0 and scale > 0.0 and abs(e) > width:
        # isolated outliers are rejected; dense rejections (a burst longer than SC_BURST within
        # ~20 ms, or a model that no longer fits) are accepted: a shift or a change is followed
        if sc[SC_RUN] < sc[SC_BURST]:
            sc[SC_OUTLIERS] += 1.0
            status = 2
        else:
            sc[SC_SHIFTS] += 1.0
            status = 3
        sc[SC_RUN] += 1.0
    if status != 2:
        a = abs(e)
        if scale > 0.0:
            sc[SC_SCALE] = scale + sc[SC_SCALEK] * (1.25 * min(a, 4.0 * scale) - scale)
        else:
            sc[SC_SCALE] = 1.25 * a
        sc[SC_E2] += sc[SC_MONK] * (e * e - sc[SC_E2])
    return status


@njit(cache=CACHE, fastmath=FAST)
def note_input(u: float, sc: np.ndarray) -> None:
    """Input bookkeeping for the gate: samples since the last input change and that change's size."""
    if u != sc[SC_ULAST]:
        sc[SC_TSCALE] = sc[SC_BABS] * abs(u - sc[SC_ULAST])
        sc[SC_ULAST] = u
        sc[SC_SINCE] = 0.0
    else:
        sc[SC_SINCE] += 1.0



@njit(cache=CACHE, fastmath=FAST)
def sample(u: float, y: float, st: np.ndarray, S: np.ndarray, ring: np.ndarray) -> int:
    """One sample: predict, gate, accumulate, monitor, remember, advance. Returns a status code.

    Low bits: 0 accepted, 1 output missing (NaN), 2 rejected as an outlier, 3
    beyond the gate but accepted (rejections were dense: a shift or a change,
    not an outlier), 4 not accumulated (statistics paused). Flag 8: the caller's
    scheduled work is due (``sc[SC_DUE]`` reached). The input and the output as
    used (NaN when not accumulated) go into the history ``ring`` (2 x H).
    """
    sc = st[:SC_SIZE]
    q = int(sc[SC_NQ])
    nr = int(sc[SC_NR])
    nh = int(sc[SC_NH])
    p = q + FREE + int(sc[SC_NM]) + nh + nr
    o = SC_SIZE
    phi = st[o:o + p]
    m = st[o + p:o + 2 * p]
    sy = st[o + 2 * p:o + 3 * p]
    c0 = co_at(q, int(sc[SC_NM]), nr + nh)
    co = st[c0:c0 + co_size(q, int(sc[SC_NM]))]
    ztail = st[c0 + co.shape[0]:c0 + co.shape[0] + q]
    ho = c0 + co.shape[0] + 2 * q + ONE         # the hysteresis block (``hysteresis.block_at``)
    if nh > 0:
        HK.columns(st, ho, nh, q, phi, p - nr - nh, m)
    pred = _drift_regressors(phi, m, st[c0 + co.shape[0] + q:c0 + co.shape[0] + 2 * q + ONE], sc, q, p, nr)
    for i in range(q + ONE, p):
        pred += phi[i] * m[i]
    sc[SC_PRED] = pred
    status = 0
    if y != y:
        status = 1
    else:
        status = gate(y, pred, sc)
        if status != 2:
            if sc[SC_ACC] > 0.0 and sc[SC_STUCK] == 0.0:
                _accumulate(y, phi, S, sy, sc)
            elif status == 0:
                status = 4
    return status + _move_on(u, y, status, st, ho, nh, q, co, phi, sc, ring, ztail)


@njit(cache=CACHE)
def state_finite(theta: np.ndarray, S: np.ndarray, sc: np.ndarray) -> bool:
    """Are a tracker's estimate, its statistics' diagonal and its live prediction all finite (the estimator's error
    contract checks it at each scheduled re-fit or test)? One kernel: numpy's reductions from Python, cold by
    the time a scheduled call comes, took 38 us median and up to 81 us of that update()."""
    if not math.isfinite(sc[SC_PRED]):
        return False
    for i in range(theta.shape[0]):
        if not math.isfinite(theta[i]):
            return False
    for i in range(S.shape[0]):
        if not math.isfinite(S[i, i]):
            return False
    return True


@njit(cache=CACHE)
def _remember(u: float, y: float, co: np.ndarray, q: int, sc: np.ndarray, ring: np.ndarray,
              ztail: np.ndarray) -> None:
    size = ring.shape[1]
    pos = int(sc[SC_RPOS])
    if sc[SC_RCOUNT] >= size:   # the oldest sample leaves: the tail state absorbs it
        old = ring[0, pos]
        for i in range(q):
            ztail[i] = co[i] * ztail[i] + co[q + i] * old
        sc[SC_RSTART] += 1.0
    else:
        sc[SC_RCOUNT] += 1.0
    ring[0, pos] = u
    ring[1, pos] = y
    pos += 1
    sc[SC_RPOS] = 0.0 if pos == size else float(pos)


@njit(cache=CACHE)
def _rescale(S: np.ndarray, sy: np.ndarray, sc: np.ndarray, factor: float) -> None:
    p = sy.shape[0]
    for i in range(p):
        sy[i] *= factor
        for j in range(p):
            S[i, j] *= factor
    sc[SC_SYY] *= factor


#: Samples whose rank-one updates of the statistics ``block`` defers and then adds in one pass (``_flush``).
DEFER_ROWS = 64


@njit(cache=CACHE)
def block(u: np.ndarray, y: np.ndarray, st: np.ndarray, S: np.ndarray, ring: np.ndarray,
          status: np.ndarray, start: int = 0, stop: int = -1) -> int:
    """Samples ``start`` to ``stop`` (-1: the end) until due work (flag 8), their statuses from status[0];
    returns how many were consumed. (A range, not slices: the start-up replay calls it from cold Python.)

    ``sample``'s steps for each sample, bit for bit, in one loop (``_block``): the views of the state array taken
    once, and the rank-one updates of S waiting in a block of DEFER_ROWS regressor rows, added in one pass over S
    (``_flush``: the same operations on each element in the same order). S is complete whenever this returns,
    so no reader of S sees the deferral. Here: the deferred rows' memory, which ``_block`` (no reference counts)
    cannot allocate."""
    p = S.shape[0]
    return _block(u, y, st, S, ring, status, start, stop, np.empty((DEFER_ROWS, p)), np.empty(DEFER_ROWS))


@njit(cache=CACHE, fastmath=FAST, _nrt=False)
def _block(u: np.ndarray, y: np.ndarray, st: np.ndarray, S: np.ndarray, ring: np.ndarray, status: np.ndarray,
           start: int, stop: int, X: np.ndarray, gx: np.ndarray) -> int:
    """``block``'s loop, without numba's reference counts (``_nrt=False``): every array here is a view of the
    caller's, and the counts kept for each view passed to the step's helpers were half of the loop's time (0.36
    against 0.18 us a sample). What it calls is compiled alike, so it must not need the runtime either (an
    allocation, a slice copy: ``_flush`` has no spare row for that reason); a kernel that cannot compile so is an
    internal fault of every block (the block tests assert none)."""
    end = u.shape[0] if stop < 0 else stop
    sc = st[:SC_SIZE]
    q = int(sc[SC_NQ])
    nm = int(sc[SC_NM])
    nr = int(sc[SC_NR])
    nh = int(sc[SC_NH])
    p = S.shape[0]
    o = SC_SIZE
    phi = st[o:o + p]
    m = st[o + p:o + 2 * p]
    sy = st[o + 2 * p:o + 3 * p]
    c0 = co_at(q, nm, nr + nh)
    c1 = c0 + co_size(q, nm)
    co = st[c0:c1]
    ztail = st[c1:c1 + q]
    md = st[c1 + q:c1 + 2 * q + ONE]
    ho = c1 + 2 * q + ONE                       # the hysteresis block (``hysteresis.block_at``)
    k = 0
    used = end - start
    for i in range(start, end):
        ui, yi = u[i], y[i]
        if nh > 0:
            HK.columns(st, ho, nh, q, phi, p - nr - nh, m)
        pred = _drift_regressors(phi, m, md, sc, q, p, nr)
        for j in range(q + ONE, p):
            pred += phi[j] * m[j]
        sc[SC_PRED] = pred
        status_i = 0
        if yi != yi:
            status_i = 1
        else:
            status_i = gate(yi, pred, sc)
            if status_i != 2:
                if sc[SC_ACC] > 0.0 and sc[SC_STUCK] == 0.0:
                    k = _defer(yi, phi, S, sy, sc, X, gx, k)
                elif status_i == 0:
                    status_i = 4
        status_i += _move_on(ui, yi, status_i, st, ho, nh, q, co, phi, sc, ring, ztail)
        status[i - start] = status_i
        if status_i >= 8:
            used = i - start + 1
            break
    _flush(S, X, gx, k)
    return used


@njit(cache=CACHE, fastmath=FAST, inline="always")
def _move_on(u: float, y: float, status: int, st: np.ndarray, ho: int, nh: int, q: int, co: np.ndarray,
             phi: np.ndarray, sc: np.ndarray, ring: np.ndarray, ztail: np.ndarray) -> int:
    """A sample's last steps after its gate (``sample`` and ``block`` alike): the ring remembers it (its output only
    if it was used: status 0 or 3), the hysteresis tail and plays, the input's notes and the node states move on,
    the count too. Returns 8 if the caller's work is due at this sample, else 0."""
    if nh > 0 and sc[SC_RCOUNT] >= ring.shape[1]:
        HK.tail(st, ho, nh, q, co, ring[0, int(sc[SC_RPOS])])
    _remember(u, y if status == 0 or status == 3 else math.nan, co, q, sc, ring, ztail)
    note_input(u, sc)
    advance(phi, co, q, u)
    if nh > 0:
        HK.step(st, ho, nh, q, co, u)
    sc[SC_N] += 1.0
    return 8 if sc[SC_N] >= sc[SC_DUE] else 0


@njit(cache=CACHE, fastmath=FAST, inline="always")
def _defer(y: float, phi: np.ndarray, S: np.ndarray, sy: np.ndarray, sc: np.ndarray, X: np.ndarray,
           gx: np.ndarray, k: int) -> int:
    """``_accumulate`` with S's rank-one update left in row k of (X, gx) (flushed when the rows are full or the
    weight is renormalised); returns the rows waiting."""
    f = sc[SC_FORGET]
    g = sc[SC_G]
    if f < 1.0:
        g = g / f
        if g > 1e100:
            _flush(S, X, gx, k)
            k = 0
            _rescale(S, sy, sc, 1.0 / g)
            g = 1.0
        sc[SC_G] = g
    p = phi.shape[0]
    for i in range(p):
        gi = g * phi[i]
        sy[i] += gi * y
        X[k, i] = phi[i]
    gx[k] = g
    sc[SC_SYY] += g * y * y
    sc[SC_NEFF] = sc[SC_NEFF] * f + 1.0
    k += 1
    if k == X.shape[0]:
        _flush(S, X, gx, k)
        k = 0
    return k


@njit(cache=CACHE, fastmath=FAST)
def _flush(S: np.ndarray, X: np.ndarray, gx: np.ndarray, k: int) -> None:
    """S's upper triangle += that of sum over the k rows t of (gx[t] X[t])^T X[t], element by element in the rows'
    order as ``_accumulate`` adds them (``S[i, j] += (g phi[i]) phi[j]``, rounded alike), so the statistics are bit
    for bit the same. Only the upper triangle (j >= i): nothing reads below the diagonal (the module docstring's
    "Statistics"). Eight rows per pass over S, each element loaded and stored once per eight updates. The column
    index is unsigned (``_columns``), so the loop over a row runs four columns per instruction: the same
    operations on each element, 0.5 of the time of a signed index's scalar loop (microbenchmark, P = 50 to 58).
    Nothing allocated: ``_block`` runs it without reference counts."""
    p = S.shape[0]
    t = 0
    while t + 8 <= k:
        x0, x1, x2, x3, x4, x5, x6, x7 = X[t], X[t + 1], X[t + 2], X[t + 3], X[t + 4], X[t + 5], X[t + 6], X[t + 7]
        for i in range(p):
            row = S[i]
            g0, g1, g2, g3 = gx[t] * x0[i], gx[t + 1] * x1[i], gx[t + 2] * x2[i], gx[t + 3] * x3[i]
            g4, g5, g6, g7 = gx[t + 4] * x4[i], gx[t + 5] * x5[i], gx[t + 6] * x6[i], gx[t + 7] * x7[i]
            for j in _columns(i, p):
                v = row[j] + g0 * x0[j]
                v = v + g1 * x1[j]
                v = v + g2 * x2[j]
                v = v + g3 * x3[j]
                v = v + g4 * x4[j]
                v = v + g5 * x5[j]
                v = v + g6 * x6[j]
                row[j] = v + g7 * x7[j]
        t += 8
    while t < k:
        x0 = X[t]
        for i in range(p):
            g0 = gx[t] * x0[i]
            row = S[i]
            for j in _columns(i, p):
                row[j] += g0 * x0[j]
        t += 1


@njit(cache=CACHE)
def symmetrize(S: np.ndarray, out: np.ndarray, scale: float) -> None:
    """out = scale * (full symmetric matrix whose upper triangle is S)."""
    p = S.shape[0]
    for i in range(p):
        for j in range(i, p):
            v = S[i, j] * scale
            out[i, j] = v
            out[j, i] = v


@njit(cache=CACHE)
def cost_of(theta: np.ndarray, a1l: float, a2l: float, lam: np.ndarray, dx: float, F: np.ndarray,
            fy: np.ndarray, fyy: float) -> float:
    """Window cost sum w (y - phi . m(theta))^2 from full (symmetric) statistics F, fy, fyy."""
    p = fy.shape[0]
    m = np.empty(p)
    full_coefficients(theta, a1l, a2l, lam, dx, m)
    return cost_rows(F, fy, m, 0, p, fyy)


@njit(cache=CACHE, fastmath=FAST)
def cost_rows(F: np.ndarray, fy: np.ndarray, m: np.ndarray, i0: int, i1: int, partial: float) -> float:
    """``partial`` plus rows i0..i1 of the window cost's sum m_i ((F m)_i - 2 fy_i): started at fyy and
    run over all rows, the cost at coefficients m. In row slices, it is the same sum in the same order
    (the re-fit spreads it over samples, ``fit_machine.fit_unit``)."""
    p = fy.shape[0]
    c = partial
    for i in range(i0, i1):
        Fi = F[i]
        t = 0.0
        for j in range(p):
            t += Fi[j] * m[j]
        c += m[i] * (t - 2.0 * fy[i])
    return c


@njit(cache=CACHE)
def _resonance_derivatives(alpha: float, lam: np.ndarray, dx: float, a1: float, a2: float,
                           va1: np.ndarray, va2: np.ndarray) -> None:
    """d v / d a1 and d v / d a2 of ``kernels.model_coefficients`` (analytic).

    v_i = w_i A_i with A_i = 1 / (a2 lam_i^2 - a1 lam_i + 1), so dA/da1 = lam A^2 and
    dA/da2 = -lam^2 A^2; the last two entries follow from their sums.
    """
    q = lam.shape[0]
    s = math.sin(math.pi * alpha) / math.pi
    lo = lam[1] * math.exp(-dx)
    w0 = s * dx * lo ** (1.0 - alpha) / (1.0 - math.exp(-(1.0 - alpha) * dx))
    t1 = 0.0
    t2 = 0.0
    sa = 0.0
    sl = 0.0
    sl2 = 0.0
    for i in range(q):
        li = lam[i]
        w = w0 if i == 0 else s * dx * li ** (1.0 - alpha)
        a = 1.0 / (a2 * li * li - a1 * li + 1.0)
        aa = a * a
        va1[i] = w * li * aa
        va2[i] = -w * li * li * aa
        c = a2 * li - a1
        t1 += w * (li * aa * c - a)
        t2 += w * (-li * li * aa * c + a * li)
        sa += w * a
        sl += w * li * aa
        sl2 += w * li * li * aa
    va1[q] = t1
    va2[q] = t2
    va1[q + 1] = -a2 * sl
    va2[q + 1] = -sa + a2 * sl2


@njit(cache=CACHE)
def resonance_derivatives(theta: np.ndarray, lam: np.ndarray, dx: float, va1: np.ndarray, va2: np.ndarray) -> None:
    """d v / d a1 and d v / d a2 at theta (``_resonance_derivatives``): the middle part of ``jacobian_coefficients``,
    a slice of its own in the re-fit (a power per node: with the assembly, one slice was ~2.3 us)."""
    _resonance_derivatives(theta[0], lam, dx, math.exp(theta[1]), math.exp(theta[2]), va1, va2)


@njit(cache=CACHE)
def jacobian_coefficients(theta: np.ndarray, a1l: float, a2l: float, lam: np.ndarray, dx: float,
                          C: np.ndarray) -> None:
    """Columns of C: d(phi . m)/d theta_j as coefficient vectors over phi (analytic)."""
    q = lam.shape[0]
    v = np.empty(q + 2)
    dv = np.empty(q + 2)
    model_coefficients(theta[0], lam, dx, math.exp(theta[1]), math.exp(theta[2]), v, dv)
    va1, va2 = np.empty(q + 2), np.empty(q + 2)
    resonance_derivatives(theta, lam, dx, va1, va2)
    jacobian_assemble(theta, a1l, a2l, lam, dx, v, dv, C, va1, va2)


@njit(cache=CACHE)
def jacobian_assemble(theta: np.ndarray, a1l: float, a2l: float, lam: np.ndarray, dx: float, v: np.ndarray,
                      dv: np.ndarray, C: np.ndarray, va1: np.ndarray, va2: np.ndarray) -> None:
    """The last part of ``jacobian_coefficients``: C from the model coefficients v and dv/dalpha at theta
    (``kernels.model_coefficients``) and their resonance derivatives va1, va2 (``resonance_derivatives``)."""
    q = lam.shape[0]
    n = C.shape[1]
    a1 = math.exp(theta[1])
    a2 = math.exp(theta[2])
    b = theta[3]
    C[:, :] = 0.0
    d1 = a1 - a1l
    d2 = a2 - a2l
    for i in range(q + 2):
        C[i, 0] = b * dv[i]
        C[i, 1] = b * a1 * va1[i]
        C[i, 2] = b * a2 * va2[i]
        C[i, 3] = v[i]
    for j in range(2):      # the first-order resonance slots: d1 v_x, d2 v_x
        C[q + 2 + j, 0] = b * d1 * dv[q + j]
        C[q + 4 + j, 0] = b * d2 * dv[q + j]
        C[q + 2 + j, 1] = b * a1 * (v[q + j] + d1 * va1[q + j])
        C[q + 4 + j, 1] = b * a1 * d2 * va1[q + j]
        C[q + 2 + j, 2] = b * a2 * d1 * va2[q + j]
        C[q + 4 + j, 2] = b * a2 * (v[q + j] + d2 * va2[q + j])
        C[q + 2 + j, 3] = d1 * v[q + j]
        C[q + 4 + j, 3] = d2 * v[q + j]
    for j in range(4, n):
        C[q + ONE + j - 4, j] = 1.0


@njit(cache=CACHE, fastmath=FAST)
def normal_equations(theta: np.ndarray, C: np.ndarray, F: np.ndarray, fy: np.ndarray, fyy: float) -> tuple:
    """(J^T J, J^T r, cost) of the window at theta from its Jacobian coefficients C.

    C is block diagonal (``jacobian_coefficients``): its first four columns (alpha, ln a1, ln a2, b)
    live on the model part of the regressor (rows 0..Q+5, block A), the offset, free responses and
    drift rates are unit vectors on the rest. With F split the same way, J^T J = [[A^T F11 A, A^T F12],
    [F21 A, F22]]: about a third of the multiply-adds of the dense C^T F C, and no BLAS call (whose
    set-up dominated at these sizes). The model coefficients are m = C[:, 3:] theta[3:].

    Three parts (``normal_prepare``, ``normal_rows``, ``normal_finish``) that the re-fit runs as
    separate slices of background work; here in one call.
    """
    p, k = C.shape
    At = np.empty((4, p - (k - 4)))
    m = np.empty(p)
    FA = np.empty((p, 4))
    fm = np.empty(p)
    H = np.empty((k, k))
    g = np.empty(k)
    normal_prepare(theta, C, At, m)
    normal_rows(F, At, m, FA, fm, 0, p)
    cost = normal_finish(At, m, FA, fm, F, fy, fyy, H, g)
    return H, g, cost


@njit(cache=CACHE)
def normal_prepare(theta: np.ndarray, C: np.ndarray, At: np.ndarray, m: np.ndarray) -> None:
    """A^T (the model block of C, contiguous: the row loops vectorize) and the model coefficients m."""
    p, k = C.shape
    mq = p - (k - 4)                   # rows of the model part (Q + 6)
    for j in range(mq):
        for c in range(4):
            At[c, j] = C[j, c]
    for i in range(mq):
        m[i] = At[3, i] * theta[3]
    for i in range(mq, p):
        m[i] = theta[4 + i - mq]


@njit(cache=CACHE, fastmath=FAST)
def normal_rows(F: np.ndarray, At: np.ndarray, m: np.ndarray, FA: np.ndarray, fm: np.ndarray,
                i0: int, i1: int) -> None:
    """Rows i0..i1 of F[:, :mq] A and of F m (the O(P^2) part of the normal equations)."""
    mq = At.shape[1]
    p = m.shape[0]
    for i in range(i0, i1):
        Fi = F[i]
        for c in range(4):
            t = 0.0
            for j in range(mq):
                t += Fi[j] * At[c, j]
            FA[i, c] = t
        t = 0.0
        for j in range(p):
            t += Fi[j] * m[j]
        fm[i] = t


@njit(cache=CACHE, fastmath=FAST)
def normal_finish(At: np.ndarray, m: np.ndarray, FA: np.ndarray, fm: np.ndarray, F: np.ndarray,
                  fy: np.ndarray, fyy: float, H: np.ndarray, g: np.ndarray) -> float:
    """J^T J into H, J^T r into g from the rows; returns the window cost."""
    mq = At.shape[1]
    p = m.shape[0]
    k = H.shape[0]
    cost = fyy
    for i in range(p):
        cost += m[i] * (fm[i] - 2.0 * fy[i])
    for a in range(4):
        for c in range(4):
            t = 0.0
            for j in range(mq):
                t += At[a, j] * FA[j, c]
            H[a, c] = t
        for c in range(4, k):
            H[a, c] = FA[mq + c - 4, a]          # (F21 A)^T = A^T F12
            H[c, a] = H[a, c]
        t = 0.0
        for j in range(mq):
            t += At[a, j] * (fy[j] - fm[j])
        g[a] = t
    for a in range(4, k):
        for c in range(4, k):
            H[a, c] = F[mq + a - 4, mq + c - 4]
        g[a] = fy[mq + a - 4] - fm[mq + a - 4]
    return cost


@njit(cache=CACHE)
def lm_trial(theta: np.ndarray, free: np.ndarray, mu: float, H: np.ndarray, g: np.ndarray, cost: float,
             a1l: float, a2l: float, lam: np.ndarray, dx: float, F: np.ndarray, fy: np.ndarray, fyy: float,
             lo: float, hi: float, out: np.ndarray) -> float:
    """The damped Gauss-Newton step; theta updated in place if the window cost drops.

    ``free[j]`` = 1 lets parameter j move (``LINEAR``: with LINEAR_DAMPING x the damping). ``out`` = [cost before, cost
    after, accepted]. Returns the next damping ``mu``. Three parts (``trial_point``, the trial's cost,
    ``trial_verdict``) that the re-fit runs as separate slices of background work; here in one call.
    """
    n = theta.shape[0]
    trial = np.empty(n)
    ok, mu_fail = trial_point(theta, free, mu, H, g, cost, lo, hi, trial, out, np.empty((n, n)), np.empty(n),
                              np.empty(n))
    if not ok:
        return mu_fail
    return trial_verdict(theta, trial, cost_of(trial, a1l, a2l, lam, dx, F, fy, fyy), cost, mu, out)


@njit(cache=CACHE)
def trial_point(theta: np.ndarray, free: np.ndarray, mu: float, H: np.ndarray, g: np.ndarray, cost: float,
                lo: float, hi: float, trial: np.ndarray, out: np.ndarray, A: np.ndarray, d: np.ndarray,
                x: np.ndarray) -> tuple:
    """The damped Gauss-Newton step from theta into ``trial``; returns (solved, the damping if not).

    Two parts the re-fit runs as separate slices: ``trial_factor`` and ``trial_step``."""
    ok, mu_next = trial_factor(theta, free, mu, H, g, cost, out, A, d, x)
    if not ok:
        return False, mu_next
    return trial_step(theta, mu, lo, hi, trial, A, d, x)


@njit(cache=CACHE)
def trial_factor(theta: np.ndarray, free: np.ndarray, mu: float, H: np.ndarray, g: np.ndarray, cost: float,
                 out: np.ndarray, A: np.ndarray, d: np.ndarray, x: np.ndarray) -> tuple:
    """The damped step's scaled system, factored: returns (factored, the damping if not).

    In caller's scratch (A: k x k, d and x: k; the re-fit lends the covariance's, idle during its steps), the
    scaled matrix's lower triangle built in A and factored in place, the scaled right-hand side in x
    (``trial_step`` solves it): written with numpy (a copy of H, its diagonal, an outer product, a quotient,
    isfinite checks) the step's ten temporaries were about half of its ~2.3 us. The arithmetic is the same,
    operation for operation. A direction the damped matrix is not positive definite in (rounding) is held
    (``cholesky_holding``): the step moves the other parameters."""
    n = theta.shape[0]
    top = 0.0
    for i in range(n):
        top = max(top, abs(H[i, i]) * max(abs(theta[i]), 1.0) ** 2)
    for i in range(n):
        # a parameter the window carries (almost) no information about does not move
        if free[i] == 0.0 or not abs(H[i, i]) * max(abs(theta[i]), 1.0) ** 2 > 1e-14 * top:
            x[i] = 0.0                     # (x marks it: held; its entries of the scaled matrix are the unit's)
            d[i] = 1.0 + 1e-300
        elif free[i] == LINEAR:
            x[i] = 1.0
            d[i] = math.sqrt(abs(H[i, i] + (LINEAR_DAMPING * mu * H[i, i] + 1e-300))) + 1e-300
        else:
            x[i] = 1.0
            d[i] = math.sqrt(abs(H[i, i] + (mu * H[i, i] + 1e-300))) + 1e-300
    out[0] = cost
    out[1] = cost
    out[2] = 0.0
    failed = min(mu * 10.0, 1e8)
    for i in range(n):
        for j in range(i + 1):
            if x[i] == 0.0 or x[j] == 0.0:
                a = 1.0 if i == j else 0.0
            elif i == j:
                a = H[i, i] + ((LINEAR_DAMPING if free[i] == LINEAR else 1.0) * mu * H[i, i] + 1e-300)
            else:
                a = H[i, j]
            v = a / (d[i] * d[j])
            if not math.isfinite(v):
                return False, failed
            A[i, j] = v
    for i in range(n):                     # the right-hand side, scaled (x: held or not, then the step)
        x[i] = (g[i] if x[i] != 0.0 else 0.0) / d[i]
        if not math.isfinite(x[i]):
            return False, failed
    cholesky_holding(A, n, x)
    return True, mu


@njit(cache=CACHE)
def trial_step(theta: np.ndarray, mu: float, lo: float, hi: float, trial: np.ndarray, A: np.ndarray,
               d: np.ndarray, x: np.ndarray) -> tuple:
    """The step from ``trial_factor``'s factor and right-hand side into ``trial`` (ln a1, ln a2 moved at most
    0.3, alpha within [lo, hi]); returns (solved, the damping if not)."""
    n = theta.shape[0]
    _cholesky_solve_in_place(A, x, n)
    for i in range(n):
        s = x[i] / d[i]
        if not math.isfinite(s):
            return False, min(mu * 10.0, 1e8)
        if i == 1 or i == 2:
            s = min(max(s, -0.3), 0.3)
        trial[i] = theta[i] + s
    trial[0] = min(max(trial[0], lo), hi)
    return True, mu


@njit(cache=CACHE)
def trial_verdict(theta: np.ndarray, trial: np.ndarray, c_new: float, cost: float, mu: float,
                  out: np.ndarray) -> float:
    """Take the trial if the window cost dropped; returns the next damping."""
    if c_new == c_new and c_new < cost:
        theta[:] = trial
        out[1] = c_new
        out[2] = 1.0
        return max(mu / 3.0, 1e-7)
    return min(mu * 4.0, 1e8)


@njit(cache=CACHE)
def lm_normal(theta: np.ndarray, a1l: float, a2l: float, lam: np.ndarray, dx: float, F: np.ndarray,
              fy: np.ndarray, fyy: float, H_out: np.ndarray, g_out: np.ndarray) -> float:
    """The first half of a Levenberg-Marquardt step (Jacobian and normal equations, ~6 us at P ~ 50):
    J^T J into ``H_out``, J^T r into ``g_out``; returns the window cost at theta. ``lm_trial`` is the
    second half (the tracker runs them as two units of background work)."""
    C = np.empty((fy.shape[0], theta.shape[0]))
    jacobian_coefficients(theta, a1l, a2l, lam, dx, C)
    H, g, cost = normal_equations(theta, C, F, fy, fyy)
    H_out[:, :] = H
    g_out[:] = g
    return cost


@njit(cache=CACHE)
def covariance(H: np.ndarray, free: np.ndarray, cov: np.ndarray) -> None:
    """inv(J^T J) over the free parameters (unscaled: times sigma^2); inf where it is singular."""
    n = H.shape[0]
    L = np.empty((n, n))
    d = np.empty(n)
    ok = covariance_factor(H, free, L, d)
    covariance_columns(L, ok, cov, np.empty(n), 0, n)
    covariance_inverse(L, d, ok, cov, free, H)


@njit(cache=CACHE)
def covariance_factor(H: np.ndarray, free: np.ndarray, L: np.ndarray, d: np.ndarray) -> bool:
    """The first part of ``covariance``: the Cholesky factor L of J^T J over the free parameters, scaled to
    a unit diagonal by d; False where it is singular. The scaled matrix's lower triangle is built in L and
    factored in place (its former numpy temporaries, a copy, a diagonal, an outer product and a quotient,
    were about half of this slice)."""
    if _scaled_lower(H, free, L, d, 0.0) and cholesky_factor(L, L, H.shape[0], 0.0):
        return True
    linear = False                 # not positive definite in rounding: the free responses' prior, if any
    for i in range(H.shape[0]):
        linear = linear or free[i] == LINEAR
    return linear and _scaled_lower(H, free, L, d, LINEAR_PRIOR) and cholesky_factor(L, L, H.shape[0], 0.0)


@njit(cache=CACHE)
def _scaled_lower(H: np.ndarray, free: np.ndarray, L: np.ndarray, d: np.ndarray, prior: float) -> bool:
    """L's lower triangle = H with its held (or uninformative: zero diagonal) rows and columns replaced by the
    unit's, scaled to a unit diagonal by d, plus ``prior`` on the ``LINEAR`` parameters' diagonal; False if an
    entry is not finite."""
    n = H.shape[0]
    for i in range(n):
        held = free[i] == 0.0 or H[i, i] == 0.0
        d[i] = math.sqrt(abs(1.0 if held else H[i, i])) + 1e-300
    for i in range(n):
        held_i = free[i] == 0.0 or H[i, i] == 0.0
        for j in range(i + 1):
            if held_i or free[j] == 0.0 or H[j, j] == 0.0:
                a = 1.0 if i == j else 0.0
            else:
                a = H[i, j]
            v = a / (d[i] * d[j])
            if not math.isfinite(v):
                return False
            if i == j and free[i] == LINEAR:
                v += prior
            L[i, j] = v
    return True


@njit(cache=CACHE)
def covariance_columns(L: np.ndarray, ok: bool, cov: np.ndarray, x: np.ndarray, j0: int, j1: int) -> None:
    """Columns j0..j1 of the scaled inverse from the factor into ``cov`` (``covariance_inverse`` then judges and
    unscales it): the re-fit spreads the k solves over slices. ``x``: a scratch vector of k."""
    n = L.shape[0]
    if not ok:
        return
    for j in range(j0, j1):
        for i in range(n):
            x[i] = 0.0
        x[j] = 1.0
        _cholesky_solve_in_place(L, x, n)
        for i in range(n):
            cov[i, j] = x[i]


@njit(cache=CACHE)
def covariance_inverse(L: np.ndarray, d: np.ndarray, ok: bool, cov: np.ndarray, free: np.ndarray,
                       H: np.ndarray) -> None:
    """The last part of ``covariance``: the inverse whose scaled columns ``covariance_columns`` wrote into cov,
    judged and unscaled in place (all inf if the factor failed or the matrix is too ill-conditioned for its
    inverse to mean anything; ``LINEAR`` parameters left out of that judgement). A free parameter whose column
    is zero over the window (H's diagonal 0), held in the factor, has no information: its variance is inf."""
    n = L.shape[0]
    if not ok:
        cov[:, :] = np.inf
        return
    # An has a unit diagonal, so lambda_max <= n and 1/lambda_min <= trace(inv): n trace(inv)
    # bounds the condition number (within a factor n of it); beyond 1e13 the inverse is noise. The free
    # responses' own block (``LINEAR``) is left out: their combinations the window does not determine are
    # theirs (a stream in operation read every variance inf for seconds at the floor for them alone)
    tr = 0.0
    for j in range(n):
        if free[j] != LINEAR:
            tr += cov[j, j]
    if not (tr > 0.0 and n * tr < 1e13):
        cov[:, :] = np.inf
        return
    for i in range(n):
        for j in range(n):
            cov[i, j] = cov[i, j] / (d[i] * d[j])
    for j in range(n):
        if free[j] != 0.0 and H[j, j] == 0.0:
            cov[j, :] = np.inf
            cov[:, j] = np.inf


@njit(cache=CACHE)
def cholesky_factor(A: np.ndarray, L: np.ndarray, n: int, pivot_floor: float) -> bool:
    """Lower Cholesky factor of the leading n x n block of a symmetric A into L's lower triangle.

    Reads only A's lower triangle and writes only L's, each entry of A read before L's same entry is written,
    so L may be A itself (in place, no scratch: the drift score test inside the per-sample kernel). Returns
    False at the first pivot not above ``pivot_floor`` (0: not numerically positive definite).
    """
    return _factor(A, L, n, pivot_floor, L[0, :0]) >= 0     # (an empty view: fail, not hold; no allocation)


@njit(cache=CACHE)
def cholesky_holding(A: np.ndarray, n: int, x: np.ndarray) -> int:
    """``cholesky_factor`` in place over the leading n x n block, holding the parameters whose pivot is not
    positive: their row of the factor becomes the unit's, their entries below it 0 and their right-hand side
    x[j] 0, so that the solve leaves them where they are and solves for the others (the factor of the matrix
    without them). Returns how many were held.

    A Gauss-Newton matrix is positive semi-definite; a pivot at or below 0 is rounding in a direction the window
    does not determine. A resonance critically damped or overdamped with a pole at an SOE node's rate makes the
    node's coefficients and their resonance derivatives ~1e8, cancelled by the resonance entries, and J^T J's
    ln a1, ln a2 entries then keep ~1e-17 of their terms: a negative diagonal, which Levenberg-Marquardt's damping
    (a multiple of the diagonal) keeps negative, and the whole step failed at every damping: a re-fit then never
    moved anything again (a plant resting on a branch, fed sample by sample, stayed at 520x the noise floor)."""
    return _factor(A, A, n, 0.0, x)


@njit(cache=CACHE)
def _factor(A: np.ndarray, L: np.ndarray, n: int, pivot_floor: float, x: np.ndarray) -> int:
    """The factor of ``cholesky_factor`` (``x`` empty: -1 at the first pivot not above ``pivot_floor``) and of
    ``cholesky_holding`` (such a pivot's parameter held, x[j] = 0); returns how many were held."""
    held = 0
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > pivot_floor:
            if x.shape[0] == 0:
                return -1
            for k in range(j):
                L[j, k] = 0.0
            L[j, j] = 1.0
            for i in range(j + 1, n):
                L[i, j] = 0.0
            x[j] = 0.0
            held += 1
            continue
        djj = math.sqrt(s)
        L[j, j] = djj
        for i in range(j + 1, n):
            t = A[i, j]
            for k in range(j):
                t -= L[i, k] * L[j, k]
            L[i, j] = t / djj
    return held


@njit(cache=CACHE)
def forward_substitution(L: np.ndarray, b: np.ndarray, x: np.ndarray, n: int) -> None:
    """x = L^-1 b over the leading n x n block of the lower triangular L."""
    for i in range(n):
        t = b[i]
        for k in range(i):
            t -= L[i, k] * x[k]
        x[i] = t / L[i, i]


@njit(cache=CACHE)
def _cholesky(A: np.ndarray, L: np.ndarray) -> bool:
    """Lower Cholesky factor of a small symmetric matrix (no LAPACK call: ~10x less overhead at n ~ 9).

    Returns False when A is not numerically positive definite.
    """
    L[:, :] = 0.0
    return cholesky_factor(A, L, A.shape[0], 0.0)


@njit(cache=CACHE)
def _cholesky_solve(L: np.ndarray, b: np.ndarray, x: np.ndarray) -> None:
    """x = (L L^T)^-1 b by forward and back substitution."""
    n = L.shape[0]
    x[:n] = b[:n]
    _cholesky_solve_in_place(L, x, n)


@njit(cache=CACHE)
def _cholesky_solve_in_place(L: np.ndarray, x: np.ndarray, n: int) -> None:
    """x = (L L^T)^-1 x over the leading n x n block of the lower triangular L (``_cholesky_solve``'s arithmetic,
    without a second vector: each entry of x is read before it is written)."""
    forward_substitution(L, x, x, n)
    for i in range(n - 1, -1, -1):
        t = x[i]
        for k in range(i + 1, n):
            t -= L[k, i] * x[k]
        x[i] = t / L[i, i]


#: Samples per block of a replay's statistics update (``replay``): the block's rows added to the statistics in one
#: pass over S instead of a rank-one update per sample (at P = 51: 0.18 against 0.38 us per sample, 32 samples per
#: block).
REPLAY_BLOCK = 32


def replay_scratch(p: int) -> tuple:
    """Work arrays of ``replay`` for P regressors: the block's rows, weighted rows and outputs."""
    return np.empty((REPLAY_BLOCK, p)), np.empty((REPLAY_BLOCK, p)), np.empty(REPLAY_BLOCK)


@njit(cache=CACHE, inline="always")
def _replay_views(st: np.ndarray) -> tuple:
    """What a replay reads and advances in st: scalars, Q, rates, P, phi, m, sy, coefficients, md, and the
    hysteresis columns' count and block (``hysteresis.py``)."""
    sc = st[:SC_SIZE]
    q = int(sc[SC_NQ])
    nr = int(sc[SC_NR])
    nh = int(sc[SC_NH])
    p = q + FREE + int(sc[SC_NM]) + nh + nr
    o = SC_SIZE
    phi = st[o:o + p]
    m = st[o + p:o + 2 * p]
    sy = st[o + 2 * p:o + 3 * p]
    c0 = co_at(q, int(sc[SC_NM]), nr + nh)
    co = st[c0:c0 + co_size(q, int(sc[SC_NM]))]
    md = st[c0 + co.shape[0] + q:c0 + co.shape[0] + 2 * q + ONE]
    return sc, q, nr, p, phi, m, sy, co, md, nh, c0 + co.shape[0] + 2 * q + ONE


@njit(cache=CACHE, fastmath=FAST)
def _add_block(X: np.ndarray, Xw: np.ndarray, yb: np.ndarray, nb: int, S: np.ndarray, sy: np.ndarray) -> None:
    """S += Xw[:nb]^T X[:nb] in its upper triangle (the module docstring's "Statistics"), sy += Xw[:nb]^T yb[:nb]
    (the weighted rows of a block): eight rows per pass over S.

    Not BLAS: as warm as OpenBLAS's dgemm here (7.2 against 7.4 us for 32 rows at P = 59), but a replay's first
    block comes after thousands of calls without one, and a cold dgemm (its code and packing buffers) took
    27-33 us against 18 us for this loop (a replay's first accumulating unit was the slowest call after each
    change, ~41 us)."""
    p = sy.shape[0]
    r = 0
    while r + 8 <= nb:
        for i in range(p):
            a0, a1, a2, a3 = Xw[r, i], Xw[r + 1, i], Xw[r + 2, i], Xw[r + 3, i]
            a4, a5, a6, a7 = Xw[r + 4, i], Xw[r + 5, i], Xw[r + 6, i], Xw[r + 7, i]
            sy[i] += (a0 * yb[r] + a1 * yb[r + 1] + a2 * yb[r + 2] + a3 * yb[r + 3]
                      + a4 * yb[r + 4] + a5 * yb[r + 5] + a6 * yb[r + 6] + a7 * yb[r + 7])
            for j in _columns(i, p):
                S[i, j] += (a0 * X[r, j] + a1 * X[r + 1, j] + a2 * X[r + 2, j] + a3 * X[r + 3, j]
                            + a4 * X[r + 4, j] + a5 * X[r + 5, j] + a6 * X[r + 6, j] + a7 * X[r + 7, j])
        r += 8
    while r < nb:
        for i in range(p):
            a = Xw[r, i]
            sy[i] += a * yb[r]
            for j in _columns(i, p):
                S[i, j] += a * X[r, j]
        r += 1


@njit(cache=CACHE, fastmath=FAST)
def replay(ring: np.ndarray, p0: int, n: int, skip: int, st: np.ndarray, S: np.ndarray, X: np.ndarray,
           Xw: np.ndarray, yb: np.ndarray) -> None:
    """Re-accumulate n remembered samples from ring position p0 (wrapping); the first ``skip`` only advance.

    No gate, no prediction: the ring holds the outputs as they were used (NaN
    where they were not), so a replay reproduces the accepted samples exactly
    for a new linearization point. ``st[SC_N]`` must hold the index of the
    first replayed sample (the drift columns' time); it advances with the replay.
    The drift columns use the coefficients ``m``, ``md`` in ``st`` (the current
    estimate) for every replayed sample.

    The statistics are those of ``replay_direct`` (a rank-one update per sample,
    as the live kernel accumulates), gathered in blocks of ``REPLAY_BLOCK`` rows
    and added one block at a time (``_add_block``; ``replay_scratch``: X, Xw, yb).
    """
    sc, q, nr, p, phi, m, sy, co, md, nh, ho = _replay_views(st)
    size = ring.shape[1]
    block = X.shape[0]
    f = sc[SC_FORGET]
    nb = 0
    for k in range(n):
        pos = (p0 + k) % size
        y = ring[1, pos]
        if k >= skip and y == y:
            if nh > 0:
                HK.columns(st, ho, nh, q, phi, p - nr - nh, m)
            if nr > 0:
                _drift_regressors(phi, m, md, sc, q, p, nr)
            g = sc[SC_G]               # the weight of this row, as ``_accumulate`` grows it
            if f < 1.0:
                g = g / f
                if g > 1e100:          # the rows gathered so far carry the old scale: add them first
                    if nb > 0:
                        _add_block(X, Xw, yb, nb, S, sy)
                        nb = 0
                    _rescale(S, sy, sc, 1.0 / g)
                    g = 1.0
                sc[SC_G] = g
            for i in range(p):
                X[nb, i] = phi[i]
                Xw[nb, i] = g * phi[i]
            yb[nb] = y
            sc[SC_SYY] += g * y * y
            sc[SC_NEFF] = sc[SC_NEFF] * f + 1.0
            nb += 1
            if nb == block:
                _add_block(X, Xw, yb, nb, S, sy)
                nb = 0
        advance(phi, co, q, ring[0, pos])
        if nh > 0:
            HK.step(st, ho, nh, q, co, ring[0, pos])
        sc[SC_N] += 1.0
    if nb > 0:
        _add_block(X, Xw, yb, nb, S, sy)


@njit(cache=CACHE, inline="always")
def replay_unit(chunk: int, skip_left: int, cold_rows: int) -> int:
    """Samples in a replay's next unit: up to eight chunks only advanced (states, no statistics: ~1/8 of the work)
    while ``skip_left`` > 0, the last of them ending at the skip; then ``settings.cold_replay_rows`` accumulated (the
    statistics, p x p, and the block's code come from memory after thousands of calls without a replay:
    with 20 samples after the skip's end in the same unit the call took ~40 us, after ~90 us for 297 when
    accumulating past the skip's end at the advance's length); then ``chunk`` accumulated."""
    if skip_left > 0:
        return min(skip_left, 8 * chunk)
    return min(cold_rows, chunk) if skip_left == 0 else chunk


@njit(cache=CACHE, fastmath=FAST)
def replay_units(ring: np.ndarray, p0: int, origin: int, i: int, stop: int, skip: int, chunk: int, cold_rows: int,
                 units: int, st: np.ndarray, S: np.ndarray, X: np.ndarray, Xw: np.ndarray, yb: np.ndarray) -> tuple:
    """Up to ``units`` units of a replay (``replay`` of ``replay_unit``'s sizes) from sample i, whose ring position is
    (p0 + i) mod the ring's size, toward ``stop``; ``skip``: the samples after ``origin`` that only advance. Returns
    (the sample after the last one replayed, the last unit's size). One unit a call where the work is spread over
    update() calls; every unit up to the next change-test instant in one call in block mode (the units' sizes,
    hence the statistics bit for bit, are the same either way: ``replay`` adds its rows in blocks that end with
    each call)."""
    size = ring.shape[1]
    n = 0
    while units > 0 and i < stop:
        left = skip - (i - origin)
        n = min(replay_unit(chunk, left, cold_rows), stop - i)
        replay(ring, (p0 + i) % size, n, max(left, 0), st, S, X, Xw, yb)
        i += n
        units -= 1
    return i, n


@njit(cache=CACHE)
def ring_copy(ring: np.ndarray, p0: int, u: np.ndarray, y: np.ndarray) -> None:
    """u, y = the remembered inputs and outputs from ring position p0 on (wrapping), as many as u holds."""
    size = ring.shape[1]
    for k in range(u.shape[0]):
        pos = (p0 + k) % size
        u[k] = ring[0, pos]
        y[k] = ring[1, pos]


@njit(cache=CACHE)
def swap_into(live: np.ndarray, replayed: np.ndarray, theta: np.ndarray, lam: np.ndarray, dx: float) -> None:
    """The state after a replay, in place: ``replayed`` (its states, statistics and coefficients: phi, sy, co; the
    weight, syy, effective samples, linearization point, drift origin) takes the live state's scalars, monitors
    and tail, and the prediction's coefficients for theta at the new point (``set_estimate``). One kernel: as numpy
    slices from Python, in the update() that swaps, it cost ~35-50 us cold; into a new array (``swapped_state``
    until 93452cc) its page was first touched there. The tracker swaps its two state arrays so."""
    q = int(live[SC_NQ])
    nt = int(live[SC_NR]) + int(live[SC_NH])
    p = q + FREE + int(live[SC_NM]) + nt
    o = SC_SIZE
    ztail = ztail_at(q, int(live[SC_NM]), nt)
    g, syy, neff = replayed[SC_G], replayed[SC_SYY], replayed[SC_NEFF]
    a1l, a2l, tref = replayed[SC_A1L], replayed[SC_A2L], replayed[SC_TREF]
    replayed[:o] = live[:o]
    replayed[SC_G], replayed[SC_SYY], replayed[SC_NEFF] = g, syy, neff
    replayed[SC_A1L], replayed[SC_A2L], replayed[SC_TREF] = a1l, a2l, tref
    replayed[o + p:o + 2 * p] = live[o + p:o + 2 * p]    # (between phi and sy)
    nh = int(live[SC_NH])
    if nh == 0:
        replayed[ztail:] = live[ztail:]
    else:                                # the replay's plays and their states stay (its thresholds, its point)
        ho = HK.block_at(q, int(live[SC_NM]), int(live[SC_NR]), nh)
        replayed[ztail:ho] = live[ztail:ho]
        HK.swap_block(live, replayed, ho, nh, q)
    set_estimate(theta, replayed, lam, dx)


@njit(cache=CACHE, fastmath=FAST)
def replay_direct(ring: np.ndarray, p0: int, n: int, skip: int, st: np.ndarray, S: np.ndarray) -> None:
    """``replay`` one rank-one update per sample, as the live kernel accumulates (the reference in the tests)."""
    sc, q, nr, p, phi, m, sy, co, md, nh, ho = _replay_views(st)
    size = ring.shape[1]
    for k in range(n):
        pos = (p0 + k) % size
        y = ring[1, pos]
        if k >= skip and y == y:
            if nh > 0:
                HK.columns(st, ho, nh, q, phi, p - nr - nh, m)
            if nr > 0:
                _drift_regressors(phi, m, md, sc, q, p, nr)
            _accumulate(y, phi, S, sy, sc)
        advance(phi, co, q, ring[0, pos])
        if nh > 0:
            HK.step(st, ho, nh, q, co, ring[0, pos])
        sc[SC_N] += 1.0
