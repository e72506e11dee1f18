"""The recursive tracker (Remark 3, "carry on with the newest estimate"): a Gauss-Newton RPEM, no replay.

docs/online.md, "Remark 3: window vs recursive": the fractional recursion depends on alpha, so when
alpha (or the resonance) changes one either recomputes over the window
(``tracker.WindowTracker``) or carries on with the newest estimate. This module
is the second strategy. It uses the window tracker's regressor ``phi``
(``window.py``: SOE nodes of the input, the resonance states ``x`` at a
linearization point ``(a1l, a2l)`` with their a1/a2 sensitivity states, the
offset, the free responses) and its coefficient maps, but instead of
statistics and re-fits it runs a recursive prediction-error method on

    theta = [alpha, ln a1, ln a2, b, offset, free-response weights...]

Per sample, in one numba call (``sample``), at a constant cost:

1. prediction ``phi . m`` and its gradient ``psi = C^T phi`` (``C`` the
   Jacobian coefficients of ``window.jacobian_coefficients``: the output error's
   exact gradient, through the sensitivity states for a1 and a2 and the analytic
   SOE-weight derivative for alpha);
2. the shared output gate and monitors (``window.gate``: outliers, stuck output);
3. the Gauss-Newton / Kalman form of the update with exponential forgetting
   ``lambda = 1 - dt/window_s``: ``K = P psi / (psi' P psi + s^2)``,
   ``theta += K e``, ``P = (P - K psi' P) / lambda``, with ``s`` the robust
   innovation scale; the model coefficients follow to first order,
   ``m += C dtheta`` (exact in the linear parameters);
4. bounded forgetting: ``P`` is divided by lambda only while
   ``trace(P / P_reset) < n``, so a direction the input stops exciting does
   not wind up (its variance stops at its reset prior);
5. change detection, a generalised likelihood-ratio test for a jump of the
   parameters (Willsky-Jones) on the normalised innovations: over blocks of
   ``TEST_S`` the score ``z = sum psi e / s^2`` and the information
   ``I = sum psi psi' / s^2`` are accumulated (n^2 per sample); every
   ``CHECK_S`` ``LR = z' I^-1 z`` (chi-square with n degrees of freedom under no
   change) and the jump estimate ``I^-1 z``. A change is declared when LR
   exceeds ``GLR_MIN`` and ``GLR_JUMP`` times the median of the recent blocks (a
   model that is slightly off raises the statistic evenly, a change makes it
   jump) and the jump moves a1, a2 or b by more than ``tracker.CHANGE_MOVE`` and
   ``CHANGE_SIGMAS`` of its own sigma. Then the estimate restarts from the
   block's start (before the change; alpha held: creep does not jump with a
   payload), the covariance is reset in the directions that jumped, and flag 8
   makes the Python side record an event;
6. every ``REFRESH_S`` (1 ms), if theta moved more than the refresh tolerances
   since the last refresh: the linearization point moves to the current
   resonance and the states are carried on to first order,
   ``x(a_new) = x(a_old) + dx/da1 (a1 - a1l) + dx/da2 (a2 - a2l)``
   (measured against the exact simulator: for a 0.5 % move it removes 91 % of
   the prediction jump; the sensitivity states grow with the cycles rung since
   the last input step, hence small, frequent moves; the rest decays with the
   resonance's settling time, the states being stable filters of the input); the
   resonance step, ``C`` and ``m`` are recomputed exactly (a few us, inside
   the same numba call).

Python runs on the sample path only at an alarm (to record the event) and
then every ``refit_every`` samples until the event has settled: in settled
tracking ``update()`` is the numba call and nothing else (a Python slow path
once every 1000 samples, measured, cost 30-70 us there with cold caches).
The fit (``fit``: 1-sigma from ``P``, an absolute covariance because the gain
uses the innovation variance) is built when the estimate is read. Drift: with
forgetting the estimate follows slow drift by itself (lagging by about rate x
window_s); ``b_rate`` and ``alpha_rate`` are 0. Measured against the window
tracker: docs/online.md, "Remark 3: window vs recursive".
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import window as W
from .checkpoint import Checkpointable
from .soe import SoeBasis
from .tracker import CHANGE_MOVE, CHANGE_SIGMAS, FREE_RATES, Fit, ParameterView, _largest_move

CACHE = True
CHANGE_MOVE_A1 = CHANGE_MOVE["a1"]
CHANGE_MOVE_A2 = CHANGE_MOVE["a2"]
CHANGE_MOVE_B = CHANGE_MOVE["b"]
FAST = W.FAST

# indices into the recursive scalars (after the window layout in ``st``)
R_FORGET = 0      # lambda
R_TESTN = 1       # samples per test block
R_NHIST = 2       # test statistics in the history (at most GLR_HISTORY)
R_LR = 3          # the last block's statistic
R_JUMPK = 4       # GLR_JUMP
R_LIMIT = 5       # GLR_MIN (inf: no change detection)
R_ALARMS = 6      # alarms raised (Python compares with what it has recorded)
R_QUIET = 7       # samples left during which no new alarm is raised (re-convergence)
R_QUIETN = 8      # that hold, in samples
R_EVERY = 9       # refresh check period (samples)
R_REFRESHES = 10  # exact refreshes of C and m
R_RELIN = 11      # moves of the linearization point (states carried on)
R_LO = 12         # alpha bounds
R_HI = 13
R_DX = 14         # SOE node spacing
R_COST = 15       # mean e^2 over the forgetting window (times R_COSTW; restarted at a detected change)
R_COSTK = 16      # its smoothing factor
R_SNAPN = 17      # sample index of the test block's start
R_ALARMN = 18     # R_SNAPN at the last alarm: the change happened after it
R_LNA2MIN = 19    # lower bound of ln a2 (resonance below fs/2)
R_NP = 20         # number of parameters n
R_TOLA = 21       # refresh tolerance of alpha (absolute)
R_TOLLN = 22      # refresh tolerance of ln a1, ln a2 and of b (relative)
R_EVLR = 23       # LR at the last alarm
R_UPDATES = 24    # parameter updates (accepted samples)
R_CHECKN = 25     # samples between interim looks of the change test (divides R_TESTN)
R_COSTW = 26      # weight of R_COST (the same smoothing of 1): R_COST / R_COSTW is the mean, also when restarted
R_SIZE = 27

#: Per-sample bounds of a step (alpha absolute, ln a1 and ln a2): the recursion stays in the basin.
STEP_ALPHA = 0.002
STEP_LN = 0.02
#: Refresh check period (s) and tolerances: below them the first-order update of m is exact to
#: ~1e-4 of the output (second-order terms), far below the noise.
REFRESH_S = 1e-3
TOL_ALPHA = 1e-3
TOL_LN = 5e-3
#: GLR change test: block length (s), threshold (chi-square, n <= 9 degrees of freedom: p < 1e-15),
#: jump factor against the median of the last GLR_HISTORY blocks; after a detected change no new
#: alarm for QUIET_S and the history restarts (the re-convergence is itself a burst of innovations).
TEST_S = 0.5
CHECK_S = 0.05
GLR_MIN = 100.0
GLR_JUMP = 5.0
GLR_HISTORY = 8
QUIET_S = 1.5
#: A detection within this long (s) of the last one (or of its restart) restarts that event.
MERGE_S = 5.0
#: Prior 1-sigma at the start (from the search) and after a detected change: alpha (absolute,
#: plus a share of alpha), ln a1, ln a2, b (relative); offset and free responses in output units.
START_SD = {"alpha": 0.01, "alpha_rel": 0.1, "ln_a": 0.1, "b_rel": 0.1, "offset_rel": 10.0}
RESET_SD = {"ln_a": 0.3, "b_rel": 0.3}


def layout(q: int, n_free: int) -> dict:
    """Offsets of the parts of ``st``: the window layout (``window.layout``, no drift columns), then
    the recursive scalars (R_SIZE), theta, theta at the last refresh, theta at the test block's start,
    the reset prior variances, psi, P psi (n each), the SOE nodes lam (q), the test block's score z (n),
    information I (n x n, flat) and the history of its statistics (GLR_HISTORY)."""
    o = W.layout(q, n_free, 0)
    n = 5 + n_free
    o["r"] = o["size"]
    o["theta"] = o["r"] + R_SIZE
    o["ref"] = o["theta"] + n
    o["snap"] = o["ref"] + n
    o["prior"] = o["snap"] + n
    o["psi"] = o["prior"] + n
    o["ppsi"] = o["psi"] + n
    o["lam"] = o["ppsi"] + n
    o["z"] = o["lam"] + q
    o["info"] = o["z"] + n
    o["hist"] = o["info"] + n * n
    o["work"] = o["hist"] + GLR_HISTORY
    o["size"] = o["work"] + _work_size(n, o["p"])
    o["n"] = n
    return o


@njit(cache=CACHE)
def _work_size(n: int, p: int) -> int:
    """Scratch of the test and the refresh (no allocation on the sample path): two n x n matrices, three
    n-vectors, the sorted history, and the P x n Jacobian."""
    return 2 * n * n + 3 * n + GLR_HISTORY + p * n


@njit(cache=CACHE)
def _base(sc: np.ndarray) -> int:
    """Offset of the recursive scalars in st (the window layout's size)."""
    q = int(sc[W.SC_NQ])
    nm = int(sc[W.SC_NM])
    p = q + W.FREE + nm
    return W.SC_SIZE + 3 * p + 2 * q + 18 + nm + q + q + W.ONE


@njit(cache=CACHE)
def _parts(st: np.ndarray) -> tuple:
    """Views of ``st`` (``layout``): scalars, Q, P, phi, m, co, recursive scalars, n, offset of theta."""
    sc = st[:W.SC_SIZE]
    q = int(sc[W.SC_NQ])
    nm = int(sc[W.SC_NM])
    p = q + W.FREE + nm
    o = W.SC_SIZE
    c0 = o + 3 * p
    rb = _base(sc)
    r = st[rb:rb + R_SIZE]
    return sc, q, p, st[o:o + p], st[o + p:o + 2 * p], st[c0:c0 + 2 * q + 18 + nm], r, int(r[R_NP]), rb + R_SIZE


@njit(cache=CACHE)
def refresh(st: np.ndarray, CT: np.ndarray) -> None:
    """Move the linearization point to the current resonance (states carried on to first order) and
    recompute the resonance step, the Jacobian coefficients ``CT`` (n x P) and ``m`` exactly."""
    sc, q, p, phi, m, co, r, n, t0 = _parts(st)
    theta = st[t0:t0 + n]
    ref = st[t0 + n:t0 + 2 * n]
    lam = st[t0 + 6 * n:t0 + 6 * n + q]
    a1 = math.exp(theta[1])
    a2 = math.exp(theta[2])
    d1 = a1 - sc[W.SC_A1L]
    d2 = a2 - sc[W.SC_A2L]
    if d1 != 0.0 or d2 != 0.0:
        for j in range(2):
            phi[q + j] += phi[q + W.S1 + j] * d1 + phi[q + W.S2 + j] * d2
        W.resonance_coefficients(a1, a2, sc[W.SC_H], co[2 * q:2 * q + 18])
        sc[W.SC_A1L] = a1
        sc[W.SC_A2L] = a2
        r[R_RELIN] += 1.0
    wo = t0 + 7 * n + q + n * n + GLR_HISTORY + 2 * n * n + 3 * n + GLR_HISTORY
    C = st[wo:wo + p * n].reshape((p, n))
    W.jacobian_coefficients(theta, a1, a2, lam, r[R_DX], C)
    for i in range(p):
        s = 0.0
        for j in range(n):
            CT[j, i] = C[i, j]
            if j >= 3:
                s += C[i, j] * theta[j]
        m[i] = s
    for j in range(n):
        ref[j] = theta[j]
    sc[W.SC_BABS] = abs(theta[3])
    settle = 8.0 * a2 / a1
    sc[W.SC_HOLD] = min(max(20.0, 2.0 * settle / sc[W.SC_H]), 2.0 / sc[W.SC_H])
    r[R_REFRESHES] += 1.0


@njit(cache=CACHE, fastmath=FAST)
def _rpem(e: float, phi: np.ndarray, m: np.ndarray, P: np.ndarray, CT: np.ndarray, sc: np.ndarray,
          r: np.ndarray, theta: np.ndarray, prior: np.ndarray, psi: np.ndarray, ppsi: np.ndarray,
          z: np.ndarray, info: np.ndarray) -> None:
    """One Gauss-Newton RPEM step with bounded forgetting; the change test's score and information.

    The step keeps its direction when a component is clipped (per-sample bounds
    on alpha, ln a1, ln a2 and b): the whole step shrinks, so the linear
    parameters never compensate a clipped nonlinear move.
    """
    n = theta.shape[0]
    p = phi.shape[0]
    for j in range(n):
        s = 0.0
        for i in range(p):
            s += CT[j, i] * phi[i]
        psi[j] = s
    spp = 0.0
    for j in range(n):
        s = 0.0
        for k in range(n):
            s += P[j, k] * psi[k]
        ppsi[j] = s
        spp += psi[j] * s
    spp = max(spp, 0.0)
    lamv = max(sc[W.SC_SCALE] * sc[W.SC_SCALE], sc[W.SC_NOISE] * sc[W.SC_NOISE], 1e-300)
    s = spp + lamv
    w = e / lamv
    for j in range(n):
        z[j] += psi[j] * w
        pj = psi[j] / lamv
        for k in range(n):
            info[j * n + k] += pj * psi[k]
    f = e / s
    shrink = 1.0
    shrink = min(shrink, STEP_ALPHA / (abs(ppsi[0] * f) + 1e-300))
    shrink = min(shrink, STEP_LN / (abs(ppsi[1] * f) + 1e-300), STEP_LN / (abs(ppsi[2] * f) + 1e-300))
    shrink = min(shrink, STEP_LN * abs(theta[3]) / (abs(ppsi[3] * f) + 1e-300))
    f *= shrink
    for j in range(n):
        d = ppsi[j] * f
        if j == 0:
            d = min(max(theta[0] + d, r[R_LO]), r[R_HI]) - theta[0]
        elif j == 2:
            d = max(theta[2] + d, r[R_LNA2MIN]) - theta[2]
        if d != 0.0:
            theta[j] += d
            for i in range(p):
                m[i] += CT[j, i] * d
    tr = 0.0
    for i in range(n):
        for k in range(n):
            P[i, k] -= ppsi[i] * ppsi[k] / s
        tr += P[i, i] / prior[i]
    if tr < n and r[R_FORGET] < 1.0:
        f = 1.0 / r[R_FORGET]
        for i in range(n):
            for k in range(n):
                P[i, k] *= f
    r[R_COST] += r[R_COSTK] * (e * e - r[R_COST])
    r[R_COSTW] += r[R_COSTK] * (1.0 - r[R_COSTW])
    r[R_UPDATES] += 1.0


@njit(cache=CACHE)
def change_test(st: np.ndarray, P: np.ndarray, CT: np.ndarray, final: bool) -> None:
    """The GLR statistic of a parameter jump over the block so far; on a change, restart from the estimate at
    the block's start and reset P. ``final``: the block ends (its statistic joins the history, the next one
    starts); otherwise an interim look (every ``CHECK_S``: a change is caught within ~50 ms of the step that
    reveals it, while its transient still rings for the re-started recursion)."""
    sc = st[:W.SC_SIZE]
    q = int(sc[W.SC_NQ])
    rb = _base(sc)
    r = st[rb:rb + R_SIZE]
    n = int(r[R_NP])
    t0 = rb + R_SIZE
    theta = st[t0:t0 + n]
    snap = st[t0 + 2 * n:t0 + 3 * n]
    prior = st[t0 + 3 * n:t0 + 4 * n]
    zo = t0 + 6 * n + q
    z = st[zo:zo + n]
    info = st[zo + n:zo + n + n * n]
    hist = st[zo + n + n * n:zo + n + n * n + GLR_HISTORY]
    wo = zo + n + n * n + GLR_HISTORY
    A = st[wo:wo + n * n].reshape((n, n))
    L = st[wo + n * n:wo + 2 * n * n].reshape((n, n))
    v = wo + 2 * n * n
    d = st[v:v + n]
    rhs = st[v + n:v + 2 * n]
    jump = st[v + 2 * n:v + 3 * n]
    srt = st[v + 3 * n:v + 3 * n + GLR_HISTORY]
    # the normalised information (unit diagonal; a parameter without information cannot jump)
    for i in range(n):
        d[i] = math.sqrt(abs(info[i * n + i]) * (1.0 + 1e-9)) + 1e-150
    finite = True
    for i in range(n):
        for k in range(n):
            A[i, k] = info[i * n + k] / (d[i] * d[k])
            finite = finite and math.isfinite(A[i, k])
        A[i, i] *= 1.0 + 1e-9
        rhs[i] = z[i] / d[i]
        finite = finite and math.isfinite(rhs[i])
    lr = 0.0
    sd1 = math.inf                     # 1-sigma of the jump in ln a1, ln a2, b: sqrt(diag(I^-1))
    sd2 = math.inf
    sd3 = math.inf
    if finite and W._cholesky(A, L):
        W._cholesky_solve(L, rhs, jump)
        for i in range(n):
            lr += jump[i] * rhs[i]
            jump[i] /= d[i]
        for j in range(1, 4):
            for i in range(n):
                rhs[i] = 1.0 if i == j else 0.0
            W._cholesky_solve(L, rhs, A[0])        # A is free now: its first row holds the column
            sdj = math.sqrt(abs(A[0, j])) / d[j]
            if j == 1:
                sd1 = sdj
            elif j == 2:
                sd2 = sdj
            else:
                sd3 = sdj
    else:
        for i in range(n):
            jump[i] = 0.0
    r[R_LR] = lr
    quiet = r[R_QUIET] > 0.0
    nh = int(r[R_NHIST])
    level = _median(hist, nh, srt) if nh >= GLR_HISTORY // 2 else math.inf    # no reference yet: no alarm
    # a physically large move (tracker.CHANGE_MOVE) that the block determines (CHANGE_SIGMAS of its 1-sigma)
    m1 = abs(jump[1]) > CHANGE_MOVE_A1 and abs(jump[1]) > CHANGE_SIGMAS * sd1
    m2 = abs(jump[2]) > CHANGE_MOVE_A2 and abs(jump[2]) > CHANGE_SIGMAS * sd2
    m3 = abs(jump[3]) > CHANGE_MOVE_B * abs(theta[3]) and abs(jump[3]) > CHANGE_SIGMAS * sd3
    big = m1 or m2 or m3
    if not quiet and lr > r[R_LIMIT] and lr > r[R_JUMPK] * level and big:
        # the estimate as before the change (the block's start): the samples since chased the change with the
        # old covariance; the re-convergence starts from there, alpha held (creep does not jump)
        # (the linearised jump I^-1 z is not applied: measured, for a 71 % stiffness change it pointed a2 the
        # wrong way and the recursion diverged; it only decides which directions are reset)
        for j in range(4):
            theta[j] = snap[j]
        # covariance resetting in the directions that jumped: the resonance (a1 and a2 together: a new a2
        # moves the best a1) and/or the gain, and the offset; alpha keeps its variance, nothing else moves
        for j in range(1, 5):
            if j == 4 or (j <= 2 and (m1 or m2)) or (j == 3 and m3):
                for k in range(n):
                    P[j, k] = 0.0
                    P[k, j] = 0.0
                P[j, j] = prior[j]
        r[R_ALARMS] += 1.0
        r[R_ALARMN] = r[R_SNAPN]
        r[R_EVLR] = lr
        r[R_QUIET] = r[R_QUIETN]
        r[R_NHIST] = 0.0
        r[R_COST] = 0.0                    # the window error restarts with the change, as the window tracker's
        r[R_COSTW] = 0.0
        sc[W.SC_DUE] = sc[W.SC_N]          # the caller records the event at this sample (flag 8)
        refresh(st, CT)
    elif not final:
        return
    elif not quiet:
        if nh < GLR_HISTORY:
            hist[nh] = lr
            r[R_NHIST] = nh + 1
        else:
            for i in range(GLR_HISTORY - 1):
                hist[i] = hist[i + 1]
            hist[GLR_HISTORY - 1] = lr
    for j in range(n):
        z[j] = 0.0
        if r[R_QUIET] != r[R_QUIETN]:    # at an alarm snap keeps the estimate before the change (the event's)
            snap[j] = theta[j]
    for j in range(n * n):
        info[j] = 0.0
    r[R_SNAPN] = sc[W.SC_N]


@njit(cache=CACHE)
def _median(x: np.ndarray, count: int, work: np.ndarray) -> float:
    """Median of x[:count] (insertion sort into work: a handful of values, no allocation)."""
    for i in range(count):
        v = x[i]
        j = i
        while j > 0 and work[j - 1] > v:
            work[j] = work[j - 1]
            j -= 1
        work[j] = v
    h = count // 2
    return work[h] if count % 2 else 0.5 * (work[h - 1] + work[h])


@njit(cache=CACHE, fastmath=FAST)
def sample(u: float, y: float, st: np.ndarray, P: np.ndarray, CT: np.ndarray) -> int:
    """One sample: predict, gate, RPEM update, CUSUM, advance, refresh when due. Status as ``window.sample``.

    Low bits: 0 accepted, 1 output missing (NaN), 2 rejected as an outlier,
    3 beyond the gate but accepted, 4 not used (adaptation paused or output
    stuck). Flag 8: the caller's work is due (an alarm, or the settle check of an open event).
    """
    sc, q, p, phi, m, co, r, n, t0 = _parts(st)
    theta = st[t0:t0 + n]
    pred = 0.0
    for i in range(p):
        pred += phi[i] * m[i]
    sc[W.SC_PRED] = pred
    status = 0
    if y != y:
        status = 1
    else:
        status = W.gate(y, pred, sc)
        if status != 2:
            if sc[W.SC_ACC] > 0.0 and sc[W.SC_STUCK] == 0.0:
                zo = t0 + 6 * n + q
                _rpem(y - pred, phi, m, P, CT, sc, r, theta, st[t0 + 3 * n:t0 + 4 * n], st[t0 + 4 * n:t0 + 5 * n],
                      st[t0 + 5 * n:t0 + 6 * n], st[zo:zo + n], st[zo + n:zo + n + n * n])
            elif status == 0:
                status = 4
    W.note_input(u, sc)
    W.advance(phi, co, q, u)
    sc[W.SC_N] += 1.0
    if r[R_QUIET] > 0.0:
        r[R_QUIET] -= 1.0
    if int(sc[W.SC_N]) % int(r[R_CHECKN]) == 0:
        change_test(st, P, CT, int(sc[W.SC_N]) % int(r[R_TESTN]) == 0)
    if int(sc[W.SC_N]) % int(r[R_EVERY]) == 0:
        ref = st[t0 + n:t0 + 2 * n]
        if abs(theta[0] - ref[0]) > r[R_TOLA] or abs(theta[1] - ref[1]) > r[R_TOLLN] \
                or abs(theta[2] - ref[2]) > r[R_TOLLN] or abs(theta[3] - ref[3]) > r[R_TOLLN] * abs(ref[3]):
            refresh(st, CT)
    if sc[W.SC_N] >= sc[W.SC_DUE]:
        status += 8
    return status


@njit(cache=CACHE)
def block(u: np.ndarray, y: np.ndarray, st: np.ndarray, P: np.ndarray, CT: np.ndarray,
          status: np.ndarray, start: int = 0, stop: int = -1) -> int:
    """Samples ``start`` to ``stop`` (-1: the end) until due work (flag 8), their statuses from status[0];
    returns how many were consumed (``window.block``)."""
    end = u.shape[0] if stop < 0 else stop
    for k in range(start, end):
        s = sample(u[k], y[k], st, P, CT)
        status[k - start] = s
        if s >= 8:
            return k - start + 1
    return end - start


class RecursiveTracker(ParameterView, Checkpointable):
    """Gauss-Newton RPEM on the window tracker's regressor: constant work per sample, no replay.

    The estimator reads the same names as from ``WindowTracker``: ``alpha``,
    ``a1``, ``a2``, ``b``, ``offset``, ``fit`` (theta, cost, neff, 1-sigma,
    sample), ``events``, ``sc`` (the shared monitors and counters),
    ``phi``/``co``/``m`` for ``predict_one``.
    """

    def __init__(self, basis: SoeBasis, theta: np.ndarray, *, window_s: float | None, free: bool,
                 gate: float, burst: int, stuck: int, alpha_bounds: tuple[float, float], refit_every: int,
                 detect: bool, scale: float) -> None:
        self.basis = basis
        self.h = h = basis.h
        self.q = q = basis.size
        self.n_free = len(FREE_RATES) if free else 0
        self.n_rate = 0
        self.lay = lay = layout(q, self.n_free)
        self.p = lay["p"]
        self.refit_every = refit_every
        self.detect = detect
        self.forget = 1.0 if window_s is None else 1.0 - h / window_s
        #: samples per unit when the estimator replays its start-up buffer into the tracker (~6 us)
        self.feed_chunk = max(4, 6000 // (2 * self.p * (5 + self.n_free)))
        self.fitting = True
        self.drift_on = False
        self.events: list[dict] = []
        self.researches: list[dict] = []   # the window tracker's re-searches of the resonance; none here
        self.disagreement: dict | None = None   # the window tracker's change-test disagreement; none here
        self.false_alarms = 0            # alarms after which nothing moved (no event kept)
        self.rejected = 0                # never: the recursion has no fits to reject
        self._jobs: list = []            # no background jobs: the interface the estimator polls
        self._alarms = 0
        n = lay["n"]
        st = np.zeros(lay["size"])
        theta0 = np.zeros(n)
        theta0[:len(theta)] = theta
        a1, a2 = math.exp(theta0[1]), math.exp(theta0[2])
        W.start_state(st, basis.decay, basis.gain, np.exp(-np.asarray(FREE_RATES[:self.n_free]) * h),
                      self.forget, h, a1, a2, 0)
        W.set_monitors(st[:W.SC_SIZE], h, gate, burst, stuck)
        st[W.SC_DUE] = math.inf          # Python is called only at an alarm (and until its event settles)
        co = st[lay["co"]:lay["ztail"]]
        phi = st[lay["phi"]:lay["m"]]
        r = st[lay["r"]:lay["theta"]]
        lo, hi = alpha_bounds
        check = max(1, round(CHECK_S / h))
        r[[R_FORGET, R_TESTN, R_CHECKN, R_JUMPK, R_LIMIT, R_QUIETN, R_EVERY, R_LO, R_HI, R_DX, R_COSTK, R_LNA2MIN,
           R_NP, R_TOLA, R_TOLLN]] = [
            self.forget, check * max(1, round(TEST_S / (check * h))), check, GLR_JUMP, GLR_MIN if detect else math.inf,
            round(QUIET_S / h), max(1, round(REFRESH_S / h)), lo, hi, basis.dx,
            min(1.0, h / (window_s or 30.0)), 2.0 * math.log(h / math.pi), n, TOL_ALPHA, TOL_LN]
        st[lay["theta"]:lay["ref"]] = theta0
        st[lay["snap"]:lay["prior"]] = theta0
        st[lay["lam"]:lay["z"]] = basis.lam
        b, sc_out = abs(theta0[3]), max(abs(scale), 1e-150)
        alpha0 = float(theta0[0])
        start = np.full(n, (START_SD["offset_rel"] * sc_out) ** 2)
        start[:4] = [(START_SD["alpha"] + START_SD["alpha_rel"] * alpha0) ** 2, START_SD["ln_a"] ** 2,
                     START_SD["ln_a"] ** 2, (START_SD["b_rel"] * b) ** 2]
        prior = start.copy()
        prior[1:4] = [RESET_SD["ln_a"] ** 2, RESET_SD["ln_a"] ** 2, (RESET_SD["b_rel"] * b) ** 2]
        st[lay["prior"]:lay["psi"]] = prior
        self.st = st
        self.sc = st[:W.SC_SIZE]
        self.r = r
        self.theta = st[lay["theta"]:lay["ref"]]
        self.phi = phi
        self.m = st[lay["m"]:lay["sy"]]
        self.co = co
        self.S = self.P = np.diag(start)     # S: the name the estimator's shared code passes
        self.ring = self.CT = np.zeros((n, self.p))
        refresh(st, self.CT)
        self._check = self.theta[:4].tolist()     # the estimate at the last settle check
        self._fit: Fit | None = None

    # ------------------------------------------------------------------ parameters
    b_rate = 0.0                         # drift is followed by the forgetting, not modelled
    alpha_rate = 0.0

    @property
    def n(self) -> int:
        """Samples fed."""
        return int(self.sc[W.SC_N])

    @property
    def prediction(self) -> float:
        return float(self.sc[W.SC_PRED])

    @property
    def relinearizations(self) -> int:
        """Moves of the linearization point (states carried on, never replayed)."""
        return int(self.r[R_RELIN])

    # ------------------------------------------------------------------ per sample
    def feed(self, u: float, y: float) -> int:
        """One sample (u as applied, y measured; NaN y = missing). Returns the kernel's status."""
        status = sample(u, y, self.st, self.P, self.CT)
        if status >= 8:
            self._schedule()
        return status

    def feed_block(self, u: np.ndarray, y: np.ndarray, status: np.ndarray, start: int = 0, stop: int = -1) -> int:
        """Samples ``start`` to ``stop`` (-1: the end) up to the next publication or alarm; returns how many were
        consumed."""
        used = block(u, y, self.st, self.P, self.CT, status, start, stop)
        if status[used - 1] >= 8:
            self._schedule()
        return used

    def work(self, units: int = 1) -> bool:
        """No background work: everything is done per sample (the estimator's polling interface)."""
        return True

    def finish(self) -> None:
        """Nothing queued (block mode)."""

    busy = False

    # ------------------------------------------------------------------ publication and events
    def _schedule(self) -> None:
        """Record a new alarm; while an event is open check every ``refit_every`` samples whether it settled."""
        alarms = int(self.r[R_ALARMS])
        if alarms > self._alarms:
            self._alarms = alarms
            self._record_alarm()
        elif self.events and not self.events[-1]["settled"]:
            self._settle_events(self._check)
        self._check = self.theta[:4].tolist()
        self.sc[W.SC_DUE] = self.n + self.refit_every if self.events and not self.events[-1]["settled"] else math.inf

    @property
    def refits(self) -> int:
        """Parameter updates (one per accepted sample)."""
        return int(self.r[R_UPDATES])

    @property
    def fit(self) -> Fit:
        """The current estimate as a fit: theta, mean squared innovation over the window times its effective
        length, the 1-sigma from P (built when read, cached per sample)."""
        n = self.n
        if self._fit is not None and self._fit.sample == n:
            return self._fit
        new = self.theta.tolist()
        sd = [math.sqrt(v) if v >= 0.0 else math.inf for v in self.P.diagonal().tolist()]
        a1, a2 = math.exp(new[1]), math.exp(new[2])
        std = {"alpha": sd[0], "a1": sd[1] * a1, "a2": sd[2] * a2, "b": sd[3], "offset": sd[4]}
        neff = min(float(self.r[R_UPDATES]), 1.0 / max(1.0 - self.forget, 1e-300))
        mean = float(self.r[R_COST]) / float(self.r[R_COSTW]) if self.r[R_COSTW] > 0.0 else 0.0
        self._fit = Fit(theta=self.theta.copy(), cost=mean * neff, neff=neff, std=std, sample=n)
        return self._fit

    def _record_alarm(self) -> None:
        """The change test fired (covariance already reset by the kernel): open an event, or restart the last
        one when it is open or was detected less than ``MERGE_S`` ago (the same change seen again while the
        resonance re-converges: one event, whose moves are measured from before it once all has settled)."""
        g = float(self.r[R_EVLR])
        last = self.events[-1] if self.events else None
        now = self.n * self.h
        if last is not None and (not last["settled"] or now - last["_last_t"] < MERGE_S):
            last["restarts"] += 1
            last["lr"] = max(last["lr"], g)
            last["settled"] = False
            last["_last_t"] = now
            last.pop("settled_t", None)
            return
        snap = self.st[self.lay["snap"]:self.lay["prior"]]
        self.events.append({"t": float(self.r[R_ALARMN]) * self.h, "detected_t": self.n * self.h, "moved": [],
                            "relative_change": {}, "lr": g, "settled": False, "restarts": 1,
                            "estimate_settled": None,     # (not judged here: see tracker._settled_before)
                            "_before": snap[:4].copy(), "_last_t": self.n * self.h})

    def _settle_events(self, previous: list[float]) -> None:
        """Once the estimate has stopped moving after a change, record what moved; an alarm after which
        nothing moved beyond ``tracker.CHANGE_MOVE`` was a false alarm and leaves no event."""
        ev = self.events[-1]
        now = self.theta[:4].tolist()
        if _largest_move(now, previous) < 0.002 and self.n * self.h - ev["_last_t"] > 1.0:
            before = ev["_before"]
            change = {"alpha": now[0] / before[0] - 1, "a1": math.exp(now[1] - before[1]) - 1,
                      "a2": math.exp(now[2] - before[2]) - 1, "b": now[3] / before[3] - 1}
            moved = sorted(k for k, v in change.items() if abs(v) > CHANGE_MOVE.get(k, 0.02))
            if not moved:
                self.events.pop()
                self.false_alarms += 1
                return
            ev.update(relative_change={k: float(v) for k, v in change.items()}, moved=moved, settled=True,
                      settled_t=self.n * self.h)

    # --- tracker protocol (online/trackers/protocol.py)
    def advance(self, u: float, y: float, units: int, work: bool = True) -> bool:
        """One live sample (no background work here: ``units`` and ``work`` are the window tracker's). Returns False
        only when the check at an alarm or a settle check finds the state non-finite."""
        status = sample(u, y, self.st, self.P, self.CT)
        if status >= 8:
            self._schedule()
            return self.state_finite()
        return True

    def state_finite(self) -> bool:
        """Are the estimate, the covariance's diagonal and the live prediction all finite?"""
        return W.state_finite(self.theta, self.S, self.sc)

    def predict_next(self, u: float) -> float:
        """The model output at the next sample if ``u`` (as applied) is applied now; no state changes."""
        phi = self.phi.copy()
        W.advance(phi, self.co, self.q, u)
        return float(phi @ self.m)

    def begin_replay(self, noise: float, adapting: bool) -> None:
        """Before the start-up buffer is replayed: the noise monitor at ``noise``."""
        self.sc[W.SC_NOISE] = noise
        if not adapting:
            self.sc[W.SC_ACC] = 0.0
        self.fitting = False

    def restart_monitors(self, noise: float) -> None:
        """The output monitors as at a stream's first sample (``window.restart_monitors``)."""
        W.restart_monitors(self.sc, noise)

    def go_live(self, outlier_gate: float) -> None:
        """The start-up buffer replayed: the outlier gate open at ``outlier_gate`` (no jobs: updates are per sample)."""
        self.sc[W.SC_GATE] = float(outlier_gate)
        self.fitting = True

    def drain(self) -> None:
        """Nothing queued (a checkpoint's drain)."""

    @property
    def adapting(self) -> bool:
        """Do the updates move the estimate (False: frozen)?"""
        return bool(self.sc[W.SC_ACC])

    @adapting.setter
    def adapting(self, on: bool) -> None:
        self.sc[W.SC_ACC] = 1.0 if on else 0.0

    @property
    def noise_level(self) -> float:
        """The output noise monitor's standard deviation."""
        return float(self.sc[W.SC_NOISE])

    @property
    def live_error_power(self) -> float:
        """Mean square of the live prediction error over the last ~0.2 s."""
        return float(self.sc[W.SC_E2])

    @property
    def outliers(self) -> int:
        """Outputs the gate did not use."""
        return int(self.sc[W.SC_OUTLIERS])

    @property
    def shifts(self) -> int:
        """Runs of gated outputs longer than the burst: shifts, not outliers."""
        return int(self.sc[W.SC_SHIFTS])

    @property
    def output_stuck(self) -> bool:
        """Is the output frozen or clipped while the model says it moves?"""
        return bool(self.sc[W.SC_STUCK])

    @property
    def input_held_samples(self) -> float:
        """Samples since the input last changed."""
        return float(self.sc[W.SC_SINCE])

    def drop_failed_jobs(self) -> list[str] | None:
        """No background jobs: a fault is never confined to one (None)."""
        return None

    remembered_window = 0                # no samples are remembered: a restart starts from new ones

    def copy_recent(self, u: np.ndarray, y: np.ndarray) -> None:
        """Nothing remembered (``remembered_window`` is 0)."""


def warm() -> None:
    """Compile (or load from numba's cache) the recursive kernels."""
    basis = SoeBasis.build(1e-3, horizon_s=10.0)
    tr = RecursiveTracker(basis, np.array([0.1, math.log(2e-3), math.log(1e-6), 1.0, 0.0]), window_s=1.0, free=True,
                          gate=8.0, burst=2, stuck=10, alpha_bounds=(0.005, 0.9), refit_every=50, detect=True,
                          scale=1.0)
    u = np.r_[np.zeros(10), np.ones(200)]
    tr.feed_block(u, 0.5 * u, np.empty(u.size, dtype=np.int64))
    tr.feed(1.0, 0.5)
    tr.feed(1.0, math.nan)
