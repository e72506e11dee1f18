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

The plays start centred on the first input; a device's operators start wherever its last motion left them (a
piezo at rest after a rise sits on its ascending branch, p_i = u - r_i). Two more columns let the data say
which: the start columns, the responses to ``D_s = sum_i w_i (p_i^s - p_i)``, the loop's input as it would be
from the ascending (s = a: p_i^s = u0 - r_i at the start) or the descending start (p_i^s = u0 + r_i), less the
centred one's (weights of their sample's time, as the columns' m); after a rest at the first input, a start in
equilibrium (``set_start_form``), whose coefficients are fitted only between ``free_start`` and a restart's
``drop_start`` (pinned at 0 otherwise). Their coefficients b sigma_s are linear too:
sigma_s = 1 is the start s exactly, 0 the centred one. ``D_s`` is zero once the input has risen or fallen by 2 r_i
since the start for every opened play (the three starts' plays are then one), but the nodes' memory keeps its
response alive. Without these columns the window fitted a start on a branch with a wrong loop and b (on random
sine and triangle records started on a branch, b was off by a median 18 %; with them, 11 %); on plants started
centred the weights came out 2-3x closer with them too.

The block at the end of the state array (``block_at``; ``size`` entries; K plays, ``nh = K + START`` columns):

==================  ====================================================================================
``[0]``             1 once the operators have been started (at the first input, centred on it)
``[1]``, ``[2]``    the lowest and the highest input fed (``sweep``, the rest at the start)
``[GAIN]``          b of the coefficients m (``set_gain``): the columns are unit-gain responses
``[RISE]``          the input's largest rise above its lowest value before it (``sweep``) ...
``[FALL]``          ... and its largest fall below its highest value before it
``[REST]``          samples fed before the input first moved (a rest at the start)
``[EQUILIBRIUM]``   1: the start columns describe a start in equilibrium (``set_start_form``), 0: a jump
``[REST_MIN]``      the rest (samples) beyond which the input's first move reads its start in equilibrium
``[DROPPED]``       1: a start in equilibrium's columns left out for good, their coefficients 0 (``drop_start``)
``[FREED]``         1: the re-fits fit the coefficients of a start in equilibrium's columns (``free_start``)
``[AGE]``           samples since the ``opened`` flags last aged (``set_memory``) ...
``[EPOCH]``         ... and the samples between two agings (0: never)
``[RANGE_AGE]``     samples since the recent input range last aged (every ``EPOCH`` samples, as the flags)
``[RECENT]``...     the input's lowest and highest value in this epoch, then in the epoch before (``recent_span``)
``r`` (K)           the thresholds
``plays`` (K)       the operators' states after the last sample
``ptail`` (K)       their states before the oldest remembered sample
``opened`` (K)      bit 0 moved up, bit 1 moved down in this epoch; bits 2, 3 the same in the epoch before
``starts`` (2K)     the plays from the ascending and from the descending start, after the last sample
``stail`` (2K)      the same before the oldest remembered sample
``w`` (K)           the weights w_i of the coefficients m (``set_gain``), for the start columns' D_s
``chan`` (nh, Q+2)  each play's (then each D_s's) SOE nodes and resonance states x0, x1
``ctail`` (nh, Q)   their node states before the oldest remembered sample
==================  ====================================================================================
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .layout import ONE, md_at, resonance_in_co

