"""The window tracker's re-fit as a numba state machine: one kernel call per unit of background work.

A re-fit (the window's statistics, Levenberg-Marquardt steps, the covariance, the drift test) runs
about ten times a second at 10 kHz. As a Python generator with numpy glue between its kernels it
cost 20-110 us per unit: by the time a re-fit runs, the interpreter's and numpy's code paths are
cold, and each line of glue (an array copy, a mask, a scalar read from an array) costs far more than
its warm microsecond. Here the whole re-fit lives in one flat work array (``allocate``) and
``refit_unit`` advances it by one stage per call; the tracker's Python starts it and reads the
result once (``result``).

Work array: a header of scalars (``RF_*``), then theta, the covariance's diagonal, and the arrays
of the fit (statistics F, fy; J^T J and J^T r; the covariance; the drift test's normal equations;
the three parameter masks).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import window as W

CACHE = True

# header of the work array
RF_STAGE = 0      # next stage (0 start, 1 normal equations, 2 trial step, 3 covariance, 4-5 drift score)
RF_STEP = 1       # Levenberg-Marquardt steps taken
RF_MU = 2         # damping (carried from one re-fit to the next)
RF_FYY = 3        # sum of squares of the window's output (true scale)
RF_COST = 4       # window cost at theta before the last trial step
RF_A1L = 5        # linearization point the statistics were taken at
RF_A2L = 6
RF_LO = 7         # alpha bounds
RF_HI = 8
RF_STEPS = 9      # Levenberg-Marquardt steps per re-fit
RF_BEFORE = 10    # out = [cost before, cost after, accepted] of the last lm_trial
RF_AFTER = 11     # window cost at the result
RF_MOVED = 12     # 1 if the last trial step was accepted
RF_NEFF = 13      # effective samples of the window at the result
RF_DRIFT = 14     # drift test run: 0 none, 1 score test (rates off), 2 Wald test (rates on)
RF_DRIFT_STAT = 15
RF_DRIFT_SWITCH = 16   # +1 switch the rates on, -1 off (their values zeroed), 0 keep
RF_DRIFT_ON = 17  # thresholds (the tracker's DRIFT_ON, DRIFT_OFF, DRIFT_MAX)
RF_DRIFT_OFF = 18
RF_DRIFT_MAX = 19
RF_SIGMA2 = 20    # noise variance of the drift test
RF_K = 21         # number of parameters
RF_R0 = 22        # first drift-rate parameter
RF_START_COST = 23   # window cost at the starting theta (the first normal equations')
HEAD = 24

#: Parameter masks (rows of the masks block): all free, drift rates fixed, alpha and rates fixed, and the
#: change test's (the resonance, the gain and the offset).
MASK_ALL, MASK_CONSTANT, MASK_HOLD, MASK_TEST = 0, 1, 2, 3
MASKS = 4


def allocate(p: int, k: int, r0: int, steps: int, alpha_bounds: tuple[float, float], drift_on: float,
             drift_off: float, drift_max: float) -> np.ndarray:
    """A fresh work array for statistics of size p and k parameters (rates from r0 on)."""
    wk = np.zeros(HEAD + 2 * k + 3 * k * k + 2 * k + p * p + p + MASKS * k)
    wk[RF_MU] = 1e-3
    wk[RF_LO], wk[RF_HI] = alpha_bounds
    wk[RF_STEPS] = steps
    wk[RF_DRIFT_ON], wk[RF_DRIFT_OFF], wk[RF_DRIFT_MAX] = drift_on, drift_off, drift_max
    wk[RF_K], wk[RF_R0] = k, r0
    masks = wk[wk.size - MASKS * k:].reshape(MASKS, k)
    masks[:] = 1.0
    masks[MASK_CONSTANT, r0:] = 0.0
    masks[MASK_HOLD, r0:] = 0.0
    masks[MASK_HOLD, 0] = 0.0
    masks[MASK_TEST] = 0.0
    masks[MASK_TEST, 1:5] = 1.0
    return wk


@njit(cache=CACHE)
def _views(wk: np.ndarray, p: int, k: int) -> tuple:
    """theta, var, H, g, cov, H2, g2, F, fy, masks: views into the work array."""
    o = HEAD
    theta = wk[o:o + k]
    var = wk[o + k:o + 2 * k]
    o += 2 * k
    H = wk[o:o + k * k].reshape(k, k)
    cov = wk[o + k * k:o + 2 * k * k].reshape(k, k)
    H2 = wk[o + 2 * k * k:o + 3 * k * k].reshape(k, k)
    o += 3 * k * k
    g = wk[o:o + k]
    g2 = wk[o + k:o + 2 * k]
    o += 2 * k
    F = wk[o:o + p * p].reshape(p, p)
    fy = wk[o + p * p:o + p * p + p]
    o += p * p + p
    masks = wk[o:o + MASKS * k].reshape(MASKS, k)
    return theta, var, H, g, cov, H2, g2, F, fy, masks


@njit(cache=CACHE)
def refit_unit(st: np.ndarray, S: np.ndarray, shift: np.ndarray, live: np.ndarray, wk: np.ndarray,
               lam: np.ndarray, dx: float, mask: int, drift: int) -> bool:
    """Advance the re-fit by one stage; True when it is done (the result in ``wk``, see ``result``).

    ``live`` is the tracker's theta (the start); ``mask`` the parameters to free (``MASK_*``);
    ``drift`` the drift test to run after the fit (0 none, 1 score test, 2 Wald test).
    """
    p, k = S.shape[0], live.shape[0]
    theta, var, H, g, cov, H2, g2, F, fy, masks = _views(wk, p, k)
    free = masks[mask]
    stage = int(wk[RF_STAGE])
    if stage == 0:                     # the statistics at true scale, frozen for the fit
        wk[RF_FYY] = W.true_statistics(st, S, shift, F, fy)
        theta[:] = live
        wk[RF_A1L], wk[RF_A2L] = st[W.SC_A1L], st[W.SC_A2L]
        wk[RF_STEP] = 0.0
        wk[RF_DRIFT] = 0.0
        wk[RF_DRIFT_SWITCH] = 0.0
        wk[RF_STAGE] = 1.0
        return False
    a1l, a2l, fyy = wk[RF_A1L], wk[RF_A2L], wk[RF_FYY]
    if stage == 1:                     # J^T J, J^T r at theta
        wk[RF_COST] = W.lm_normal(theta, a1l, a2l, lam, dx, F, fy, fyy, H, g)
        if wk[RF_STEP] == 0.0:
            wk[RF_START_COST] = wk[RF_COST]
        wk[RF_STAGE] = 2.0
        return False
    if stage == 2:                     # the damped step
        out = wk[RF_BEFORE:RF_MOVED + 1]
        wk[RF_MU] = W.lm_trial(theta, free, wk[RF_MU], H, g, wk[RF_COST], a1l, a2l, lam, dx, F, fy, fyy,
                               wk[RF_LO], wk[RF_HI], out)
        wk[RF_STEP] += 1.0
        done = wk[RF_STEP] >= wk[RF_STEPS] or (wk[RF_MOVED] == 0.0 and wk[RF_MU] > 1e3)
        wk[RF_STAGE] = 3.0 if done else 1.0
        return False
    if stage == 3:
        W.covariance(H, free, cov)
        for i in range(k):
            var[i] = cov[i, i]
        wk[RF_NEFF] = st[W.SC_NEFF]
        wk[RF_STAGE] = 0.0
        return _drift_test(wk, theta, cov, k, drift)
    if stage == 4:                     # score test: the normal equations at the result
        W.lm_normal(theta, a1l, a2l, lam, dx, F, fy, fyy, H2, g2)
        wk[RF_STAGE] = 5.0
        return False
    stat = W.drift_score(H2, g2, free, int(wk[RF_R0])) / wk[RF_SIGMA2]
    wk[RF_DRIFT_STAT] = stat
    if stat > wk[RF_DRIFT_ON]:
        wk[RF_DRIFT_SWITCH] = 1.0
    wk[RF_STAGE] = 0.0
    return True


@njit(cache=CACHE)
def start_test(st: np.ndarray, S: np.ndarray, S0: np.ndarray, sy0: np.ndarray, syy0: float, shift: np.ndarray,
               shift0: np.ndarray, live: np.ndarray, wk: np.ndarray) -> None:
    """Start the change test in its own work array: the statistics since a snapshot (S0, sy0, syy0,
    shift0; ``window.since_statistics``), theta from the live estimate, fresh damping. ``refit_unit``
    with ``MASK_TEST`` and no drift test then fits them from stage 1 on."""
    p, k = S.shape[0], live.shape[0]
    theta, var, H, g, cov, H2, g2, F, fy, masks = _views(wk, p, k)
    wk[RF_FYY] = W.since_statistics(st, S, S0, sy0, syy0, shift, shift0, F, fy)
    theta[:] = live
    wk[RF_A1L], wk[RF_A2L] = st[W.SC_A1L], st[W.SC_A2L]
    wk[RF_STEP] = 0.0
    wk[RF_MU] = 1e-3
    wk[RF_DRIFT] = 0.0
    wk[RF_DRIFT_SWITCH] = 0.0
    wk[RF_STAGE] = 1.0


@njit(cache=CACHE)
def _drift_test(wk: np.ndarray, theta: np.ndarray, cov: np.ndarray, k: int, drift: int) -> bool:
    """After the covariance: the Wald test of the rates (done), or queue the score test (not done).

    Rates on: their Wald statistic over the noise variance; below DRIFT_OFF, or a rate beyond the
    plausible DRIFT_MAX, switches them off and zeroes them. Rates off: the score test takes two
    more stages (the normal equations at the result, then the Gauss-Newton gain of freeing them).
    """
    if drift == 0 or (drift == 1 and not np.all(np.isfinite(theta))):
        return True
    wk[RF_DRIFT] = drift
    sigma2 = max(wk[RF_AFTER], 0.0) / max(wk[RF_NEFF] - k, 1.0)
    wk[RF_SIGMA2] = sigma2
    wk[RF_DRIFT_STAT] = 0.0
    if not sigma2 > 0.0:
        return True
    r0 = int(wk[RF_R0])
    if drift == 1:
        wk[RF_STAGE] = 4.0
        return False
    n = k - r0
    stat = 0.0
    if not np.all(np.isfinite(cov[r0:, r0:])):
        stat = 0.0                     # singular: the rates are undetermined
    elif n == 1:
        stat = theta[r0] ** 2 / cov[r0, r0] / sigma2 if cov[r0, r0] > 0.0 else 0.0
    else:                              # the 2x2 Wald form in closed form
        c00, c01, c11 = cov[r0, r0], cov[r0, r0 + 1], cov[r0 + 1, r0 + 1]
        det = c00 * c11 - c01 * c01
        x, y = theta[r0], theta[r0 + 1]
        stat = (c11 * x * x - 2.0 * c01 * x * y + c00 * y * y) / det / sigma2 if det > 0.0 else 0.0
    stat = stat if math.isfinite(stat) else 0.0
    wk[RF_DRIFT_STAT] = stat
    limit = wk[RF_DRIFT_MAX]
    plausible = abs(theta[r0]) < limit and (n < 2 or abs(theta[r0 + 1]) < limit * abs(theta[0]))
    if stat < wk[RF_DRIFT_OFF] or not plausible:
        wk[RF_DRIFT_SWITCH] = -1.0
        theta[r0:] = 0.0
    return True


def result(wk: np.ndarray) -> tuple[list[float], list[float], list[float]]:
    """(header, theta, diagonal of the covariance) as plain floats, in one numpy call."""
    k = int(wk[RF_K])
    vals = wk[:HEAD + 2 * k].tolist()
    return vals[:HEAD], vals[HEAD:HEAD + k], vals[HEAD + k:]
