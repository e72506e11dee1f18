"""The window tracker's re-fit as a numba state machine that the per-sample kernel advances.

A re-fit (the window's statistics, Levenberg-Marquardt steps, the covariance, the drift test) runs
about ten times a second at 10 kHz. As a Python generator with numpy glue between its kernels it
cost 20-110 us per unit: by the time a re-fit runs, the interpreter's and numpy's code paths are
cold, and each line of glue (an array copy, a mask, a scalar read from an array) costs far more than
its warm microsecond. Here the whole re-fit lives in one flat work array (``allocate``);
``fit_unit`` advances it by one slice of about a microsecond (``SLICE_MACS``), and in a control
loop the per-sample kernel itself runs the slices (``sample_work``): no Python between them. The
tracker's Python starts a re-fit (``begin``) or a change test (``start_test``) and reads the result
once (``accept``, ``test_outcome``).

Work array: a header of scalars (``RF_*``), then theta, the covariance's diagonal, and the arrays
of the fit (statistics F, fy; J^T J and J^T r; the covariance; the drift test's normal equations;
the parameter masks; the slices' intermediate results).
"""
from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba import njit

from . import coefficients as kernels
from . import hysteresis as HK
from . import window as W

CACHE = True

# header of the work array
RF_STAGE = 0      # next stage (ST_*)
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
RF_MASK = 24      # the parameters this fit frees (MASK_*), chosen at its start (``_plan``)
RF_HOLD_N = 25    # samples after a change during which alpha and the rates are held
RF_DRIFT_MIN_N = 26   # samples the window must span before the drift test
RF_DRIFT_EVERY = 27   # while the rates are off, the score test runs at every this-many-th re-fit
RF_NRATE = 28     # drift columns (0-2)
RF_LN_A2_MIN = 29     # the resonances the sampling represents: ln a2 >= this ...
RF_LN_ZETA_LO = 30    # ... and ln zeta within these
RF_LN_ZETA_HI = 31
RF_RELINEARIZE = 32   # relative move of a1, a2 within which the linearized cost holds
RF_ROW = 33       # next row of the stage that runs over the statistics' rows in slices
RF_PARTIAL = 34   # the trial cost's sum over the rows done so far
RF_SCORING = 35   # 1 while the normal equations are the score test's (at the result, into H2, g2)
RF_NORMAL_ROWS = 36   # rows of the normal equations per slice (``SLICE_MACS``)
RF_COST_ROWS = 37     # rows of the trial cost per slice
RF_FACTORED = 38      # 1 if the covariance's Cholesky factor exists (its inverse's stage reads it)
RF_GAIN_BOTH = 39     # the score test's Gauss-Newton gain with the rates freed (its second slice subtracts)
RF_SNAP = 40          # the change test's snapshot slot (``snapshot_slots``) ...
RF_SNAP_SYY = 41      # ... its syy
RF_FREE_RATES = 42    # 1: the test frees the drift rates (``start_test``'s free_rates)
RF_SLOTS = 43         # snapshot slots after the scratch (the change test's work array only)
RF_SHIFT_ROWS = 44    # the drift-origin total's shape (a slot holds a copy)
RF_SHIFT_COLS = 45
RF_SINCE_N = 46       # the sample count at which a change test took its statistics ...
RF_SINCE_G = 47       # ... and their weight g
RF_WIDE = 48          # 1: the window fits all its free responses; 0: the four it starts with (``allocate``'s extra)
RF_WIDE_DUE = 49      # 1: the wide test follows this re-fit (``_plan``)
RF_WIDE_ON = 50       # its threshold (the tracker's WIDE_ON)
RF_WIDE_STAT = 51     # its last statistic
RF_GAIN_NARROW = 52   # its Gauss-Newton gain without the extra free responses (its second slice subtracts it)
RF_INVERSE_COLS = 53  # columns of the covariance's inverse per slice (``SLICE_MACS``, ``SOLVE_MAC_COST``)
RF_AFTER_WARM = 54    # the stage that follows the warming slices (``ST_WARM``): ST_BEGIN or ST_SINCE
RF_WARM_ROWS = 55     # rows warmed per slice (``WARM_SLICE``)
RF_WARMED = 56        # the warming reads' sum (kept, so that the reads are not optimized away)
RF_TRUST = 57         # the resonance's trust region: |ln a - ln a_lin| at most this (0: none; ``_trust``)
RF_SCALE_ROWS = 58    # rows of a change test's statistics scaled per slice (``since_scaled``; ``WARM_SLICE``)
HEAD = 59

#: Multiply-adds per slice of a re-fit (well under a microsecond): the per-sample kernel runs one slice per
#: sample while a re-fit or a change test is under way (``sample_work``), so a 10 kHz control loop sees
#: ~0.3-1 us more on ~3 % of its samples, not 7-45 us on ~1 % of them. At 4000 the normal equations' rows
#: and the inverse's columns took 0.9 and 1.6 us per slice (timed alone, cold): with a sample's ~2.1 us the
#: calls sat at 4-5 us, and a loaded machine put a third of them over the 5 us p99 goal. At 2000: 0.3, 0.7 us.
SLICE_MACS = 2000
#: A triangular solve's multiply-add in the cost of a vectorized row loop's (each waits for the one before:
#: measured, the covariance's 15 solves of 15 took ~4 us, ~1.2 ns per multiply-add, against ~0.3 ns in the rows).
SOLVE_MAC_COST = 4
#: Entries of a cold matrix brought into the cache per slice before a stage that must touch all of it in one
#: slice (``ST_WARM``: the re-fit's frozen statistics F before they are written at one instant, a change test's
#: snapshot and difference before the difference is taken at one instant). At 700: ~0.9 us per slice; 350: ~0.3.
WARM_SLICE = 350