CACHE = True
FAST: set[str] = set()   # IEEE arithmetic, as the window kernels (``window.FAST``: why)
#: Prior scale of each weight in the window's fit (a Gaussian around 0, as the batch fit's
#: ``effects.hysteresis.WEIGHT_SCALE``): a weight the window determines better than this is the data's; a combination
#: of operators the input opens alike (near-collinear columns) is held near 0 instead of cancelling in large pairs.
WEIGHT_SCALE = 0.03
#: Prior scale of each start column's sigma_s (a Gaussian around 0): one start is sigma = 1, so the data decide
#: wherever they tell the starts apart; where they do not (an input that has not moved) the centred start stays.
START_SCALE = 1.0
#: The prior's noise level is at least this times the window's output RMS (a noise-free record still pins them).
PRIOR_FLOOR = 1e-6
#: Entries before the thresholds: the started flag, the input's lowest and highest value, b of the coefficients,
#: the input's largest rise and fall (``sweep``), the samples before its first move, the start's form, the
#: ``opened`` flags' epoch and the recent input range's.
HEAD = 18
GAIN = 3
RISE = 4
FALL = 5
REST = 6
#: 1 once the start columns describe a start in equilibrium (``set_start_form``), 0 while they describe a jump.
EQUILIBRIUM = 7
#: The samples at the first input beyond which its first move reads the start as one in equilibrium (0: never).
REST_MIN = 8
#: 1 once a start in equilibrium's columns are left out for good (``drop_start``).
DROPPED = 9
#: 1 once the re-fits fit the coefficients of a start in equilibrium's columns (``free_start``).
FREED = 10
#: Samples since the ``opened`` flags last aged, and the samples between two agings (``set_memory``; 0: never).
AGE = 11
EPOCH = 12
#: Samples since the recent input range last aged (``recent_span``; every ``EPOCH`` samples, on a clock of its own: a
#: replay rebuilds the ``opened`` flags over the remembered samples, the range stays the live stream's).
RANGE_AGE = 13
#: The input's lowest and highest value in this epoch (RECENT, RECENT + 1) and in the one before (RECENT + 2, + 3).
RECENT = 14
#: Start columns after the K play columns: the ascending start's, then the descending start's.
START = 2


@njit(cache=CACHE, inline="always")
def columns_for(k: int) -> int:
    """Hysteresis columns for K play operators: their K columns and the START start columns (0 without plays)."""
    return k + START if k > 0 else 0


@njit(cache=CACHE, inline="always")
def size(q: int, nh: int) -> int:
    """Entries of the hysteresis block for Q nodes and nh columns (0 without them)."""
    if nh == 0:
        return 0
    k = nh - START
    return HEAD + 9 * k + nh * (q + 2) + nh * q


@njit(cache=CACHE, inline="always")
def block_at(q: int, nm: int, nr: int, nh: int) -> int:
    """Offset of the hysteresis block: after ``md``, the last block of the layout (its trailing columns are the
    nh hysteresis columns and the R drift columns)."""
    return md_at(q, nm, nr + nh) + q + ONE


@njit(cache=CACHE, inline="always")
def channels_at(o: int, nh: int) -> int:
    """Offset of ``chan`` for the block at ``o`` with nh columns."""
    return o + HEAD + 9 * (nh - START)


@njit(cache=CACHE)
def set_thresholds(st: np.ndarray, o: int, r: np.ndarray) -> None:
    """The operators' thresholds (before the first sample: the operators start at it)."""
    k = r.shape[0]
    for i in range(k):
        st[o + HEAD + i] = r[i]


@njit(cache=CACHE)
def set_start_form(st: np.ndarray, o: int, rest_min: float) -> None:
    """How the start columns read the stream's start (before the first sample). Until the input first moves, and
    for good if it held its first level for ``rest_min`` samples or fewer (a step at the first sample, behind the
    rest the start-up prepends), the input and the plays were zero before the first sample and a start on a branch
    differs from the centred one from it on: ``D_s = sum_i w_i (p_i^s - p_i)``, the estimate's weights. An input
    that held its first level longer shows the plant at rest there (a device resting on a branch since long
    before): at its first move D_s becomes zero before it (its channels cleared) and grows only as the input moves
    the plays, ``D_s = (1/K) sum_i [(p_i^s - p_i) - (p_i^s - p_i)(start)]``, with fixed weights (the estimate's
    weights fed back into it held a wrong loop: on random staircases from rest on a branch the live compensation
    reached 10x in 96 of 120 scans, with this form in all 120). Its coefficients: ``free_start``, ``drop_start``."""
    st[o + EQUILIBRIUM] = 0.0
    st[o + REST_MIN] = rest_min
    st[o + DROPPED] = 0.0
    st[o + FREED] = 0.0


