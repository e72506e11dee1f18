"""The window tracker's hysteresis columns: play operators filtered by the plant, as regressors of its own fit.

The plant is Hammerstein, ``y = b G1[u + sum_i w_i p_i(u)] + offset`` with ``G1 = 1/(s^alpha (1 + a1 s + a2
s^2))`` and ``p_i`` the play operators of thresholds ``r_i`` (``effects.hysteresis.play_operators``). G1 is
linear, so ``y = b G1[u] + sum_i (b w_i) G1[p_i] + offset``: each play's output goes through the same SOE nodes
and resonance states as u (the nodes do not depend on alpha), and its column is the unit-gain model's response to
it, ``h_i = chan_i . m[:Q+2] / b`` with the window's current coefficients ``m``. The products c_i = b w_i are then
linear parameters of the window's least squares beside the offset (the weights relative to b, the batch fit's,
are c_i / b); the columns are pseudo-linear (computed with the estimate of their sample's time, as the drift
columns are, and recomputed with the current one by every replay). Unit gain: a column computed while b was
still far off (the start, a change) is as good as one computed now; with b in it, such rows made the window
trade b against the first weights (b 20-50 % off on random plants).

The block at the end of the state array (``block_at``; ``size`` entries):

==================  ====================================================================================
``[0]``             1 once the operators have been started (at the first input, centred on it)
``[1]``, ``[2]``    the lowest and the highest input fed (the tracker widens the thresholds with them)
``[GAIN]``          b of the coefficients m (``window.set_estimate``): the columns are unit-gain responses
``r`` (K)           the thresholds
``plays`` (K)       the operators' states after the last sample
``ptail`` (K)       their states before the oldest remembered sample
``opened`` (K)      1 moved up, 2 moved down, 3 both since the start (or a replay's oldest sample): opened
``chan`` (K, Q+2)   each play's SOE nodes and resonance states x0, x1 (at the linearization point)
``ctail`` (K, Q)    each play's node states before the oldest remembered sample
==================  ====================================================================================
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .layout import FREE, ONE, md_at, resonance_in_co

CACHE = True
#: Prior scale of each weight in the window's fit (a Gaussian around 0, as the batch fit's
#: ``effects.hysteresis.WEIGHT_SCALE``): a weight the window determines better than this is the data's; a combination
#: of operators the input opens alike (near-collinear columns) is held near 0 instead of cancelling in large pairs.
WEIGHT_SCALE = 0.03
#: The prior's noise level is at least this times the window's output RMS (a noise-free record still pins them).
PRIOR_FLOOR = 1e-6
#: Entries before the thresholds: the started flag, the input's lowest and highest value, b of the coefficients.
HEAD = 4
GAIN = 3


@njit(cache=CACHE, inline="always")
def size(q: int, k: int) -> int:
    """Entries of the hysteresis block for Q nodes and K operators (0 without operators)."""
    if k == 0:
        return 0
    return HEAD + 4 * k + k * (q + 2) + k * q


@njit(cache=CACHE, inline="always")
def block_at(q: int, nm: int, nr: int, nh: int) -> int:
    """Offset of the hysteresis block: after ``md``, the last block of the layout (its trailing columns are the
    K hysteresis columns and the R drift columns)."""
    return md_at(q, nm, nr + nh) + q + ONE


@njit(cache=CACHE, inline="always")
def channels_at(o: int, k: int) -> int:
    """Offset of ``chan`` for the block at ``o``."""
    return o + HEAD + 4 * k


@njit(cache=CACHE)
def set_thresholds(st: np.ndarray, o: int, r: np.ndarray) -> None:
    """The operators' thresholds (before the first sample: the operators start at it)."""
    k = r.shape[0]
    for i in range(k):
        st[o + HEAD + i] = r[i]


@njit(cache=CACHE, fastmath={"contract", "reassoc", "arcp"})
def columns(st: np.ndarray, o: int, k: int, q: int, phi: np.ndarray, c0: int, m: np.ndarray) -> None:
    """phi[c0 + i] = chan_i . m[:Q+2] / b: the unit-gain model's response to play i at the current coefficients."""
    ch = channels_at(o, k)
    w = q + 2
    b = st[o + GAIN]
    inv = 1.0 / b if b != 0.0 else 0.0
    for i in range(k):
        row = ch + i * w
        acc = 0.0
        for j in range(w):
            acc += st[row + j] * m[j]
        phi[c0 + i] = acc * inv


