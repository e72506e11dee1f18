"""The free response of a record taken in operation: basis functions for an unknown initial state.

A record cut out of longer operation starts with the plant moving: the
resonance carries a state, and the fractional integrator remembers the whole
past input. By linearity the output is the response to the in-record input
changes (measured from the first sample's level) plus the free response of the
past, which is a superposition of

* steps before the record: S(t + T) for unknown T > 0, with S the exact
  unit-step response. S(t + T) varies smoothly with log T, so a geometric grid
  of T (ratio 3, from one sample to a few record lengths) spans it; steps
  further back are close to a constant plus a slow ramp, which the longest
  columns and the constant carry;
* the resonance's own homogeneous solutions (two exponential modes), for the
  part of a recent step's ringing the grid misses.

All are linear in their unknown weights and are projected out of the fit
(variable projection), so the nonlinear search stays (alpha, a1, a2).
"""
from __future__ import annotations

import numpy as np

from .discretize import resonance_poles

#: Ratio of the geometric grid of past step instants.
GRID_RATIO = 3.0
#: The longest past step instant, in record lengths.
LONGEST_PAST = 3.0


def past_offsets(n: int) -> np.ndarray:
    """Sample offsets m of the past steps (T = m h): 0, 1, 3, 9, ... up to LONGEST_PAST n."""
    top = max(int(LONGEST_PAST * n), 2)
    m = np.unique(np.round(GRID_RATIO ** np.arange(0, np.log(top) / np.log(GRID_RATIO) + 1)).astype(np.int64))
    return np.concatenate(([0], m[m <= top]))


def step_columns(step_long: np.ndarray, n: int, offsets: np.ndarray) -> np.ndarray:
    """Columns S(t + m h) on the record's n samples from one long step response (length >= n + max m)."""
    return np.column_stack([step_long[m:m + n] for m in offsets])


def homogeneous_columns(a1: float, a2: float, h: float, n: int) -> np.ndarray:
    """The two free modes of 1 + a1 s + a2 s^2 on n samples (Re/Im of e^(p t) for a complex pair).

    Modes that have decayed below 1e-300 within a sample are returned as zeros;
    the caller drops empty columns.
    """
    slow, fast = resonance_poles(a1, a2)
    t = np.arange(n) * h
    if abs(slow.imag) > 0.0:
        e = np.exp(np.clip(slow.real * t, -700.0, 0.0)) * np.exp(1j * slow.imag * t)
        return np.column_stack((e.real, e.imag))
    return np.column_stack((np.exp(np.clip(slow.real * t, -700.0, 0.0)),
                            np.exp(np.clip(fast.real * t, -700.0, 0.0))))


def free_columns(step_long: np.ndarray, a1: float, a2: float, h: float, n: int) -> np.ndarray:
    """All free-response columns (steps in the past and the resonance modes), without the constant."""
    return np.hstack((step_columns(step_long, n, past_offsets(n)), homogeneous_columns(a1, a2, h, n)))


def creep_columns(alpha: float, h: float, n: int) -> np.ndarray:
    """The fractional integrator's part alone, (t + T)^alpha, for starting grids that skip the resonance."""
    t = np.arange(n) * h
    m = past_offsets(n)
    return np.column_stack([(t + k * h) ** alpha for k in m[1:]])