#: Stages of a fit, in order: (idle until ``begin``, ``queue_test`` or ``start_test``), the warming of the cold
#: matrices the next one-instant stage touches (``ST_WARM``, in slices); for a re-fit the drift origin's move
#: (``window.move_origin``, O(P^2): in a slice, not in the Python call that starts the re-fit) and the statistics
#: at true scale (one slice each); for a change test the statistics since its snapshot (the difference at one
#: instant, then its move and its scaling in row slices, ``queue_test``; none after ``start_test``); per
#: Levenberg-Marquardt step the model coefficients (in two halves of the nodes), their resonance derivatives, the
#: Jacobian's, the normal equations' rows in slices and their assembly, the damped step (its factor, then its
#: solve), the trial's coefficients, the trial's cost in slices and the verdict; then the covariance's factor, its
#: inverse in column slices (and the Wald test), and for the score test the normal equations again at the result
#: and the score's two Gauss-Newton gains (with and without the rates), one slice each; for the wide test (a
#: stream in operation whose window fits four of its free responses) the same normal equations and its two gains,
#: without and with the other four, one slice each.
#: Each call does one stage or slice: up to about a microsecond of work (``SLICE_MACS``).
(ST_IDLE, ST_SCALE, ST_JACOBIAN, ST_ASSEMBLE, ST_ROWS, ST_SOLVE, ST_TRIAL_POINT, ST_TRIAL,
 ST_COVARIANCE, ST_INVERSE, ST_SCORE, ST_SCORE_WITHOUT, ST_BEGIN, ST_SINCE, ST_SINCE_FINISH, ST_WIDE,
 ST_WIDE_WITH, ST_WARM, ST_SINCE_SCALE, ST_DERIVATIVES, ST_STEP, ST_COEFFICIENTS) = range(22)

#: Parameter masks (rows of the masks block): all free, drift rates fixed, alpha and rates fixed, the
#: change test's (the resonance, the gain and the offset), and the change test's with the drift rates; then
#: the first three again with the extra free responses fixed (at zero: ``allocate``'s extra), NARROW rows on.
MASK_ALL, MASK_CONSTANT, MASK_HOLD, MASK_TEST, MASK_TEST_RATES = 0, 1, 2, 3, 4
NARROW = 5
MASKS = 8