@njit(cache=CACHE)
def set_memory(st: np.ndarray, o: int, epoch: float) -> None:
    """How long an operator counts as opened (``pin_unopened``): the flags of its moves up and down age every
    ``epoch`` samples (the window's forgetting time; 0: never), and it is opened while it moved both ways within
    this epoch and the one before. A window that forgets holds an operator's weight only while the input still moves
    it: stuck (the input's range now narrower than 2 r_i), its column is a constant plus the dying creep of its last
    move, which the weight trades with the offset and with any slow drift of the plant (a loop whose width grows:
    weights of 0.3 on operators the input had left 40 s before, the compensator, whose own play sits at another
    constant, then off by b w_i times that difference)."""
    st[o + AGE] = 0.0
    st[o + EPOCH] = epoch
    st[o + RANGE_AGE] = 0.0


@njit(cache=CACHE, inline="always")
def _epoch_turns(st: np.ndarray, o: int, clock: int) -> bool:
    """One sample on the clock at ``clock`` (``AGE``, ``RANGE_AGE``): True, and the clock back at 0, when it reaches
    ``EPOCH`` (never without an epoch)."""
    if st[o + EPOCH] <= 0.0:
        return False
    st[o + clock] += 1.0
    if st[o + clock] < st[o + EPOCH]:
        return False
    st[o + clock] = 0.0
    return True


@njit(cache=CACHE, inline="always")
def _age(st: np.ndarray, o: int, k: int) -> None:
    """One sample towards the ``opened`` flags' next aging (``set_memory``): at it, this epoch's flags become the
    epoch before's."""
    if not _epoch_turns(st, o, AGE):
        return
    for i in range(k):
        st[o + HEAD + 3 * k + i] = float((int(st[o + HEAD + 3 * k + i]) & 3) << 2)


@njit(cache=CACHE, inline="always")
def _track_range(st: np.ndarray, o: int, u: float) -> None:
    """The input u into this epoch's range; every ``EPOCH`` samples this epoch's range becomes the one before and a
    new one starts at u (``recent_span``)."""
    if u < st[o + RECENT]:
        st[o + RECENT] = u
    if u > st[o + RECENT + 1]:
        st[o + RECENT + 1] = u
    if not _epoch_turns(st, o, RANGE_AGE):
        return
    st[o + RECENT + 2] = st[o + RECENT]
    st[o + RECENT + 3] = st[o + RECENT + 1]
    st[o + RECENT] = u
    st[o + RECENT + 1] = u


@njit(cache=CACHE, inline="always")
def _is_open(flags: float) -> bool:
    """Moved up and down within this epoch and the one before (``set_memory``)."""
    f = int(flags)
    return ((f & 3) | (f >> 2)) == 3


@njit(cache=CACHE)
def _settle_start(st: np.ndarray, o: int, nh: int, q: int) -> None:
    """The first move after a rest longer than ``REST_MIN``: the start in equilibrium (``set_start_form``), its
    D_s zero so far (the start columns' channels and tails cleared)."""
    st[o + EQUILIBRIUM] = 1.0
    k = nh - START
    ch = channels_at(o, nh)
    for j in range(START * (q + 2)):
        st[ch + k * (q + 2) + j] = 0.0
    ct = ch + nh * (q + 2)
    for j in range(START * q):
        st[ct + k * q + j] = 0.0