@njit(cache=CACHE)
def _start(st: np.ndarray, o: int, k: int, u: float) -> None:
    """The operators centred on the first input (``play_operators``' p[-1] = u[0]), here and in the tail."""
    for i in range(k):
        st[o + HEAD + k + i] = u
        st[o + HEAD + 2 * k + i] = u
    st[o] = 1.0
    st[o + 1] = u
    st[o + 2] = u


@njit(cache=CACHE, fastmath={"contract", "reassoc", "arcp"})
def step(st: np.ndarray, o: int, k: int, q: int, co: np.ndarray, u: float) -> None:
    """One sample of the zero-order-held input u: the plays, then each play's nodes and resonance states
    (exactly as ``window.advance`` moves u's; no sensitivity states)."""
    if st[o] == 0.0:
        _start(st, o, k, u)
    if u < st[o + 1]:
        st[o + 1] = u
    elif u > st[o + 2]:
        st[o + 2] = u
    r = resonance_in_co(q)
    ch = channels_at(o, k)
    w = q + 2
    for i in range(k):
        ri = st[o + HEAD + i]
        p = st[o + HEAD + k + i]
        if p < u - ri:
            p = u - ri
            st[o + HEAD + 3 * k + i] = float(int(st[o + HEAD + 3 * k + i]) | 1)
        elif p > u + ri:
            p = u + ri
            st[o + HEAD + 3 * k + i] = float(int(st[o + HEAD + 3 * k + i]) | 2)
        st[o + HEAD + k + i] = p
        row = ch + i * w
        for j in range(q):
            st[row + j] = co[j] * st[row + j] + co[q + j] * p
        x0 = st[row + q]
        x1 = st[row + q + 1]
        st[row + q] = co[r] * x0 + co[r + 1] * x1 + co[r + 4] * p
        st[row + q + 1] = co[r + 2] * x0 + co[r + 3] * x1 + co[r + 5] * p


@njit(cache=CACHE, fastmath={"contract", "reassoc", "arcp"})
def tail(st: np.ndarray, o: int, k: int, q: int, co: np.ndarray, u_old: float) -> None:
    """The oldest remembered sample leaves the ring: the tail's plays and nodes absorb it (``window._remember``'s
    ztail, for each play)."""
    if st[o] == 0.0:
        return
    ct = channels_at(o, k) + k * (q + 2)
    for i in range(k):
        ri = st[o + HEAD + i]
        p = st[o + HEAD + 2 * k + i]
        if p < u_old - ri:
            p = u_old - ri
        elif p > u_old + ri:
            p = u_old + ri
        st[o + HEAD + 2 * k + i] = p
        row = ct + i * q
        for j in range(q):
            st[row + j] = co[j] * st[row + j] + co[q + j] * p


@njit(cache=CACHE)
def replay_origin(st: np.ndarray, live: np.ndarray, o: int, k: int, q: int) -> None:
    """A replay's start at the ring's oldest sample: the live block's thresholds and tails, the plays and the
    nodes at the tail's states, the resonance states at zero (as ``window.replay_origin`` starts u's)."""
    st[o] = live[o]
    st[o + 1] = live[o + 1]
    st[o + 2] = live[o + 2]
    st[o + GAIN] = live[o + GAIN]
    for i in range(k):
        st[o + HEAD + i] = live[o + HEAD + i]
        st[o + HEAD + k + i] = live[o + HEAD + 2 * k + i]
        st[o + HEAD + 2 * k + i] = live[o + HEAD + 2 * k + i]
        st[o + HEAD + 3 * k + i] = 0.0
    ch = channels_at(o, k)
    ct = ch + k * (q + 2)
    for i in range(k):
        for j in range(q):
            st[ch + i * (q + 2) + j] = live[ct + i * q + j]
            st[ct + i * q + j] = live[ct + i * q + j]
        st[ch + i * (q + 2) + q] = 0.0
        st[ch + i * (q + 2) + q + 1] = 0.0