def allocate(p: int, k: int, r0: int, steps: int, policy: dict, slots: int = 0,
             shift_shape: tuple[int, int] = (0, 0), extra: tuple[int, ...] = ()) -> np.ndarray:
    """A fresh work array for statistics of size p and k parameters (rates from r0 on).

    ``policy``: the tracker's settings the re-fit applies, by header name without ``RF_`` (alpha
    bounds LO, HI; DRIFT_ON, DRIFT_OFF, DRIFT_MAX; HOLD_N, DRIFT_MIN_N, DRIFT_EVERY, NRATE;
    LN_A2_MIN, LN_ZETA_LO, LN_ZETA_HI, RELINEARIZE; a re-fit's TRUST). ``slots``: the change test's snapshot slots
    (``snapshot_slots``) for a drift-origin total of ``shift_shape``. ``extra``: the parameters (free
    responses) a stream in operation fits only once the wide test has found them needed (``_plan``); none:
    every free response from the start.
    """
    rows, cols = shift_shape
    wk = np.zeros(_masks_at(p, k) + MASKS * k + _scratch_size(p, k) + slots * _slot_size(p, k, rows * cols))
    wk[RF_SLOTS], wk[RF_SHIFT_ROWS], wk[RF_SHIFT_COLS] = slots, rows, cols
    wk[RF_MU] = 1e-3
    wk[RF_STEPS] = steps
    wk[RF_K], wk[RF_R0] = k, r0
    mq = p - (k - 4)
    wk[RF_NORMAL_ROWS] = max(1, SLICE_MACS // (4 * mq + p))
    wk[RF_COST_ROWS] = max(1, SLICE_MACS // p)
    wk[RF_INVERSE_COLS] = max(1, SLICE_MACS // (SOLVE_MAC_COST * k * k))
    wk[RF_WARM_ROWS] = max(1, WARM_SLICE // p)
    wk[RF_SCALE_ROWS] = max(1, WARM_SLICE // p)   # (the scaling also touches rows of F cold since the difference)
    for name, value in policy.items():
        wk[globals()["RF_" + name]] = value
    o = _masks_at(p, k)
    masks = wk[o:o + MASKS * k].reshape(MASKS, k)
    masks[:] = 1.0
    if r0 > 5:                            # a stream in operation: the offset and free responses undamped
        masks[:, 4:r0] = W.LINEAR         # (nearly collinear with the slowest free responses)
    masks[MASK_CONSTANT, r0:] = 0.0
    masks[MASK_HOLD, r0:] = 0.0
    masks[MASK_HOLD, 0] = 0.0
    masks[MASK_TEST] = 0.0
    masks[MASK_TEST, 1:5] = 1.0
    masks[MASK_TEST_RATES] = masks[MASK_TEST]
    masks[MASK_TEST_RATES, r0:] = 1.0
    masks[NARROW:NARROW + 3] = masks[:3]
    for i in extra:
        masks[NARROW:NARROW + 3, i] = 0.0
    wk[RF_WIDE] = 0.0 if extra else 1.0
    return wk


@njit(cache=CACHE)
def _masks_at(p: int, k: int) -> int:
    """Offset of the masks in the work array: after the header, theta, var, H, cov, H2, g, g2, F and fy."""
    return HEAD + 2 * k + 3 * k * k + 2 * k + p * p + p


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
    o = _masks_at(p, k)
    masks = wk[o:o + MASKS * k].reshape(MASKS, k)
    return theta, var, H, g, cov, H2, g2, F, fy, masks


@njit(cache=CACHE)
def _scratch_size(p: int, k: int) -> int:
    """C (p x k), A^T (4 x mq), m, F A (p x 4), F m, the trial theta (k) and its coefficients (p), the
    model coefficients and their alpha-derivative (p each, Q + 2 used), the covariance's factor (k x k)
    and scaling (k)."""
    return p * k + 4 * (p - (k - 4)) + p + 4 * p + p + k + p + 2 * p + k * k + k


@njit(cache=CACHE)
def _slot_size(p: int, k: int, shift_size: int) -> int:
    """A snapshot slot: S0 (p x p), sy0 (p), shift0 (shift_size), theta0 (k)."""
    return p * p + p + shift_size + k


@njit(cache=CACHE)
def _slot(wk: np.ndarray, p: int, k: int, i: int) -> tuple:
    """S0, sy0, shift0, theta0 of snapshot slot i: views into the work array after the scratch."""
    rows, cols = int(wk[RF_SHIFT_ROWS]), int(wk[RF_SHIFT_COLS])
    o = _masks_at(p, k) + MASKS * k + _scratch_size(p, k) + i * _slot_size(p, k, rows * cols)
    S0 = wk[o:o + p * p].reshape(p, p)
    o += p * p
    sy0 = wk[o:o + p]
    o += p
    shift0 = wk[o:o + rows * cols].reshape(rows, cols)
    o += rows * cols
    return S0, sy0, shift0, wk[o:o + k]


@njit(cache=CACHE)
def snapshot(st: np.ndarray, S: np.ndarray, ctx: np.ndarray, which: int, slot: int, due: float) -> tuple:
    """``window.snapshot`` into snapshot slot ``slot`` of the context's work array ``which``, with theta and the
    drift-origin total from the context; sets the next scheduled sample ``sc[SC_DUE]`` to ``due`` and checks the
    state as ``window.state_finite`` does. Returns (syy, g, finite). Three arrays instead of eight: each array
    argument costs numba's dispatch, and this runs from cold Python at every change test's instant, where the
    due sample and the check were two more calls (~4 us of the instant's ~16)."""
    theta, shift, lam, dx, wk = _unpack(ctx, which)
    S0, sy0, shift0, theta0 = _slot(wk, S.shape[0], theta.shape[0], slot)
    syy, g = W.snapshot(st, S, shift, theta, S0, sy0, shift0, theta0)
    st[W.SC_DUE] = due
    return syy, g, W.state_finite(theta, S, st)


def snapshot_slots(wk: np.ndarray, p: int, k: int) -> list[tuple]:
    """The change test's snapshot slots in its work array (``allocate``'s ``slots``): (S0, sy0, shift0, theta0)
    views each, which ``window.snapshot`` fills. In the work array, the test's first slice reads its snapshot
    there (``queue_test``), inside the per-sample kernel."""
    return [_slot(wk, p, k, i) for i in range(int(wk[RF_SLOTS]))]


@njit(cache=CACHE)
def _scratch(wk: np.ndarray, p: int, k: int, q: int) -> tuple:
    """C, At, m, FA, fm, trial, mt, v, dv, L, d: the slices' intermediate results, after the masks."""
    o = _masks_at(p, k) + MASKS * k
    mq = p - (k - 4)
    C = wk[o:o + p * k].reshape(p, k)
    o += p * k
    At = wk[o:o + 4 * mq].reshape(4, mq)
    o += 4 * mq
    m = wk[o:o + p]
    FA = wk[o + p:o + 5 * p].reshape(p, 4)
    fm = wk[o + 5 * p:o + 6 * p]
    o += 6 * p
    trial, mt = wk[o:o + k], wk[o + k:o + k + p]
    o += k + p
    v, dv = wk[o:o + q + 2], wk[o + p:o + p + q + 2]
    o += 2 * p
    return C, At, m, FA, fm, trial, mt, v, dv, wk[o:o + k * k].reshape(k, k), wk[o + k * k:o + k * k + k]


@njit(cache=CACHE)
def begin(st: np.ndarray, S: np.ndarray, shift: np.ndarray, wk: np.ndarray, window_start: int, drift_on: bool,
          converged: bool, refits: int, hold_alpha: bool) -> None:
    """Start a re-fit of the window: what it frees and which drift test follows (``_plan``; the tracker's
    state decides), and the drift origin to the newest sample (``window.move_origin``: alpha and b of the
    fit are then the values now). ``fit_unit`` (or ``sample_work``) then runs it. ``hold_alpha``: the window
    restarted after a plant change (alpha held for HOLD_N samples), not after a corrected start.

    The origin's move is the re-fit's first slice (``ST_BEGIN``): O(P^2) over statistics that are cold by the
    time a re-fit starts, it cost ~10 us of the Python call that starts it, which is then over 25 us."""
    _plan(wk, st[W.SC_N], window_start, drift_on, converged, refits, hold_alpha)
    wk[RF_ROW] = 0.0
    wk[RF_AFTER_WARM] = ST_BEGIN
    wk[RF_STAGE] = ST_WARM


@njit(cache=CACHE)
def _plan(wk: np.ndarray, n: float, window_start: int, drift_on: bool, converged: bool, refits: int,
          hold_alpha: bool) -> None:
    """What this re-fit frees and which drift test follows it.

    Alpha and the drift rates stay fixed in a short window after a change (it determines neither).
    The drift rates are tested once the window is converged and spans DRIFT_MIN_N samples: the Wald
    test at every re-fit while they are on, the score test at every DRIFT_EVERY-th while off.
    A stream in operation fits its extra free responses only once the wide test (a score test, at every
    DRIFT_EVERY-th re-fit of a converged window while they are out) has found them needed; then for good.
    """
    span = n - window_start
    hold = hold_alpha and window_start > 0 and span < wk[RF_HOLD_N]
    narrow = wk[RF_WIDE] == 0.0
    wk[RF_MASK] = (MASK_HOLD if hold else (MASK_ALL if drift_on else MASK_CONSTANT)) + (NARROW if narrow else 0)
    drift = 0
    due = refits % int(wk[RF_DRIFT_EVERY]) == 0
    if wk[RF_NRATE] > 0 and not hold and converged and span >= wk[RF_DRIFT_MIN_N]:
        drift = 2 if drift_on else (1 if due else 0)
    wk[RF_DRIFT] = drift
    wk[RF_WIDE_DUE] = 1.0 if narrow and converged and due else 0.0


#: The masks a re-fit may use (the change test holds the weights at the live values).
REFIT_MASKS = np.array([MASK_ALL, MASK_CONSTANT, MASK_HOLD, NARROW + MASK_ALL, NARROW + MASK_CONSTANT,
                        NARROW + MASK_HOLD], dtype=np.int64)


@njit(cache=CACHE)
def _hysteresis_weights(st: np.ndarray, F: np.ndarray, wk: np.ndarray, theta: np.ndarray, masks: np.ndarray,
                        q: int) -> None:
    """A re-fit with hysteresis columns: the weights' prior in its statistics (``hysteresis.weight_prior``), the
    operators the input has not opened pinned at 0 (``hysteresis.pin_unopened``)."""
    nm, nh = int(st[W.SC_NM]), int(st[W.SC_NH])
    o = HK.block_at(q, nm, int(st[W.SC_NR]), nh)
    HK.weight_prior(F, q + W.FREE + nm, nh, st[W.SC_NOISE], st[W.SC_NEFF], wk[RF_FYY], st[o + HK.GAIN])
    HK.pin_unopened(st, o, nh, theta, 5 + nm, masks, REFIT_MASKS, W.LINEAR)


@njit(cache=CACHE)
def fit_unit(st: np.ndarray, S: np.ndarray, shift: np.ndarray, live: np.ndarray, wk: np.ndarray,
               lam: np.ndarray, dx: float) -> bool:
    """Advance the re-fit (or change test) by one stage or slice; True when it is done (the result in
    ``wk``, see ``accept``) or idle.

    ``live`` is the tracker's theta (the start). The stages' arithmetic is that of ``window.lm_normal``,
    ``window.lm_trial`` and ``window.covariance``, cut into slices of ~``SLICE_MACS`` multiply-adds.
    """
    p, k, q = S.shape[0], live.shape[0], lam.shape[0]
    theta, var, H, g, cov, H2, g2, F, fy, masks = _views(wk, p, k)
    C, At, m, FA, fm, trial, mt, v, dv, L, d = _scratch(wk, p, k, q)
    stage = int(wk[RF_STAGE])
    if stage == ST_IDLE:
        return True
    if stage == ST_WARM:               # the one-instant stage's cold operands into the cache, in slices: the
        i0 = int(wk[RF_ROW])           # snapshot (read) and F (zeroed) for a change test, F for a re-fit; cold,
        i1 = min(i0 + int(wk[RF_WARM_ROWS]), p)     # SCALE and SINCE were ~8 and ~11 us, with them warm ~2
        warm_from = _slot(wk, p, k, int(wk[RF_SNAP]))[0] if wk[RF_AFTER_WARM] == ST_SINCE else F
        wk[RF_WARMED] += W.warm_rows(warm_from, F, i0, i1)
        wk[RF_ROW] = i1
        if i1 == p:
            wk[RF_STAGE] = wk[RF_AFTER_WARM]
        return False
    if stage == ST_SINCE:              # a change test's statistics since its snapshot (``queue_test``), in two
        S0, sy0, shift0, theta0 = _slot(wk, p, k, int(wk[RF_SNAP]))     # slices: the difference at this instant,
        wk[RF_FYY] = W.since_difference(st, S, S0, sy0, wk[RF_SNAP_SYY], F, fy)
        _test_start(st, live, wk, wk[RF_FREE_RATES] != 0.0)
        wk[RF_STAGE] = ST_SINCE_FINISH
        return False
    if stage == ST_SINCE_FINISH:       # ... then moved to the live drift origin and scaled (only F, fy)
        S0, sy0, shift0, theta0 = _slot(wk, p, k, int(wk[RF_SNAP]))
        W.since_moved(st, S0, sy0, shift, shift0, F, fy)
        wk[RF_ROW] = 0.0
        wk[RF_STAGE] = ST_SINCE_SCALE
        return False
    if stage == ST_SINCE_SCALE:        # ... in row slices (reads only the test's own arrays)
        i0 = int(wk[RF_ROW])
        i1 = min(i0 + int(wk[RF_SCALE_ROWS]), p)
        fyy = W.since_scaled(F, fy, wk[RF_FYY], wk[RF_SINCE_G], i0, i1)
        wk[RF_ROW] = i1
        if i1 == p:
            wk[RF_FYY] = fyy
            wk[RF_STAGE] = ST_JACOBIAN
        return False
    if stage == ST_BEGIN:              # a re-fit's drift origin to the newest sample (``begin``); the statistics
        W.move_origin(st, S, shift)    # are scaled in the next slice (the two together, cold, were ~15-25 us)
        wk[RF_STAGE] = ST_SCALE
        return False
    if stage == ST_SCALE:              # the statistics at true scale, frozen for the fit, in ONE slice: under
        # sample_work a sample lands between two slices, and rows scaled a sample apart (this stage was two
        # slices) gave a window cost that grew with the stream (demo: 1.0x -> 1.85x the noise floor in 16 s,
        # then a wrong re-search) while theta stayed right. The effective samples belong to the same instant.
        wk[RF_FYY] = W.scaled_statistics(st, S, F, fy)
        wk[RF_NEFF] = st[W.SC_NEFF]
        theta[:] = live
        if st[W.SC_NH] > 0.0:          # the hysteresis weights: their prior, the operators not yet opened pinned
            _hysteresis_weights(st, F, wk, theta, masks, q)
        wk[RF_A1L], wk[RF_A2L] = st[W.SC_A1L], st[W.SC_A2L]
        wk[RF_STEP] = 0.0
        wk[RF_DRIFT_SWITCH] = 0.0
        wk[RF_SCORING] = 0.0
        wk[RF_STAGE] = ST_JACOBIAN
        return False
    free = masks[int(wk[RF_MASK])]
    a1l, a2l, fyy = wk[RF_A1L], wk[RF_A2L], wk[RF_FYY]
    if stage == ST_JACOBIAN:           # the model coefficients at theta: the first half of the nodes (all of them
        half = lam.shape[0] // 2       # in one slice, ~0.8 us, put a third of these calls over 5 us)
        kernels.node_coefficients(theta[0], lam, dx, math.exp(theta[1]), math.exp(theta[2]), v, dv, 0, half)
        wk[RF_STAGE] = ST_COEFFICIENTS
        return False
    if stage == ST_COEFFICIENTS:       # the other half, and the resonance entries' sums
        a1, a2 = math.exp(theta[1]), math.exp(theta[2])
        kernels.node_coefficients(theta[0], lam, dx, a1, a2, v, dv, lam.shape[0] // 2, lam.shape[0])
        kernels.coefficient_sums(theta[0], lam, dx, a1, a2, v, dv)
        wk[RF_STAGE] = ST_DERIVATIVES
        return False
    if stage == ST_DERIVATIVES:        # their resonance derivatives (into fm and mt: the rows and the trial fill
        W.resonance_derivatives(theta, lam, dx, fm, mt)     # them later)
        wk[RF_STAGE] = ST_ASSEMBLE
        return False
    if stage == ST_ASSEMBLE:           # J's coefficients
        W.jacobian_assemble(theta, a1l, a2l, lam, dx, v, dv, C, fm, mt)
        W.normal_prepare(theta, C, At, m)
        wk[RF_ROW] = 0.0
        wk[RF_STAGE] = ST_ROWS
        return False
    if stage == ST_ROWS:               # a slice of the normal equations' rows; the last one assembles them
        i0 = int(wk[RF_ROW])
        i1 = min(i0 + int(wk[RF_NORMAL_ROWS]), p)
        W.normal_rows(F, At, m, FA, fm, i0, i1)
        wk[RF_ROW] = i1
        if i1 < p:
            return False
        if wk[RF_SCORING] != 0.0:      # the score test's normal equations, at the result
            W.normal_finish(At, m, FA, fm, F, fy, fyy, H2, g2)
            wk[RF_STAGE] = ST_SCORE
            return False
        wk[RF_COST] = W.normal_finish(At, m, FA, fm, F, fy, fyy, H, g)
        if wk[RF_STEP] == 0.0:
            wk[RF_START_COST] = wk[RF_COST]
        wk[RF_STAGE] = ST_SOLVE
        return False
    out = wk[RF_BEFORE:RF_MOVED + 1]
    if stage == ST_SOLVE:              # the damped step's system, factored (in the covariance's scratch and the
        ok, mu = W.trial_factor(theta, free, wk[RF_MU], H, g, wk[RF_COST], out, L, d, mt)   # trial coefficients':
        if not ok:                     # idle now)
            wk[RF_MU] = mu
            return _step_done(wk)
        wk[RF_STAGE] = ST_STEP
        return False
    if stage == ST_STEP:               # the damped step from the factor (one slice with the factor: ~1.4 us)
        ok, mu = W.trial_step(theta, wk[RF_MU], wk[RF_LO], wk[RF_HI], trial, L, d, mt)
        if not ok:
            wk[RF_MU] = mu
            return _step_done(wk)
        _trust(trial, wk)
        wk[RF_STAGE] = ST_TRIAL_POINT
        return False
    if stage == ST_TRIAL_POINT:        # the trial's coefficients
        W.full_coefficients_into(trial, a1l, a2l, lam, dx, mt, v)
        wk[RF_ROW] = 0.0
        wk[RF_PARTIAL] = fyy
        wk[RF_STAGE] = ST_TRIAL
        return False
    if stage == ST_TRIAL:              # a slice of the trial's cost; the last one decides
        i0 = int(wk[RF_ROW])
        i1 = min(i0 + int(wk[RF_COST_ROWS]), p)
        wk[RF_PARTIAL] = W.cost_rows(F, fy, mt, i0, i1, wk[RF_PARTIAL])
        wk[RF_ROW] = i1
        if i1 < p:
            return False
        wk[RF_MU] = W.trial_verdict(theta, trial, wk[RF_PARTIAL], wk[RF_COST], wk[RF_MU], out)
        return _step_done(wk)
    if stage == ST_COVARIANCE:         # the factor, then the inverse
        wk[RF_FACTORED] = 1.0 if W.covariance_factor(H, free, L, d) else 0.0
        wk[RF_ROW] = 0.0
        wk[RF_STAGE] = ST_INVERSE
        return False
    if stage == ST_INVERSE:            # the inverse's columns in slices (k solves: ~6 us in one); the last judges it
        j0 = int(wk[RF_ROW])
        j1 = min(j0 + int(wk[RF_INVERSE_COLS]), k)
        W.covariance_columns(L, wk[RF_FACTORED] != 0.0, cov, trial, j0, j1)
        wk[RF_ROW] = j1
        if j1 < k:
            return False
        W.covariance_inverse(L, d, wk[RF_FACTORED] != 0.0, cov, free, H)
        for i in range(k):
            var[i] = cov[i, i]
        wk[RF_STAGE] = ST_IDLE
        done = _drift_test(wk, theta, cov, k, int(wk[RF_DRIFT]))
        if wk[RF_WIDE_DUE] != 0.0:     # the wide test needs the noise variance whatever the drift test did
            wk[RF_SIGMA2] = _noise_variance(wk, k)
            if not (wk[RF_SIGMA2] > 0.0 and np.all(np.isfinite(theta))):
                wk[RF_WIDE_DUE] = 0.0
        if done and wk[RF_WIDE_DUE] == 0.0:
            return True
        wk[RF_SCORING] = 1.0           # the score tests: the normal equations at the result, then the scores
        wk[RF_STAGE] = ST_JACOBIAN
        return False
    r0 = int(wk[RF_R0])
    if stage == ST_SCORE:              # the score test's gain with the rates freed, then without (two slices)
        if wk[RF_DRIFT] == 1.0:
            wk[RF_GAIN_BOTH] = W.drift_gain(H2, g2, free, r0, True, L, d, trial, mt)
            wk[RF_STAGE] = ST_SCORE_WITHOUT
        else:                          # only the wide test
            wk[RF_STAGE] = ST_WIDE
        return False
    if stage == ST_SCORE_WITHOUT:
        gain = wk[RF_GAIN_BOTH] - W.drift_gain(H2, g2, free, r0, False, L, d, trial, mt)
        stat = gain / wk[RF_SIGMA2]
        wk[RF_DRIFT_STAT] = stat
        if stat > wk[RF_DRIFT_ON] and _drift_explains(gain, st, wk):
            wk[RF_DRIFT_SWITCH] = 1.0
        if wk[RF_WIDE_DUE] == 0.0:
            wk[RF_STAGE] = ST_IDLE
            return True
        wk[RF_STAGE] = ST_WIDE
        return False
    if stage == ST_WIDE:               # the wide test's gain over this fit's parameters, then with the extra free
        wk[RF_GAIN_NARROW] = W.linear_gain(H2, g2, free, L, trial, mt)    # responses too (two slices)
        wk[RF_STAGE] = ST_WIDE_WITH
        return False
    row = int(wk[RF_MASK]) - NARROW    # (the same mask with them freed)
    stat = (W.linear_gain(H2, g2, masks[row], L, trial, mt) - wk[RF_GAIN_NARROW]) / wk[RF_SIGMA2]
    wk[RF_WIDE_STAT] = stat if math.isfinite(stat) else 0.0
    if stat > wk[RF_WIDE_ON]:
        wk[RF_WIDE] = 1.0
    wk[RF_STAGE] = ST_IDLE
    return True


#: The drift rates enter the fit only if they explain at least this share of the window's cost above its noise floor
#: (``_drift_explains``), besides the score test's DRIFT_ON: a drift's misfit is the rates' to explain nearly whole,
#: while a model error of another kind (close unmodeled modes) lets any slow column take a sliver of it. The score
#: test alone, in units of the misfit itself, passed such slivers at a high SNR: the rates then carried alpha 15-19 %
#: off a single step's creep, where the constant model agrees with a batch fit to 0.1 %.
DRIFT_SHARE = 0.5


@njit(cache=CACHE)
def _drift_explains(gain: float, st: np.ndarray, wk: np.ndarray) -> bool:
    """Does freeing the drift rates (their Gauss-Newton ``gain``) explain ``DRIFT_SHARE`` of the window's cost above
    the noise floor (the output's noise level over the window's effective samples)? True at the floor."""
    excess = wk[RF_AFTER] - wk[RF_NEFF] * st[W.SC_NOISE] ** 2
    return gain >= DRIFT_SHARE * excess


@njit(cache=CACHE)
def _trust(trial: np.ndarray, wk: np.ndarray) -> None:
    """Keep the trial's ln a1, ln a2 within RF_TRUST of the linearization point (none if RF_TRUST is 0).

    The statistics give the model's cost only near the point they were taken at: beyond it the states are
    extrapolated to first order, x(a) = x(al) + dx/da (a - al), and the sensitivity columns become free
    regressors that fit what the second-order model cannot (close unmodeled modes). The re-fit moves the
    resonance at most to the region's edge; the replay at the new point (``RELINEARIZE``) then lets the
    exact cost judge the next move."""
    r = wk[RF_TRUST]
    if r > 0.0:
        for i, lin in ((1, wk[RF_A1L]), (2, wk[RF_A2L])):
            c = math.log(lin)
            trial[i] = min(max(trial[i], c - r), c + r)


@njit(cache=CACHE)
def _noise_variance(wk: np.ndarray, k: int) -> float:
    """The window's noise variance at the fit's result (cost over effective samples less k parameters): what the
    drift and wide tests' statistics are in units of."""
    return max(wk[RF_AFTER], 0.0) / max(wk[RF_NEFF] - k, 1.0)


@njit(cache=CACHE)
def _step_done(wk: np.ndarray) -> bool:
    """A Levenberg-Marquardt step ended: the next step, or the covariance after the last (not done yet)."""
    wk[RF_STEP] += 1.0
    done = wk[RF_STEP] >= wk[RF_STEPS] or (wk[RF_MOVED] == 0.0 and wk[RF_MU] > 1e3)
    wk[RF_STAGE] = ST_COVARIANCE if done else ST_JACOBIAN
    return False


@njit(cache=CACHE)
def run(st: np.ndarray, S: np.ndarray, shift: np.ndarray, live: np.ndarray, wk: np.ndarray, lam: np.ndarray,
        dx: float) -> None:
    """The rest of a re-fit or change test in one call (block mode, where no sample waits for it)."""
    while not fit_unit(st, S, shift, live, wk, lam, dx):
        pass


# header of the context array (``context``): what ``sample_work`` needs besides the sample's arrays
CX_K = 0          # parameters (theta's length)
CX_SHIFT = 1      # rows and columns of the drift-origin total (``window.move_origin``)
CX_Q = 3          # SOE nodes (lam's length)
CX_DX = 4         # the SOE grid's log step
CX_WORKS = 5      # number of work arrays, then (offset, size) of each
CX_MAX_WORKS = 2
CX_HEAD = CX_WORKS + 1 + 2 * CX_MAX_WORKS


def context(theta: np.ndarray, shift: np.ndarray, lam: np.ndarray, dx: float,
            works: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[np.ndarray]]:
    """One array holding the live theta, the drift-origin total, the SOE nodes and the work arrays, so that
    the per-sample kernel takes one argument for all of them (each array argument costs ~0.25 us of
    numba's dispatch on every call). Returns it and views of theta, shift and the works (copies of the
    values given), which the tracker then uses in their place."""
    if len(works) > CX_MAX_WORKS:
        raise ValueError(f"refit.context: at most {CX_MAX_WORKS} work arrays, got {len(works)}")
    k, q = theta.size, lam.size
    head = np.zeros(CX_HEAD)
    head[CX_K], head[CX_SHIFT], head[CX_SHIFT + 1], head[CX_Q], head[CX_DX] = k, *shift.shape, q, dx
    head[CX_WORKS] = len(works)
    o = CX_HEAD + k + shift.size + q
    for i, w in enumerate(works):
        head[CX_WORKS + 1 + 2 * i], head[CX_WORKS + 2 + 2 * i] = o, w.size
        o += w.size
    ctx = np.concatenate([head, theta, shift.ravel(), lam] + list(works))
    views = [ctx[int(head[CX_WORKS + 1 + 2 * i]):int(head[CX_WORKS + 1 + 2 * i]) + w.size]
             for i, w in enumerate(works)]
    o = CX_HEAD
    return ctx, ctx[o:o + k], ctx[o + k:o + k + shift.size].reshape(shift.shape), views


@njit(cache=CACHE)
def _unpack(ctx: np.ndarray, which: int) -> tuple:
    """theta, shift, lam, dx and work array ``which`` from a context array (``context``)."""
    k, rows, cols, q = int(ctx[CX_K]), int(ctx[CX_SHIFT]), int(ctx[CX_SHIFT + 1]), int(ctx[CX_Q])
    o = CX_HEAD
    theta = ctx[o:o + k]
    shift = ctx[o + k:o + k + rows * cols].reshape(rows, cols)
    o += k + rows * cols
    lam = ctx[o:o + q]
    w0, n = int(ctx[CX_WORKS + 1 + 2 * which]), int(ctx[CX_WORKS + 2 + 2 * which])
    return theta, shift, lam, ctx[CX_DX], ctx[w0:w0 + n]


#: ``sample_work``'s status flag: the re-fit or change test it advanced is done (added to ``window.sample``'s).
MACHINE_DONE = 16


@njit(cache=CACHE)
def sample_work(u: float, y: float, st: np.ndarray, S: np.ndarray, ring: np.ndarray, ctx: np.ndarray,
                which: int, slices: int) -> int:
    """One sample (``window.sample``), then ``slices`` slices of the re-fit or change test under way in the
    context's work array ``which`` (``context``); its status plus ``MACHINE_DONE`` when that finished.

    Why here and not in Python between samples: a re-fit runs every ~0.1 s, so by then the
    interpreter's code paths are cold, and a call from Python per slice cost more than the slice.
    Inside the per-sample call each slice adds one to a few microseconds to ~2 % of the samples.
    """
    status = W.sample(u, y, st, S, ring)
    theta, shift, lam, dx, wk = _unpack(ctx, which)
    for _ in range(slices):
        if fit_unit(st, S, shift, theta, wk, lam, dx):
            return status + MACHINE_DONE
    return status


@njit(cache=CACHE)
def block_work(u: np.ndarray, y: np.ndarray, st: np.ndarray, S: np.ndarray, ring: np.ndarray, ctx: np.ndarray,
               which: int, slices: int, status: np.ndarray, start: int) -> int:
    """``sample_work`` for samples ``start`` on, until the re-fit or change test under way finishes or the caller's
    work is due (flag 8); their statuses in ``status``; returns how many were consumed. The per-sample calls of
    update() while the machine runs, in one loop (block mode lands the machine's result at the same sample)."""
    for k in range(start, u.size):
        s = sample_work(u[k], y[k], st, S, ring, ctx, which, slices)
        status[k] = s
        if s >= 8:                         # (MACHINE_DONE is 16: a finished machine stops the loop too)
            return k + 1 - start
    return u.size - start


@njit(cache=CACHE)
def start_test(st: np.ndarray, S: np.ndarray, S0: np.ndarray, sy0: np.ndarray, syy0: float, shift: np.ndarray,
               shift0: np.ndarray, live: np.ndarray, wk: np.ndarray, free_rates: bool) -> None:
    """Start the change test in its own work array: the statistics since a snapshot (S0, sy0, syy0,
    shift0; ``window.since_statistics``), theta from the live estimate, fresh damping. ``fit_unit``
    (or ``sample_work``) then fits them from the Jacobian on (``MASK_TEST``, no drift test).

    ``free_rates``: the window has drift columns but does not fit them yet (they wait for a converged
    window spanning DRIFT_MIN_S): the test fits the drift itself. Otherwise a drifting plant's last
    second is fitted by moving the resonance (seen: a flat compensated hold drifting ~4 noise levels
    per second read a1 +35 %, a2 -26 %, statistic 731: a change restarted the window at 1.5 s).
    """
    _since(st, S, S0, sy0, syy0, shift, shift0, live, wk, free_rates)


@njit(cache=CACHE)
def queue_test(wk: np.ndarray, slot: int, syy0: float, free_rates: bool) -> None:
    """Start the change test on the snapshot in ``slot`` (``snapshot_slots``): its first slice, in the per-sample
    kernel, takes the statistics since the snapshot (``start_test``'s work, ~7 us warm, ~15 us cold: with the
    Python that starts it, it was over 25 us in one update())."""
    wk[RF_SNAP] = slot
    wk[RF_SNAP_SYY] = syy0
    wk[RF_FREE_RATES] = 1.0 if free_rates else 0.0
    wk[RF_ROW] = 0.0
    wk[RF_AFTER_WARM] = ST_SINCE
    wk[RF_STAGE] = ST_WARM


@njit(cache=CACHE)
def _since(st: np.ndarray, S: np.ndarray, S0: np.ndarray, sy0: np.ndarray, syy0: float, shift: np.ndarray,
           shift0: np.ndarray, live: np.ndarray, wk: np.ndarray, free_rates: bool) -> None:
    """``start_test``'s work in one call."""
    p, k = S.shape[0], live.shape[0]
    theta, var, H, g, cov, H2, g2, F, fy, masks = _views(wk, p, k)
    wk[RF_FYY] = W.since_statistics(st, S, S0, sy0, syy0, shift, shift0, F, fy)
    _test_start(st, live, wk, free_rates)
    wk[RF_STAGE] = ST_JACOBIAN


@njit(cache=CACHE)
def _test_start(st: np.ndarray, live: np.ndarray, wk: np.ndarray, free_rates: bool) -> None:
    """A change test's header at the instant of its statistics: theta from the live estimate, fresh damping."""
    k = live.shape[0]
    wk[HEAD:HEAD + k] = live
    wk[RF_NEFF] = st[W.SC_NEFF]
    wk[RF_SINCE_N] = st[W.SC_N]
    wk[RF_SINCE_G] = st[W.SC_G]
    wk[RF_A1L], wk[RF_A2L] = st[W.SC_A1L], st[W.SC_A2L]
    wk[RF_STEP] = 0.0
    wk[RF_MU] = 1e-3
    wk[RF_MASK] = MASK_TEST_RATES if free_rates else MASK_TEST
    wk[RF_DRIFT] = 0.0
    wk[RF_DRIFT_SWITCH] = 0.0
    wk[RF_SCORING] = 0.0


@njit(cache=CACHE)
def _drift_test(wk: np.ndarray, theta: np.ndarray, cov: np.ndarray, k: int, drift: int) -> bool:
    """After the covariance: the Wald test of the rates (done), or queue the score test (not done).

    Rates on: their Wald statistic over the noise variance; below DRIFT_OFF, or a rate beyond the
    plausible DRIFT_MAX, switches them off and zeroes them. Rates off: the score test takes two
    more stages (the normal equations at the result, then the Gauss-Newton gain of freeing them).
    """
    if drift == 0 or (drift == 1 and not np.all(np.isfinite(theta))):
        wk[RF_DRIFT] = 0.0
        return True
    sigma2 = _noise_variance(wk, k)
    wk[RF_SIGMA2] = sigma2
    wk[RF_DRIFT_STAT] = 0.0
    if not sigma2 > 0.0:
        return True
    r0 = int(wk[RF_R0])
    if drift == 1:
        return False                   # the score test follows (``fit_unit``)
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


#: ``accept``'s verdicts: swapped in, stale (re-linearized meanwhile), rejected (non-finite, zero gain, or
#: a negative cost far from the linearization point).
ACCEPTED, STALE, REJECTED = 0, 1, 2

#: What ``accept`` returns, as plain floats: the verdict; alpha, ln a1, ln a2, b; the window cost and its
#: effective samples; the largest relative move of those four; the drift test run (0-2), its statistic
#: and the rate switch (+1 on, -1 off); the variances (times sigma^2) of alpha, ln a1, ln a2, b, the
#: offset and the two rates (0 where absent); the sample count, the output's noise level and whether a1 or a2
#: moved beyond RELINEARIZE from the linearization point (what the tracker's Python would read from numpy).
#: ``accept`` returns these as a plain tuple (``Accepted._make`` names them): numba boxes a namedtuple at
#: about twice a tuple's cost, ~40 against ~15-20 us with the caches cold, as they are after a re-fit.
Accepted = namedtuple("Accepted", "verdict alpha ln_a1 ln_a2 b cost neff move drift drift_stat drift_switch "
                                  "var_alpha var_ln_a1 var_ln_a2 var_b var_offset var_rate0 var_rate1 "
                                  "n noise relinearize")


@njit(cache=CACHE)
def accept(st: np.ndarray, live: np.ndarray, wk: np.ndarray, lam: np.ndarray, dx: float) -> tuple:
    """Swap a finished re-fit into the live estimate (``live``, and the prediction's coefficients in st).

    Returns ``Accepted``'s fields as a plain tuple of floats: the tracker's Python reads one tuple, no numpy.

    The resonance is first kept within what the sampling represents. A fit taken at another linearization
    point than the live one is STALE (the next re-fit decides). A sum of squares below zero is the
    linearized cost breaking down far from the linearization point (seen: -2.5 against 1-4, after a
    post-change search in a wrong basin: its sigma would be 0 and the quality "good"), REJECTED; near it
    the linearized cost holds, and below zero it is the rounding of syy - 2 m.sy + m.S.m on an output far
    above a tiny noise (a compensated plant read through a 20-bit ADC: every fit was rejected and the
    quality never left "first window fit pending"): the output's own noise level (second differences)
    stands in for the window cost.
    """
    p, k = W.parts(st)[1], live.shape[0]
    theta, var, H, g, cov, H2, g2, F, fy, masks = _views(wk, p, k)
    bound_resonance(theta, wk)
    cost = wk[RF_AFTER]
    verdict = ACCEPTED
    move = 0.0
    if wk[RF_A1L] != st[W.SC_A1L] or wk[RF_A2L] != st[W.SC_A2L]:
        verdict = STALE
    else:
        negative = cost < -1e-9 * abs(wk[RF_FYY])
        relin = wk[RF_RELINEARIZE]
        near = abs(math.exp(theta[1]) / wk[RF_A1L] - 1) <= relin and abs(math.exp(theta[2]) / wk[RF_A2L] - 1) <= relin
        if negative and near:
            cost = st[W.SC_NOISE] ** 2 * st[W.SC_NEFF]
            negative = False
        if not np.all(np.isfinite(theta)) or theta[3] == 0.0 or not math.isfinite(cost) or negative:
            verdict = REJECTED
        else:
            for i in range(4):
                move = max(move, abs(theta[i] - live[i]) / max(abs(live[i]), 1e-300))
            live[:] = theta
            W.set_estimate(live, st, lam, dx)
    r0 = int(wk[RF_R0])
    rate0 = var[r0] if k > r0 else 0.0
    rate1 = var[r0 + 1] if k > r0 + 1 else 0.0
    relin = wk[RF_RELINEARIZE]
    far = abs(math.exp(theta[1]) / st[W.SC_A1L] - 1) > relin or abs(math.exp(theta[2]) / st[W.SC_A2L] - 1) > relin
    return (verdict, theta[0], theta[1], theta[2], theta[3], cost, wk[RF_NEFF], move, wk[RF_DRIFT],
            wk[RF_DRIFT_STAT], wk[RF_DRIFT_SWITCH], var[0], var[1], var[2], var[3], var[4], rate0, rate1,
            int(st[W.SC_N]), st[W.SC_NOISE], far)


@njit(cache=CACHE)
def bound_resonance(theta: np.ndarray, wk: np.ndarray) -> bool:
    """Keep (ln a1, ln a2) within the resonances the sampling represents (the fn and zeta bounds in the
    header); True if they were outside. Beyond them the regressor's coefficients overflow (a fit that
    collapsed a2 to 1e-11 left a NaN window for good)."""
    hit = False
    if not theta[2] >= wk[RF_LN_A2_MIN]:      # also NaN
        theta[2] = wk[RF_LN_A2_MIN]
        hit = True
    ln_zeta = theta[1] - math.log(2.0) - 0.5 * theta[2]
    lo, hi = wk[RF_LN_ZETA_LO], wk[RF_LN_ZETA_HI]
    if not lo <= ln_zeta <= hi:
        if math.isfinite(ln_zeta):
            theta[1] += min(max(ln_zeta, lo), hi) - ln_zeta
        hit = True
    return hit


#: What ``test_outcome`` returns: the window costs of the last second at the live estimate and at the test's
#: fit; the fit's and the live ln a1, ln a2, b; the fit's variances (times sigma^2) of ln a1, ln a2, b; the
#: sample count at which it took its statistics (a plain tuple, as ``accept``'s).
TestOutcome = namedtuple("TestOutcome", "before after ln_a1 ln_a2 b live_ln_a1 live_ln_a2 live_b "
                                        "var_ln_a1 var_ln_a2 var_b n")


@njit(cache=CACHE)
def test_outcome(wk: np.ndarray, live: np.ndarray) -> tuple:
    """A finished change test's numbers, ``TestOutcome``'s fields as a plain tuple of floats (the tracker's
    Python then needs no numpy)."""
    k = live.shape[0]
    theta, var = wk[HEAD:HEAD + k], wk[HEAD + k:HEAD + 2 * k]
    return (wk[RF_START_COST], wk[RF_AFTER], theta[1], theta[2], theta[3], live[1], live[2], live[3],
            var[1], var[2], var[3], int(wk[RF_SINCE_N]))


@njit(cache=CACHE)
def weight_variances(wk: np.ndarray, p: int, k: int, t0: int, out: np.ndarray) -> None:
    """The variances (times sigma^2) of the hysteresis weights w_i = c_i / b of a finished re-fit (its theta from
    t0, ``out.size`` weights) from its covariance, by the delta method: ``(var c_i - 2 w_i cov(c_i, b) + w_i^2 var b)
    / b^2``. The covariance is the window's whole Gauss-Newton one (the prior on the weights in it): each weight's
    variance has b, the creep and resonance parameters, the offset, the free responses and the start columns
    profiled out. A pinned weight (0) and a covariance that failed read inf."""
    theta, var, H, g, cov, H2, g2, F, fy, masks = _views(wk, p, k)
    b = theta[3]
    for i in range(out.shape[0]):
        j = t0 + i
        w = theta[j] / b if b != 0.0 else 0.0
        v = (cov[j, j] - 2.0 * w * cov[j, 3] + w * w * cov[3, 3]) / (b * b) if b != 0.0 else np.inf
        out[i] = v if theta[j] != 0.0 and math.isfinite(v) and v >= 0.0 else np.inf


def result(wk: np.ndarray) -> tuple[list[float], list[float], list[float]]:
    """(header, theta, diagonal of the covariance) as plain floats (tests and diagnostics)."""
    k = int(wk[RF_K])
    vals = wk[:HEAD + 2 * k].tolist()
    return vals[:HEAD], vals[HEAD:HEAD + k], vals[HEAD + k:]