@njit(cache=CACHE)
def set_gain(st: np.ndarray, o: int, nh: int, theta: np.ndarray, t0: int) -> None:
    """b and the weights w_i = theta[t0 + i] / b of an estimate into the block: the columns divide by b, the start
    columns' D_s weigh the plays with w."""
    b = theta[3]
    st[o + GAIN] = b
    k = nh - START
    wt = o + HEAD + 8 * k
    for i in range(k):
        st[wt + i] = theta[t0 + i] / b if b != 0.0 else 0.0


@njit(cache=CACHE, fastmath=FAST)
def columns(st: np.ndarray, o: int, nh: int, q: int, phi: np.ndarray, c0: int, m: np.ndarray) -> None:
    """phi[c0 + i] = chan_i . m[:Q+2] / b: the unit-gain model's response to play i (then to each D_s) at the
    current coefficients."""
    ch = channels_at(o, nh)
    w = q + 2
    b = st[o + GAIN]
    inv = 1.0 / b if b != 0.0 else 0.0
    for i in range(nh):
        row = ch + i * w
        acc = 0.0
        for j in range(w):
            acc += st[row + j] * m[j]
        phi[c0 + i] = acc * inv


@njit(cache=CACHE)
def _start(st: np.ndarray, o: int, k: int, u: float) -> None:
    """The operators centred on the first input (``play_operators``' p[-1] = u[0]), here and in the tail; the
    ascending and descending starts' plays at u - r and u + r."""
    for i in range(k):
        ri = st[o + HEAD + i]
        st[o + HEAD + k + i] = u
        st[o + HEAD + 2 * k + i] = u
        st[o + HEAD + 4 * k + i] = u - ri
        st[o + HEAD + 5 * k + i] = u + ri
        st[o + HEAD + 6 * k + i] = u - ri
        st[o + HEAD + 7 * k + i] = u + ri
    st[o] = 1.0
    st[o + 1] = u
    st[o + 2] = u
    st[o + RISE] = 0.0
    st[o + FALL] = 0.0
    st[o + REST] = 0.0
    st[o + RANGE_AGE] = 0.0
    for j in range(4):
        st[o + RECENT + j] = u


@njit(cache=CACHE, inline="always")
def _start_terms(eq: bool, c: float, w: float, p: float, pa: float, pd: float, r: float) -> tuple:
    """One play's terms of the two start columns (ascending, descending; ``set_start_form``): its start differences
    (``pa - p``, ``pd - p``) less their values at a rest (-r, +r) weighted 1/K (``c``) in the equilibrium form
    (``eq``), else weighted by the estimate's weight ``w``."""
    if eq:
        return c * (pa - p + r), c * (pd - p - r)
    return w * (pa - p), w * (pd - p)


@njit(cache=CACHE, inline="always")
def _play(p: float, u: float, r: float) -> float:
    if p < u - r:
        return u - r
    if p > u + r:
        return u + r
    return p


@njit(cache=CACHE, inline="always")
def _channel(st: np.ndarray, row: int, q: int, r: int, co: np.ndarray, x: float) -> None:
    """One sample of input x into the channel at ``row``: its nodes, then its resonance states."""
    for j in range(q):
        st[row + j] = co[j] * st[row + j] + co[q + j] * x
    x0 = st[row + q]
    x1 = st[row + q + 1]
    st[row + q] = co[r] * x0 + co[r + 1] * x1 + co[r + 4] * x
    st[row + q + 1] = co[r + 2] * x0 + co[r + 3] * x1 + co[r + 5] * x


