"""Numba kernels of the recursive tracker: the Gauss-Newton RPEM step, its GLR change test, the refresh of
the linearization point, and the layout of their state array (``layout``). The tracker class is
``creep_online.online.trackers.recursive``."""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..policy import change
from . import window as W
from .layout import RESONANCE, co_at, co_size, md_at, resonance_in_co

CACHE = True
FAST = W.FAST
_alarm = njit(cache=CACHE)(change.glr_alarm)
_significant = njit(cache=CACHE)(change.significant)

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
R_MOVE_A1 = 27    # relative moves of a1, a2, b that count as a change, and the sigmas a move must exceed
R_MOVE_A2 = 28    # (``policy.change.GeneralizedLikelihoodRatio.kernel_parameters``)
R_MOVE_B = 29
R_SIGMAS = 30
R_SIZE = 31

#: Per-sample bounds of a step (alpha absolute, ln a1 and ln a2): the recursion stays in the basin.
STEP_ALPHA = 0.002
STEP_LN = 0.02
#: Test statistics kept for the GLR's recent level (``policy.change.GeneralizedLikelihoodRatio.history``).
GLR_HISTORY = 8


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
    return md_at(q, int(sc[W.SC_NM]), 0) + q + W.ONE


@njit(cache=CACHE, inline="always")
def _parts(st: np.ndarray) -> tuple:
    """Views of ``st`` (``layout``): scalars, Q, P, phi, m, co, recursive scalars, n, offset of theta."""
    sc = st[:W.SC_SIZE]
    q = int(sc[W.SC_NQ])
    nm = int(sc[W.SC_NM])
    p = q + W.FREE + nm
    o = W.SC_SIZE
    c0 = co_at(q, nm, 0)
    rb = _base(sc)
    r = st[rb:rb + R_SIZE]
    return sc, q, p, st[o:o + p], st[o + p:o + 2 * p], st[c0:c0 + co_size(q, nm)], r, int(r[R_NP]), rb + R_SIZE


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
        res = resonance_in_co(q)
        W.resonance_coefficients(a1, a2, sc[W.SC_H], co[res:res + RESONANCE])
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


#: theta's entries from this one on (the offset, the free responses, the drift terms) enter the prediction linearly,
#: each through a phi entry of its own (from ``q + ONE`` in order): their Jacobian rows are unit vectors
#: (``W.jacobian_assemble``), so ``_rpem`` reads and moves those entries instead of running over all of phi (in
#: operation 5 of 9 rows, about half of a sample's multiply-adds).
LINEAR_FROM = 4


@njit(cache=CACHE, fastmath=FAST)
def _rpem(e: float, phi: np.ndarray, m: np.ndarray, P: np.ndarray, CT: np.ndarray, sc: np.ndarray,
          r: np.ndarray, theta: np.ndarray, prior: np.ndarray, psi: np.ndarray, ppsi: np.ndarray,
          z: np.ndarray, info: np.ndarray, q: int) -> None:
    """One Gauss-Newton RPEM step with bounded forgetting; the change test's score and information.

    The step keeps its direction when a component is clipped (per-sample bounds
    on alpha, ln a1, ln a2 and b): the whole step shrinks, so the linear
    parameters never compensate a clipped nonlinear move.
    """
    n = theta.shape[0]
    p = phi.shape[0]
    for j in range(LINEAR_FROM):
        s = 0.0
        for i in range(p):
            s += CT[j, i] * phi[i]
        psi[j] = s
    for j in range(LINEAR_FROM, n):     # (the sum above over a unit row: its one entry, +0.0 as the sum starts)
        psi[j] = 0.0 + phi[q + W.ONE + j - LINEAR_FROM]
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
            if j < LINEAR_FROM:
                for i in range(p):
                    m[i] += CT[j, i] * d
            else:                       # (a unit row: the other entries would add zeros)
                m[q + W.ONE + j - LINEAR_FROM] += d
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
    # a physically large move that the block determines (``policy.change.significant``)
    m1 = _significant(jump[1], abs(jump[1]), r[R_MOVE_A1], r[R_SIGMAS], sd1)
    m2 = _significant(jump[2], abs(jump[2]), r[R_MOVE_A2], r[R_SIGMAS], sd2)
    m3 = _significant(jump[3], abs(jump[3]), r[R_MOVE_B] * abs(theta[3]), r[R_SIGMAS], sd3)
    if _alarm(lr, level, quiet, r[R_LIMIT], r[R_JUMPK], m1 or m2 or m3):
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
    """One sample: predict, gate, RPEM update, advance (``_step``), then the change test and the refresh when due
    (``_checks``). Status as ``window.sample``.

    Low bits: 0 accepted, 1 output missing (NaN), 2 rejected as an outlier,
    3 beyond the gate but accepted, 4 not used (adaptation paused or output
    stuck). Flag 8: the caller's work is due (an alarm, or the settle check of an open event).
    """
    sc, q, p, phi, m, co, r, n, t0 = _parts(st)
    zo = t0 + 6 * n + q
    status = _step(u, y, P, CT, sc, q, phi, m, co, r, st[t0:t0 + n], st[t0 + 3 * n:t0 + 4 * n],
                   st[t0 + 4 * n:t0 + 5 * n], st[t0 + 5 * n:t0 + 6 * n], st[zo:zo + n], st[zo + n:zo + n + n * n])
    return status + _checks(st, P, CT)


