"""How a stream whose input is at a level from its first sample starts: a step from rest at t = 0, or in operation.

A stream whose first input is zero starts at rest (the estimator waits for the
input's first move). One whose first input ``u0`` is not zero is one of two:

* **a step from rest at the first sample** (the most common first record: the
  plant at rest, the input switched on as the acquisition starts): the input
  read as 0 before the first sample and ``u0`` from it, the output starting at
  its rest level and moving away from it as the step response;
* **a stream taken in operation**: the plant moving from an unknown past input;
  its output starts wherever that past left it.

The estimator reads it in two stages:

1. ``starts_near_rest``: the first output sample sits near the rest level (zero,
   as the batch identification takes it when no samples precede the first input
   change: within ``REST_SHARE`` of the output's movement from it, or within a
   few noise levels). A stream in operation starts at a level set by its past
   and, while the input holds, moves little (its first output was 1.6-1000x its
   movement over the first 0.05-0.5 s of the scenario bench's records taken in
   operation, 40 and 80 dB): it is read in operation at once. Checked when the
   in-operation search is ready (the input has moved), or, while the input holds,
   every ``WAIT_S`` (``shows_step``: the output must also have moved far from
   its first sample, ``MOVED_SIGMAS`` noise levels: a step to estimate).
2. If the output may show a step and the input has moved, both readings are
   searched on the same samples, the step from rest (from rest, the input 0
   before the first sample) and the stream in operation (its unknown past's free
   responses projected out), and ``prefer_step`` compares their costs: the
   in-operation reading is taken only if it fits clearly better (``COST_RATIO``)
   and by more than its extra free parameters are worth (an information
   criterion). (Seen: a stream in
   operation whose output happened to start near zero and crept far before the
   input's first move, mid_operation seed 1000 at 80 dB; the step's reading fits
   the resonance the move reveals only with the past's creep, which it lacks.)
   If the input has not moved, only the step's reading can give an estimate:
   it is taken once the output shows the step.

A stream read from rest with few rest samples before its first input change
gets the rest its reading implies prepended (``REST_LEAD``, ``lead_in``).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

#: A step from rest: the first output within this share of the output's movement from it ...
REST_SHARE = 0.1
#: ... or within this many noise levels of it (the first sample's own noise) ...
NEAR_SIGMAS = 4.0
#: ... and, while the input holds, the movement at least this many noise levels (the step response stands out of
#: the noise: there is a step to estimate).
MOVED_SIGMAS = 20.0
#: The in-operation reading wins the start only if its cost per row is below the step's by more than this factor (a
#: misfit of 0.7 noise levels; and by the information criterion, ``prefer_step``). A reading that misses the plant's
#: past misfits grossly (mid_operation seed 1000 at 80 dB: 1400x); more free responses always take a sliver of a
#: misfit of another kind (close unmodelled modes at 40 dB, a step of 0.02 at the first sample: 0.65 %, enough for
#: the criterion at 10500 rows), and the window that carries them then determines alpha less well (+4.7 % there).
COST_RATIO = 1.5
#: While the input holds its first level, the start is read after this long (s): a stream in operation usually
#: moves its input sooner (the scenario bench's records taken in operation: within 1.2 s), and then both readings
#: compete on the data; a held input can only be a step's (or nothing to estimate).
WAIT_S = 1.0
#: A stream read from rest (its first input 0, or a step at its first sample) with fewer rest outputs than this before
#: its first input change is given the rest it implies (``lead_in``): as many samples as it lacks, input 0 and output
#: at its rest outputs' mean, before its first sample. The window's offset is otherwise free against a creep of small
#: alpha (nearly collinear over a window: the batch identification takes the offset as zero below 100 rest samples for
#: the same reason), and on close unmodelled modes at 40 dB a step after one sample of rest fitted alpha +18 %, b -14 %
#: to the record's end, where the same record with 0.05-0.3 s of rest ended within 0.2 %.
REST_LEAD = 100
#: The noise level: from the second differences of the newest this-many samples (``start_levels``).
NOISE_ROWS = 512
#: The output's level now: the mean of the newest this-many samples.
LEVEL_ROWS = 32


@njit(cache=True)
def start_levels(y: np.ndarray, noise_rows: int, level_rows: int) -> tuple[float, float]:
    """(level, noise) of the newest outputs: the mean of the newest ``level_rows``, and the white-noise standard
    deviation from the second differences of the newest ``noise_rows`` (their mean absolute value, values beyond
    three times it clipped: a step response's ringing moves the mean little; sqrt(pi/2)/sqrt(6) turns it into a
    standard deviation). One kernel: it runs inside one ``update()``."""
    n = y.shape[0]
    k = min(level_rows, n)
    level = 0.0
    for i in range(n - k, n):
        level += y[i]
    level /= k
    i0 = max(2, n - noise_rows)
    if n - i0 < 2:
        return level, 0.0
    plain = 0.0
    for i in range(i0, n):
        plain += abs(y[i] - 2.0 * y[i - 1] + y[i - 2])
    plain /= n - i0
    clipped = 0.0
    for i in range(i0, n):
        clipped += min(abs(y[i] - 2.0 * y[i - 1] + y[i - 2]), 3.0 * plain)
    return level, 0.5117 * clipped / (n - i0)


def reading(y: np.ndarray) -> tuple[bool, bool]:
    """Stage 1 on the outputs ``y`` buffered since the first sample: (near rest, shows a step). Near rest: the first
    output within ``REST_SHARE`` of the output's movement from it, or within ``NEAR_SIGMAS`` noise levels, of zero.
    Shows a step: near rest, and the output moved from its first sample by ``MOVED_SIGMAS`` noise levels (a held
    input's step to estimate). One kernel call (``start_levels``)."""
    level, noise = start_levels(y, NOISE_ROWS, LEVEL_ROWS)
    y0 = float(y[0])
    moved = abs(level - y0)
    near = abs(y0) <= max(REST_SHARE * moved, NEAR_SIGMAS * noise)
    return near, near and moved > 0.0 and moved >= MOVED_SIGMAS * noise


def starts_near_rest(y: np.ndarray) -> bool:
    """``reading``'s first answer."""
    return reading(y)[0]


def shows_step(y: np.ndarray) -> bool:
    """``reading``'s second answer."""
    return reading(y)[1]


def prefer_step(cost_step: float, cost_operation: float, rows: int, extra_parameters: int) -> bool:
    """Stage 2: keep the step's reading (cost per row ``cost_step``) unless the in-operation one (``cost_operation``,
    with ``extra_parameters`` more linear parameters: its free responses) fits the same ``rows`` better by more
    than they are worth, rows x ln(cost ratio) above extra_parameters x ln(rows) (the Bayesian information
    criterion), and by more than ``COST_RATIO``."""
    if not math.isfinite(cost_step):
        return False
    if not (math.isfinite(cost_operation) and cost_operation > 0.0) or cost_step <= 0.0:
        return True
    ratio = cost_step / cost_operation
    return ratio <= COST_RATIO or rows * math.log(ratio) <= extra_parameters * math.log(max(rows, 2))


def lead_in(rest_outputs: int) -> int:
    """Samples of rest to prepend to a stream read from rest that shows ``rest_outputs`` of them (``REST_LEAD``)."""
    return max(0, REST_LEAD - rest_outputs)