@njit(cache=CACHE, fastmath=FAST)
def step(st: np.ndarray, o: int, nh: int, q: int, co: np.ndarray, u: float) -> None:
    """One sample of the zero-order-held input u: the plays (and the other starts'), then each play's and each
    D_s's nodes and resonance states (exactly as ``window.advance`` moves u's; no sensitivity states)."""
    k = nh - START
    if st[o] == 0.0:
        _start(st, o, k, u)
    if st[o + 1] == st[o + 2] and u != st[o + 1] and 0.0 < st[o + REST_MIN] < st[o + REST]:
        _settle_start(st, o, nh, q)
    if u < st[o + 1]:
        st[o + 1] = u
    elif u > st[o + 2]:
        st[o + 2] = u
    if st[o + 1] == st[o + 2]:
        st[o + REST] += 1.0
    if u - st[o + 1] > st[o + RISE]:
        st[o + RISE] = u - st[o + 1]
    if st[o + 2] - u > st[o + FALL]:
        st[o + FALL] = st[o + 2] - u
    _track_range(st, o, u)
    _age(st, o, k)
    r = resonance_in_co(q)
    ch = channels_at(o, nh)
    w = q + 2
    wt = o + HEAD + 8 * k
    eq = st[o + EQUILIBRIUM] != 0.0
    c = 1.0 / k
    da = 0.0
    dd = 0.0
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
        pa = _play(st[o + HEAD + 4 * k + i], u, ri)
        pd = _play(st[o + HEAD + 5 * k + i], u, ri)
        st[o + HEAD + 4 * k + i] = pa
        st[o + HEAD + 5 * k + i] = pd
        ia, id_ = _start_terms(eq, c, st[wt + i], p, pa, pd, ri)
        da += ia
        dd += id_
        _channel(st, ch + i * w, q, r, co, p)
    _channel(st, ch + k * w, q, r, co, da)
    _channel(st, ch + (k + 1) * w, q, r, co, dd)


@njit(cache=CACHE, fastmath=FAST)
def tail(st: np.ndarray, o: int, nh: int, q: int, co: np.ndarray, u_old: float) -> None:
    """The oldest remembered sample leaves the ring: the tail's plays and nodes absorb it (``window._remember``'s
    ztail, for each play and each D_s)."""
    if st[o] == 0.0:
        return
    k = nh - START
    ct = channels_at(o, nh) + nh * (q + 2)
    wt = o + HEAD + 8 * k
    eq = st[o + EQUILIBRIUM] != 0.0
    c = 1.0 / k
    da = 0.0
    dd = 0.0
    for i in range(k):
        ri = st[o + HEAD + i]
        p = _play(st[o + HEAD + 2 * k + i], u_old, ri)
        pa = _play(st[o + HEAD + 6 * k + i], u_old, ri)
        pd = _play(st[o + HEAD + 7 * k + i], u_old, ri)
        st[o + HEAD + 2 * k + i] = p
        st[o + HEAD + 6 * k + i] = pa
        st[o + HEAD + 7 * k + i] = pd
        ia, id_ = _start_terms(eq, c, st[wt + i], p, pa, pd, ri)
        da += ia
        dd += id_
        row = ct + i * q
        for j in range(q):
            st[row + j] = co[j] * st[row + j] + co[q + j] * p
    row = ct + k * q
    for j in range(q):
        st[row + j] = co[j] * st[row + j] + co[q + j] * da
        st[row + q + j] = co[j] * st[row + q + j] + co[q + j] * dd


def sweep(st: np.ndarray, o: int) -> float:
    """The input's largest rise above its lowest value before it, or fall below its highest, since the start. Any
    two states of play i (within r_i of the input, as every start is) are pushed to the same one by a rise or fall
    of 2 r_i: once ``sweep`` reaches 2 r_i, the play no longer depends on its state at the start."""
    return float(max(st[o + RISE], st[o + FALL]))