@njit(cache=CACHE, fastmath=FAST)
def block(u: np.ndarray, y: np.ndarray, st: np.ndarray, P: np.ndarray, CT: np.ndarray,
          status: np.ndarray, start: int = 0, stop: int = -1) -> int:
    """Samples ``start`` to ``stop`` (-1: the end) until due work (flag 8), their statuses from status[0];
    returns how many were consumed (``window.block``). ``sample``'s steps for each sample, bit for bit: the
    samples' steps in runs (``_steps``) up to one at which a check is due, then its checks (``_checks``)."""
    end = u.shape[0] if stop < 0 else stop
    k = start
    while k < end:
        k = _steps(u, y, st, P, CT, status, start, k, end)
        if _checks_due(st):
            flag = _checks(st, P, CT)
            status[k - 1 - start] += flag
            if flag:
                return k - start
    return end - start


#: ``_steps`` runs without numba's reference counts (``_nrt=False``): every array it touches is a view of the caller's,
#: nothing is allocated or returned, and the counts numba otherwise keeps for each view passed to the step's helpers
#: cost more than the step (``_step`` inlined with them: 330 ns a sample; the step written out twice in ``sample``
#: and ``block``: 200 ns; without them: ~145 ns). What it calls must not need the runtime either (a slice copy,
#: an allocation): the checks (``change_test``, ``refresh``) run outside it, in ``_checks``.
NO_REFCOUNTS = {"_nrt": False}


@njit(cache=CACHE, fastmath=FAST, **NO_REFCOUNTS)
def _steps(u: np.ndarray, y: np.ndarray, st: np.ndarray, P: np.ndarray, CT: np.ndarray, status: np.ndarray,
           start: int, k0: int, end: int) -> int:
    """``_step`` for samples k0, k0 + 1, ... up to ``end`` or the first after which a check is due (``_checks_due``);
    their statuses into status[k - start]; returns the index after the last one stepped."""
    sc, q, p, phi, m, co, r, n, t0 = _parts(st)
    theta = st[t0:t0 + n]
    prior = st[t0 + 3 * n:t0 + 4 * n]
    psi = st[t0 + 4 * n:t0 + 5 * n]
    ppsi = st[t0 + 5 * n:t0 + 6 * n]
    zo = t0 + 6 * n + q
    z = st[zo:zo + n]
    info = st[zo + n:zo + n + n * n]
    for k in range(k0, end):
        status[k - start] = _step(u[k], y[k], P, CT, sc, q, phi, m, co, r, theta, prior, psi, ppsi, z, info)
        if _due(sc, r):
            return k + 1
    return end


@njit(cache=CACHE, inline="always")
def _due(sc: np.ndarray, r: np.ndarray) -> bool:
    """After a sample: is the change test's look, the refresh check or the caller's work due (``_checks``)?"""
    n = int(sc[W.SC_N])
    return n % int(r[R_CHECKN]) == 0 or n % int(r[R_EVERY]) == 0 or sc[W.SC_N] >= sc[W.SC_DUE]


@njit(cache=CACHE)
def _checks_due(st: np.ndarray) -> bool:
    """``_due`` on the state array."""
    sc = st[:W.SC_SIZE]
    return _due(sc, st[_base(sc):_base(sc) + R_SIZE])


@njit(cache=CACHE, fastmath=FAST, inline="always")
def _step(u: float, y: float, P: np.ndarray, CT: np.ndarray, sc: np.ndarray, q: int, phi: np.ndarray,
          m: np.ndarray, co: np.ndarray, r: np.ndarray, theta: np.ndarray, prior: np.ndarray, psi: np.ndarray,
          ppsi: np.ndarray, z: np.ndarray, info: np.ndarray) -> int:
    """A sample's step on the views of ``st`` (``_parts``; theta, the prior variances, psi, P psi, the test's score
    and information): the prediction, the gate, the RPEM update, the input's notes and the node states, the count;
    returns the status's low bits (``sample``). ``sample`` and ``block`` (through ``_steps``) both run it."""
    pred = 0.0
    for i in range(phi.shape[0]):
        pred += phi[i] * m[i]
    sc[W.SC_PRED] = pred
    status = 0
    if y != y:
        status = 1
    else:
        status = W.gate(y, pred, sc)
        if status != 2:
            if sc[W.SC_ACC] > 0.0 and sc[W.SC_STUCK] == 0.0:
                _rpem(y - pred, phi, m, P, CT, sc, r, theta, prior, psi, ppsi, z, info, q)
            elif status == 0:
                status = 4
    W.note_input(u, sc)
    W.advance(phi, co, q, u)
    sc[W.SC_N] += 1.0
    if r[R_QUIET] > 0.0:
        r[R_QUIET] -= 1.0
    return status


@njit(cache=CACHE, fastmath=FAST)
def _checks(st: np.ndarray, P: np.ndarray, CT: np.ndarray) -> int:
    """After a sample's ``_step``: the change test when its look is due, the refresh when the estimate left its
    tolerance; returns 8 if the caller's work is due at this sample, else 0."""
    sc, q, p, phi, m, co, r, n, t0 = _parts(st)
    if int(sc[W.SC_N]) % int(r[R_CHECKN]) == 0:
        change_test(st, P, CT, int(sc[W.SC_N]) % int(r[R_TESTN]) == 0)
    if int(sc[W.SC_N]) % int(r[R_EVERY]) == 0:
        theta = st[t0:t0 + n]
        ref = st[t0 + n:t0 + 2 * n]
        if abs(theta[0] - ref[0]) > r[R_TOLA] or abs(theta[1] - ref[1]) > r[R_TOLLN] \
                or abs(theta[2] - ref[2]) > r[R_TOLLN] or abs(theta[3] - ref[3]) > r[R_TOLLN] * abs(ref[3]):
            refresh(st, CT)
    return 8 if sc[W.SC_N] >= sc[W.SC_DUE] else 0