@njit(cache=CACHE)
def corrected_nodes(st: np.ndarray, o: int, k: int, q: int, w: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    """The node states of the corrected input v = u + sum_i w_i p_i (in place in ``zeta``, u's nodes) from each
    play's nodes in the block at ``o``; returns a copy of the plays' states (the corrected input's memory)."""
    ch = channels_at(o, k)
    for i in range(k):
        for j in range(q):
            zeta[j] += w[i] * st[ch + i * (q + 2) + j]
    return st[o + HEAD + k:o + HEAD + 2 * k].copy()


@njit(cache=CACHE)
def correct_input(u: np.ndarray, r: np.ndarray, plays: np.ndarray, w: np.ndarray) -> None:
    """u -> u + sum_i w_i p_i(u) in place, the plays advanced from their states ``plays`` (in place)."""
    k = r.shape[0]
    for n in range(u.shape[0]):
        x = u[n]
        v = x
        for i in range(k):
            p = plays[i]
            if p < x - r[i]:
                p = x - r[i]
            elif p > x + r[i]:
                p = x + r[i]
            plays[i] = p
            v += w[i] * p
        u[n] = v


@njit(cache=CACHE)
def swap_block(live: np.ndarray, replayed: np.ndarray, o: int, k: int, q: int) -> None:
    """A replay's swap (``window.swap_into``): the live input range and tails into the replayed block, whose
    thresholds, plays and channel states (at its resonance point, over every remembered sample) stay."""
    replayed[o + 1] = live[o + 1]
    replayed[o + 2] = live[o + 2]
    for i in range(k):
        replayed[o + HEAD + 2 * k + i] = live[o + HEAD + 2 * k + i]
    ct = channels_at(o, k) + k * (q + 2)
    for j in range(ct, ct + k * q):
        replayed[j] = live[j]


@njit(cache=CACHE)
def rethreshold(st: np.ndarray, o: int, k: int, q: int, r: np.ndarray, u_oldest: float, ztail: np.ndarray) -> None:
    """New thresholds ``r`` (a wider input range): the tails as if the operators had started centred on the oldest
    remembered input (``u_oldest``) with the input's history before it (each play's nodes = u's, ``ztail``). Exact
    while the ring still holds the stream's first sample (the tails are then the start's); the next replay rebuilds
    the plays and their columns from the tails."""
    ct = channels_at(o, k) + k * (q + 2)
    for i in range(k):
        st[o + HEAD + i] = r[i]
        st[o + HEAD + 2 * k + i] = u_oldest
        st[o + HEAD + 3 * k + i] = 0.0
        for j in range(q):
            st[ct + i * q + j] = ztail[j]


@njit(cache=CACHE)
def weight_prior(F: np.ndarray, c0: int, nh: int, noise: float, neff: float, fyy: float, b: float) -> None:
    """Add the weights' prior to a re-fit's statistics at true scale (F, the window's Gram matrix; the columns from
    c0, coefficients c_i = b w_i): w_i ~ N(0, WEIGHT_SCALE^2) against the output noise (the monitor's level, at
    least PRIOR_FLOOR x the window's RMS) is the pseudo-observation ``noise / (WEIGHT_SCALE |b|) * c_i = 0``, i.e.
    (noise / (WEIGHT_SCALE b))^2 on each coefficient's diagonal (the batch fit's prior rows)."""
    noise = max(noise, PRIOR_FLOOR * np.sqrt(max(fyy, 0.0) / max(neff, 1.0)))
    if b == 0.0:
        return
    lam = (noise / (WEIGHT_SCALE * b)) ** 2
    for i in range(nh):
        F[c0 + i, c0 + i] += lam


@njit(cache=CACHE)
def pin_unopened(st: np.ndarray, o: int, k: int, theta: np.ndarray, t0: int, masks: np.ndarray, rows: np.ndarray,
                 free: float) -> None:
    """A re-fit's weights (theta from t0): an operator the input has not opened (pushed both up and down) since the
    start or the oldest remembered sample follows u - r or u + r, an affine copy of the input, and its weight is not
    the data's: pinned at 0 (fixed in the masks ``rows``); an opened one is free (mask value ``free``), as the batch
    fit's rule (``effects.hysteresis.opened_operators``)."""
    for i in range(k):
        opened = int(st[o + HEAD + 3 * k + i]) == 3
        if not opened:
            theta[t0 + i] = 0.0
        for j in range(rows.shape[0]):
            masks[rows[j], t0 + i] = free if opened else 0.0