def free_start(st: np.ndarray, o: int, nh: int) -> None:
    """A re-fit that fits the window (not above the re-search's misfit line) with an opened play: the re-fits fit
    the coefficients of a start in equilibrium's columns from now on (``pin_unopened``); until then they are pinned
    at 0, the centred start. The columns take the plays' mean (fixed weights), so before the loop's weights are
    known they are the only hysteresis the window has: a move from rest that sweeps the plays turns both D_s into
    steps with the input's own, and the first re-fits with a play opened traded them with b and the weights (the
    resting-centred demo plant: b 0.27 for 2.5, weights of 8, a false change, no model after it). A window that
    fits has its loop; it need not be at the noise floor, which K operators may never reach on a real loop (the
    real 150 V record: the batch fit with the same 8 thresholds stays at 1.5x it), and there the start's creep,
    which runs through the whole record after a rest on a branch, is what the columns are for."""
    if in_equilibrium(st, o) and st[o + DROPPED] == 0.0 and bool(opened(st, o, nh).any()):
        st[o + FREED] = 1.0


def drop_start(st: np.ndarray, o: int) -> None:
    """A restart after a change: a start in equilibrium's columns are left out for good, their coefficients 0, the
    centred start. From the sweep on their D_s are constants, and in a window that starts at a change their creeping
    response only trades with alpha and b; held at the values fitted before, an error in them went into alpha (the
    resting-centred demo plant: sigma -0.13 held, alpha 0.146 for 0.12 on the scan after a restart; dropped, 0.12).
    A rest's samples dropped at the sweep (``settle_loop``) leave them as they are: their D_s is zero over the rest
    and constant from the sweep on, and the window from the sweep on still holds the creep it set off from the first
    move, which is what they are for (the real 150 V record, 3 s at rest on a branch, then a 1 Hz sine: the window
    at 1.50x the noise floor with them left out there, 1.46x with them kept and freed)."""
    if in_equilibrium(st, o):
        st[o + DROPPED] = 1.0


def recent_span(st: np.ndarray, o: int) -> float:
    """The input's range over this epoch and the one before (``set_memory``; since the start without forgetting):
    what the window's data can set play thresholds on. A command's brief excursion or a range the controller has
    left (the reference passed through before its first model) ages out of it."""
    lo = min(st[o + RECENT], st[o + RECENT + 2])
    hi = max(st[o + RECENT + 1], st[o + RECENT + 3])
    return float(hi - lo)


def in_equilibrium(st: np.ndarray, o: int) -> bool:
    """Do the start columns describe a start in equilibrium (``set_start_form``)?"""
    return bool(st[o + EQUILIBRIUM] != 0.0)


def opened(st: np.ndarray, o: int, nh: int) -> np.ndarray:
    """Which operators the input has opened (pushed both up and down) within the window's memory (``set_memory``)
    since the start or the oldest remembered sample (``pin_unopened``: the others' weights are pinned at 0)."""
    k = nh - START
    f = st[o + HEAD + 3 * k:o + HEAD + 4 * k].astype(np.int64)
    return ((f & 3) | (f >> 2)) == 3


@njit(cache=CACHE)
def replay_origin(st: np.ndarray, live: np.ndarray, o: int, nh: int, q: int) -> None:
    """A replay's start at the ring's oldest sample: the live block's thresholds, weights and tails, the plays and
    the nodes at the tail's states, the resonance states at zero (as ``window.replay_origin`` starts u's)."""
    k = nh - START
    st[o] = live[o]
    st[o + 1] = live[o + 1]
    st[o + 2] = live[o + 2]
    st[o + GAIN] = live[o + GAIN]
    st[o + RISE] = live[o + RISE]
    st[o + FALL] = live[o + FALL]
    st[o + REST] = live[o + REST]
    st[o + EQUILIBRIUM] = live[o + EQUILIBRIUM]
    st[o + REST_MIN] = live[o + REST_MIN]
    st[o + DROPPED] = live[o + DROPPED]
    st[o + FREED] = live[o + FREED]
    st[o + AGE] = 0.0
    st[o + EPOCH] = live[o + EPOCH]
    for j in range(RANGE_AGE, HEAD):
        st[o + j] = live[o + j]
    for i in range(k):
        st[o + HEAD + i] = live[o + HEAD + i]
        st[o + HEAD + k + i] = live[o + HEAD + 2 * k + i]
        st[o + HEAD + 2 * k + i] = live[o + HEAD + 2 * k + i]
        st[o + HEAD + 3 * k + i] = 0.0
        st[o + HEAD + 8 * k + i] = live[o + HEAD + 8 * k + i]
    for i in range(2 * k):
        st[o + HEAD + 4 * k + i] = live[o + HEAD + 6 * k + i]
        st[o + HEAD + 6 * k + i] = live[o + HEAD + 6 * k + i]
    ch = channels_at(o, nh)
    ct = ch + nh * (q + 2)
    for i in range(nh):
        for j in range(q):
            st[ch + i * (q + 2) + j] = live[ct + i * q + j]
            st[ct + i * q + j] = live[ct + i * q + j]
        st[ch + i * (q + 2) + q] = 0.0
        st[ch + i * (q + 2) + q + 1] = 0.0


@njit(cache=CACHE)
def corrected_nodes(st: np.ndarray, o: int, nh: int, q: int, w: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    """The node states of the corrected input v = u + sum_i w_i p_i + sum_s sigma_s D_s (in place in ``zeta``,
    u's nodes) from each column's nodes in the block at ``o`` (``w``: the K weights, then the sigma_s); returns a
    copy of the plays' states, then the ascending and the descending start's (3K: the corrected input's memory,
    ``correct_input``)."""
    ch = channels_at(o, nh)
    k = nh - START
    for i in range(nh):
        for j in range(q):
            zeta[j] += w[i] * st[ch + i * (q + 2) + j]
    out = np.empty(3 * k)
    out[:k] = st[o + HEAD + k:o + HEAD + 2 * k]
    out[k:] = st[o + HEAD + 4 * k:o + HEAD + 6 * k]
    return out


@njit(cache=CACHE)
def correct_input(u: np.ndarray, r: np.ndarray, plays: np.ndarray, w: np.ndarray, equilibrium: bool = False) -> None:
    """u -> u + sum_i w_i p_i(u) + sum_s sigma_s D_s in place (``w``: the K weights, then the sigma_s; D_s of the
    form ``set_start_form`` names), the plays (then the ascending and the descending start's) advanced from their
    states ``plays`` (3K, in place)."""
    k = r.shape[0]
    c = 1.0 / k
    for n in range(u.shape[0]):
        x = u[n]
        v = x
        da = 0.0
        dd = 0.0
        for i in range(k):
            p = _play(plays[i], x, r[i])
            pa = _play(plays[k + i], x, r[i])
            pd = _play(plays[2 * k + i], x, r[i])
            plays[i] = p
            plays[k + i] = pa
            plays[2 * k + i] = pd
            v += w[i] * p
            if equilibrium:
                da += c * (pa - p + r[i])
                dd += c * (pd - p - r[i])
            else:
                da += w[i] * (pa - p)
                dd += w[i] * (pd - p)
        u[n] = v + w[k] * da + w[k + 1] * dd


@njit(cache=CACHE)
def swap_block(live: np.ndarray, replayed: np.ndarray, o: int, nh: int, q: int) -> None:
    """A replay's swap (``window.swap_into``): the live input range and tails into the replayed block, whose
    thresholds, plays and channel states (at its resonance point, over every remembered sample) stay."""
    k = nh - START
    replayed[o + 1] = live[o + 1]
    replayed[o + 2] = live[o + 2]
    replayed[o + RISE] = live[o + RISE]
    replayed[o + FALL] = live[o + FALL]
    replayed[o + REST] = live[o + REST]
    replayed[o + DROPPED] = live[o + DROPPED]
    replayed[o + FREED] = live[o + FREED]
    for j in range(RANGE_AGE, HEAD):
        replayed[o + j] = live[o + j]
    for i in range(k):
        replayed[o + HEAD + 2 * k + i] = live[o + HEAD + 2 * k + i]
    for i in range(2 * k):
        replayed[o + HEAD + 6 * k + i] = live[o + HEAD + 6 * k + i]
    ct = channels_at(o, nh) + nh * (q + 2)
    for j in range(ct, ct + nh * q):
        replayed[j] = live[j]


@njit(cache=CACHE)
def rethreshold(st: np.ndarray, o: int, nh: int, q: int, r: np.ndarray, u_oldest: float, ztail: np.ndarray) -> None:
    """New thresholds ``r`` (a wider input range): the tails as if the operators had started on the oldest
    remembered input (``u_oldest``; centred, ascending, descending) with the input's history before it (each
    play's nodes = u's, ``ztail``; the D_s' zero). Exact while the ring still holds the stream's first sample (the
    tails are then the start's); the next replay rebuilds the plays and their columns from the tails."""
    k = nh - START
    ct = channels_at(o, nh) + nh * (q + 2)
    for i in range(k):
        st[o + HEAD + i] = r[i]
        st[o + HEAD + 2 * k + i] = u_oldest
        st[o + HEAD + 3 * k + i] = 0.0
        st[o + HEAD + 6 * k + i] = u_oldest - r[i]
        st[o + HEAD + 7 * k + i] = u_oldest + r[i]
        for j in range(q):
            st[ct + i * q + j] = ztail[j]
    for j in range(START * q):
        st[ct + k * q + j] = 0.0


@njit(cache=CACHE)
def weight_prior(F: np.ndarray, c0: int, nh: int, noise: float, neff: float, fyy: float, b: float) -> None:
    """Add the prior to a re-fit's statistics at true scale (F, the window's Gram matrix; the columns from c0,
    coefficients c_i = b w_i, then b sigma_s): w_i ~ N(0, WEIGHT_SCALE^2) against the output noise (the monitor's
    level, at least PRIOR_FLOOR x the window's RMS) is the pseudo-observation ``noise / (WEIGHT_SCALE |b|) * c_i =
    0``, i.e. (noise / (WEIGHT_SCALE b))^2 on each coefficient's diagonal (the batch fit's prior rows); sigma_s ~
    N(0, START_SCALE^2) likewise."""
    noise = max(noise, PRIOR_FLOOR * np.sqrt(max(fyy, 0.0) / max(neff, 1.0)))
    if b == 0.0:
        return
    k = nh - START
    lam = (noise / (WEIGHT_SCALE * b)) ** 2
    for i in range(k):
        F[c0 + i, c0 + i] += lam
    lam = (noise / (START_SCALE * b)) ** 2
    for i in range(k, nh):
        F[c0 + i, c0 + i] += lam


@njit(cache=CACHE)
def pin_unopened(st: np.ndarray, o: int, nh: int, theta: np.ndarray, t0: int, masks: np.ndarray, rows: np.ndarray,
                 free: float) -> None:
    """A re-fit's weights (theta from t0): an operator the input has not opened (pushed both up and down) within the
    window's memory (``set_memory``) since the start or the oldest remembered sample is pinned at 0 (fixed in the
    masks ``rows``); an opened one is free (mask value ``free``). Stricter than the batch fit's rule
    (``effects.hysteresis.opened_operators``, which also frees an operator pushed one way that held still while
    the input moved): a weight the window cannot yet tell from the gain stays out of the tracked state. The start
    columns are free (their prior holds them); a start in equilibrium's are pinned at 0, the centred start, until
    ``free_start`` and after ``drop_start``."""
    k = nh - START
    pinned = st[o + EQUILIBRIUM] != 0.0 and (st[o + FREED] == 0.0 or st[o + DROPPED] != 0.0)
    for i in range(nh):
        opened = (i >= k and not pinned) or (i < k and _is_open(st[o + HEAD + 3 * k + i]))
        if not opened:
            theta[t0 + i] = 0.0
        for j in range(rows.shape[0]):
            masks[rows[j], t0 + i] = free if opened else 0.0
